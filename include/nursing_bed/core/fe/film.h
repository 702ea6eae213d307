// Incompressible Yeoh film in plane stress on constant-strain triangles, with a relaxed
// (tension-field) energy so that the film carries no compression (paper eq. 7).
#pragma once

#include <Eigen/Dense>
#include <array>
#include <string>

#include "nursing_bed/core/io/status.h"
#include "nursing_bed/core/physics/yeoh.h"

namespace nursing_bed {
namespace fe {

/// Film material: the fitted Yeoh constants (doc/material.md) and a density for the dynamics.
struct FilmMaterial {
  YeohMaterial yeoh;              ///< paper eq. 7, fitted constants by default
  double density_kg_m3 = 1200.0;  ///< TPU 1.1-1.25 g/cm3 (doc/paper_targets.md)

  /// Success, or what is wrong (names the field).
  Status validate() const;
};

/// Wrinkling state of an element under the relaxed energy.
enum class FilmState { kTaut = 0, kWrinkled = 1, kSlack = 2 };

/// Reference data of one triangle, from its stress-free flat shape.
struct TriangleReference {
  Eigen::Matrix2d dm_inverse;  ///< inverse of the reference edge matrix in a local 2D frame
  double area_m2 = 0.0;        ///< reference area A0
  double thickness_m = 0.0;    ///< reference thickness t0
};

/// Builds the reference of the triangle (X0, X1, X2) [m]; area 0 when degenerate.
TriangleReference triangleReference(const Eigen::Vector3d& x0, const Eigen::Vector3d& x1, const Eigen::Vector3d& x2,
                                    double thickness_m);

/// Response of one triangle at its current nodes.
struct TriangleResponse {
  std::array<Eigen::Vector3d, 3> force;  ///< internal (elastic) nodal forces, -dE/dx [N]
  double energy_j = 0.0;                 ///< A0 t0 W_relaxed
  double stretch_max = 1.0;              ///< larger in-plane principal stretch
  double stretch_min = 1.0;              ///< smaller in-plane principal stretch
  double thickness_m = 0.0;              ///< current thickness t0 / (l1 l2) (incompressible)
  double tension_n_m = 0.0;              ///< larger principal Cauchy stress times thickness
  FilmState state = FilmState::kSlack;
};

/**
 * Relaxed plane-stress energy of the incompressible Yeoh film (W depends on I1 only):
 * principal Cauchy stresses sigma_i = 2 W'(I1) (l_i^2 - l3^2), l3 = 1/(l1 l2), so with
 * l1 >= l2 the film is taut if l2 > l1^-1/2, wrinkled (uniaxial tension along the major axis,
 * W = W(l1^2 + 2/l1)) if l2 <= l1^-1/2 < 1 < l1, and slack (W = 0) if l1 <= 1. The relaxed
 * energy is C1 across the boundaries.
 */
TriangleResponse triangleResponse(const FilmMaterial& material, const TriangleReference& ref, const Eigen::Vector3d& x0,
                                  const Eigen::Vector3d& x1, const Eigen::Vector3d& x2);

}  // namespace fe
}  // namespace nursing_bed
