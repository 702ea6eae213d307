// Triangle membrane mesh: stress-free reference (as made), starting positions, and the
// enclosed-volume integral of paper eq. 11.
#pragma once

#include <Eigen/Dense>
#include <array>
#include <string>
#include <vector>

#include "nursing_bed/core/io/status.h"

namespace nursing_bed {
namespace fe {

/// A membrane of constant-strain triangles. Triangles are oriented so that their normal
/// ((x1-x0) x (x2-x0)) points out of the gas.
struct MembraneMesh {
  Eigen::Matrix3Xd initial;                ///< node positions at the start of a solve [m]
  std::vector<Eigen::Vector3i> triangles;  ///< node indices
  /// Per triangle: its corners as made, flat and stress-free [m] (any frame: only the shape
  /// counts, so panels that meet at a seam keep their own flat patterns).
  std::vector<std::array<Eigen::Vector3d, 3>> rest;
  std::vector<double> thickness_m;  ///< reference film thickness per triangle [m]
  /// Per triangle: 1 if the gas presses on it and it bounds the gas volume; 0 for a film
  /// inside the gas (the welded middle connection, gas on both sides).
  std::vector<char> pressurised;
  std::vector<int> part;                   ///< label per triangle (face id, for output)
  std::vector<std::array<bool, 3>> fixed;  ///< per node: x, y, z held at the initial position

  int nodeCount() const { return static_cast<int>(initial.cols()); }
  int triangleCount() const { return static_cast<int>(triangles.size()); }
  /// Success when consistent (sizes, indices, positive areas and thicknesses), else what is wrong.
  Status validate() const;
};

/**
 * Gas volume bounded by the pressurised triangles at positions x (paper eq. 11 generalised):
 * V = sum_i (w . (xbar_i o n_i)) A_i with the axis weights w, summing to 1. The paper's
 * w = (1, 0, 0) is exact on any closed polyhedron; w = (1/2, 1/2, 0) is exact for a prism whose
 * open ends lie in planes z = const (the verification tube).
 */
double enclosedVolume(const MembraneMesh& mesh, const Eigen::Matrix3Xd& x,
                      const Eigen::Vector3d& axis_weights = Eigen::Vector3d(1.0, 0.0, 0.0));

/// Current area of all triangles [m^2].
double surfaceArea(const MembraneMesh& mesh, const Eigen::Matrix3Xd& x);

/// Appends `other` to `mesh`, merging nodes whose initial positions lie within `merge_tol_m`
/// of an existing node (for building closed bags from panels).
void appendMesh(MembraneMesh* mesh, const MembraneMesh& other, double merge_tol_m);

/// A flat structured panel: the grid (i, j) in [0, nu] x [0, nv] mapped by `place` (initial
/// position) and `flat` (position as made); each cell split in two triangles along alternating
/// diagonals; `flip` reverses the orientation.
template <typename Place, typename Flat>
MembraneMesh gridPanel(int nu, int nv, Place place, Flat flat, double thickness_m, int part, bool flip);

// ---- implementation --------------------------------------------------------------------------

template <typename Place, typename Flat>
MembraneMesh gridPanel(int nu, int nv, Place place, Flat flat, double thickness_m, int part, bool flip) {
  MembraneMesh m;
  const int n = (nu + 1) * (nv + 1);
  m.initial.resize(3, n);
  Eigen::Matrix3Xd made(3, n);
  m.fixed.assign(n, {false, false, false});
  auto id = [nu](int i, int j) { return j * (nu + 1) + i; };
  for (int j = 0; j <= nv; ++j) {
    for (int i = 0; i <= nu; ++i) {
      m.initial.col(id(i, j)) = place(i, j);
      made.col(id(i, j)) = flat(i, j);
    }
  }
  auto add = [&](int a, int b, int c) {
    const Eigen::Vector3i t = flip ? Eigen::Vector3i(a, c, b) : Eigen::Vector3i(a, b, c);
    m.triangles.push_back(t);
    m.rest.push_back({made.col(t[0]), made.col(t[1]), made.col(t[2])});
    m.thickness_m.push_back(thickness_m);
    m.pressurised.push_back(1);
    m.part.push_back(part);
  };
  for (int j = 0; j < nv; ++j) {
    for (int i = 0; i < nu; ++i) {
      const int a = id(i, j), b = id(i + 1, j), c = id(i + 1, j + 1), d = id(i, j + 1);
      if ((i + j) % 2 == 0) {
        add(a, b, c);
        add(a, c, d);
      } else {
        add(a, b, d);
        add(b, c, d);
      }
    }
  }
  return m;
}

}  // namespace fe
}  // namespace nursing_bed
