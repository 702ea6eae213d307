#include "nursing_bed/core/fe/film.h"

#include <cmath>
#include <sstream>

namespace nursing_bed {
namespace fe {

Status FilmMaterial::validate() const {
  const Status yeoh_valid = yeoh.validate();
  if (!yeoh_valid.ok()) return Status::error("material: " + yeoh_valid.message());
  if (!(density_kg_m3 > 0.0) || !std::isfinite(density_kg_m3)) {
    std::ostringstream err;
    err << "density_kg_m3 must be positive and finite, got " << density_kg_m3;
    return Status::error(err.str());
  }
  return Status::success();
}

TriangleReference triangleReference(const Eigen::Vector3d& x0, const Eigen::Vector3d& x1, const Eigen::Vector3d& x2,
                                    double thickness_m) {
  TriangleReference ref;
  const Eigen::Vector3d e1 = x1 - x0, e2 = x2 - x0;
  const double area = 0.5 * e1.cross(e2).norm();
  ref.thickness_m = thickness_m;
  if (!(area > 0.0)) return ref;
  // Local orthonormal frame in the triangle's plane: u along e1.
  const Eigen::Vector3d u = e1.normalized();
  const Eigen::Vector3d w = (e2 - e2.dot(u) * u).normalized();
  Eigen::Matrix2d dm;
  dm << e1.dot(u), e2.dot(u), 0.0, e2.dot(w);
  ref.dm_inverse = dm.inverse();
  ref.area_m2 = area;
  return ref;
}

namespace {

// Eigen-decomposition of a symmetric 2x2 matrix: values (larger first) and the major axis.
void symmetricEigen2(const Eigen::Matrix2d& c, double* big, double* small, Eigen::Vector2d* major) {
  const double mean = 0.5 * (c(0, 0) + c(1, 1));
  const double half_diff = 0.5 * (c(0, 0) - c(1, 1));
  const double radius = std::sqrt(half_diff * half_diff + c(0, 1) * c(0, 1));
  *big = mean + radius;
  *small = mean - radius;
  if (radius < 1e-14 * std::abs(mean)) {
    *major = Eigen::Vector2d::UnitX();
  } else {
    *major = Eigen::Vector2d(c(0, 1), *big - c(0, 0));
    if (major->squaredNorm() < 1e-30) *major = Eigen::Vector2d(*big - c(1, 1), c(0, 1));
    major->normalize();
  }
}

}  // namespace

TriangleResponse triangleResponse(const FilmMaterial& material, const TriangleReference& ref, const Eigen::Vector3d& x0,
                                  const Eigen::Vector3d& x1, const Eigen::Vector3d& x2) {
  TriangleResponse r;
  for (auto& f : r.force) f.setZero();
  Eigen::Matrix<double, 3, 2> ds;
  ds.col(0) = x1 - x0;
  ds.col(1) = x2 - x0;
  const Eigen::Matrix<double, 3, 2> f = ds * ref.dm_inverse;  // deformation gradient (3x2)
  const Eigen::Matrix2d c = f.transpose() * f;                // right Cauchy-Green, in plane
  double l1_sq, l2_sq;
  Eigen::Vector2d major;
  symmetricEigen2(c, &l1_sq, &l2_sq, &major);
  l2_sq = std::max(l2_sq, 1e-12);
  const double l1 = std::sqrt(l1_sq), l2 = std::sqrt(l2_sq);
  r.stretch_max = l1;
  r.stretch_min = l2;
  r.thickness_m = ref.thickness_m / (l1 * l2);
  const YeohMaterial& y = material.yeoh;
  Eigen::Matrix2d s = Eigen::Matrix2d::Zero();  // second Piola stress times t0 [N/m]
  if (l1 <= 1.0) {
    r.state = FilmState::kSlack;
  } else if (l2 <= 1.0 / std::sqrt(l1)) {
    // Wrinkled: uniaxial tension along the major axis, I1 = l1^2 + 2/l1 (paper eq. 8-10).
    r.state = FilmState::kWrinkled;
    const double i1 = l1_sq + 2.0 / l1;
    const double dw = y.energyDerivative(i1);
    r.energy_j = ref.area_m2 * ref.thickness_m * y.energy(i1);
    s = 2.0 * ref.thickness_m * dw * (1.0 - 1.0 / (l1_sq * l1)) * major * major.transpose();
    r.tension_n_m = 2.0 * dw * (l1_sq - 1.0 / l1) * ref.thickness_m / std::sqrt(l1);
  } else {
    // Taut: I1 = tr C + 1/det C (incompressible, plane stress).
    r.state = FilmState::kTaut;
    const double det = c.determinant();
    const double i1 = c.trace() + 1.0 / det;
    const double dw = y.energyDerivative(i1);
    r.energy_j = ref.area_m2 * ref.thickness_m * y.energy(i1);
    s = 2.0 * ref.thickness_m * dw * (Eigen::Matrix2d::Identity() - c.inverse() / det);
    r.tension_n_m = 2.0 * dw * (l1_sq - 1.0 / det) * r.thickness_m;
  }
  if (r.state == FilmState::kSlack) return r;
  // Nodal forces -dE/dx = -A0 P Dm^-T, P = F S.
  const Eigen::Matrix<double, 3, 2> h = -ref.area_m2 * (f * s) * ref.dm_inverse.transpose();
  r.force[1] = h.col(0);
  r.force[2] = h.col(1);
  r.force[0] = -h.col(0) - h.col(1);
  return r;
}

}  // namespace fe
}  // namespace nursing_bed
