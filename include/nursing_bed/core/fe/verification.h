// Closed-form checks of the membrane solver: a Yeoh spherical balloon and
// a long cylindrical tube (axial stretch 1) under pressure, traced through their limit points
// under volume control.
#pragma once

#include <string>
#include <vector>

#include "nursing_bed/core/fe/film.h"
#include "nursing_bed/core/fe/mesh.h"
#include "nursing_bed/core/io/status.h"

namespace nursing_bed {
namespace fe {

/// Closed sphere of radius R (icosahedron subdivided `subdivisions` times, nodes on the sphere).
MembraneMesh icosphereMesh(double radius_m, int subdivisions, double thickness_m);
/// Open tube of radius R and length L, `around` x `along` cells; every node's z held (plane
/// strain: axial stretch 1).
MembraneMesh tubeMesh(double radius_m, double length_m, int around, int along, double thickness_m);

/// Balloon: p = t0 / (R0 l^2) dW(2 l^2 + l^-4)/dl (equibiaxial, incompressible).
double spherePressureExact(const YeohMaterial& m, double thickness_m, double radius_m, double stretch);
/// Tube with axial stretch 1: p = 2 W'(I1) (l^2 - l^-2) t0 / (l^2 R0), I1 = l^2 + 1 + l^-2.
double tubePressureExact(const YeohMaterial& m, double thickness_m, double radius_m, double stretch);

struct VerificationPoint {
  double stretch = 1.0;  ///< FE stretch from the volume (sphere: (V/V0)^1/3, tube: (V/V0)^1/2)
  double fe_pressure_pa = 0.0;
  double exact_pressure_pa = 0.0;  ///< closed form at the FE stretch
  double relative_error = 0.0;
  bool converged = false;
  std::string message;
  int iterations = 0;
};

struct VerificationCase {
  enum class Shape { kSphere, kTube };
  Shape shape = Shape::kSphere;
  double radius_m = 0.05;
  double thickness_m = 0.5e-3;
  double tube_length_m = 0.02;
  int resolution = 3;             ///< sphere: subdivisions; tube: cells around (along: 2)
  std::vector<double> stretches;  ///< volume-controlled targets

  /// Success, or what is wrong (names the field).
  Status validate() const;
};

/// Runs the case by continuation; throws std::invalid_argument for a bad case or material.
std::vector<VerificationPoint> runVerification(const VerificationCase& c, const FilmMaterial& material);

}  // namespace fe
}  // namespace nursing_bed
