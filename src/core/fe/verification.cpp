#include "nursing_bed/core/fe/verification.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <sstream>
#include <stdexcept>

#include "nursing_bed/core/fe/membrane_model.h"
#include "nursing_bed/core/fe/relaxation.h"
#include "nursing_bed/core/physics/units.h"

namespace nursing_bed {
namespace fe {
namespace {

MembraneMesh meshFromTriangles(const Eigen::Matrix3Xd& nodes, const std::vector<Eigen::Vector3i>& tris,
                               double thickness_m) {
  MembraneMesh m;
  m.initial = nodes;
  m.triangles = tris;
  m.fixed.assign(nodes.cols(), {false, false, false});
  for (const auto& t : tris) {
    m.rest.push_back({nodes.col(t[0]), nodes.col(t[1]), nodes.col(t[2])});
    m.thickness_m.push_back(thickness_m);
    m.pressurised.push_back(1);
    m.part.push_back(0);
  }
  return m;
}

}  // namespace

MembraneMesh icosphereMesh(double radius_m, int subdivisions, double thickness_m) {
  if (!(radius_m > 0.0)) throw std::invalid_argument("icosphereMesh: radius_m must be positive");
  if (subdivisions < 0 || subdivisions > 6) throw std::invalid_argument("icosphereMesh: subdivisions must be 0..6");
  const double g = (1.0 + std::sqrt(5.0)) / 2.0;
  std::vector<Eigen::Vector3d> v = {{-1, g, 0},  {1, g, 0},  {-1, -g, 0}, {1, -g, 0}, {0, -1, g},  {0, 1, g},
                                    {0, -1, -g}, {0, 1, -g}, {g, 0, -1},  {g, 0, 1},  {-g, 0, -1}, {-g, 0, 1}};
  std::vector<Eigen::Vector3i> f = {{0, 11, 5},  {0, 5, 1},  {0, 1, 7},  {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
                                    {11, 10, 2}, {10, 7, 6}, {7, 1, 8},  {3, 9, 4},  {3, 4, 2},   {3, 2, 6}, {3, 6, 8},
                                    {3, 8, 9},   {4, 9, 5},  {2, 4, 11}, {6, 2, 10}, {8, 6, 7},   {9, 8, 1}};
  for (auto& p : v) p.normalize();
  for (int s = 0; s < subdivisions; ++s) {
    std::map<std::pair<int, int>, int> mid;
    auto midpoint = [&](int a, int b) {
      const auto key = std::minmax(a, b);
      const auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      v.push_back((v[a] + v[b]).normalized());
      return mid[key] = static_cast<int>(v.size()) - 1;
    };
    std::vector<Eigen::Vector3i> next;
    for (const auto& t : f) {
      const int ab = midpoint(t[0], t[1]), bc = midpoint(t[1], t[2]), ca = midpoint(t[2], t[0]);
      next.insert(next.end(), {{t[0], ab, ca}, {t[1], bc, ab}, {t[2], ca, bc}, {ab, bc, ca}});
    }
    f.swap(next);
  }
  Eigen::Matrix3Xd nodes(3, v.size());
  for (std::size_t i = 0; i < v.size(); ++i) nodes.col(i) = radius_m * v[i];
  return meshFromTriangles(nodes, f, thickness_m);
}

MembraneMesh tubeMesh(double radius_m, double length_m, int around, int along, double thickness_m) {
  if (!(radius_m > 0.0) || !(length_m > 0.0))
    throw std::invalid_argument("tubeMesh: radius_m and length_m must be positive");
  if (around < 6 || along < 1) throw std::invalid_argument("tubeMesh: need around >= 6 and along >= 1");
  Eigen::Matrix3Xd nodes(3, around * (along + 1));
  for (int j = 0; j <= along; ++j) {
    for (int i = 0; i < around; ++i) {
      const double a = 2.0 * kPi * i / around;
      nodes.col(j * around + i) << radius_m * std::cos(a), radius_m * std::sin(a), length_m * j / along;
    }
  }
  std::vector<Eigen::Vector3i> tris;
  for (int j = 0; j < along; ++j) {
    for (int i = 0; i < around; ++i) {
      const int a = j * around + i, b = j * around + (i + 1) % around;
      tris.emplace_back(a, b, b + around);  // outward normal
      tris.emplace_back(a, b + around, a + around);
    }
  }
  MembraneMesh m = meshFromTriangles(nodes, tris, thickness_m);
  for (auto& f : m.fixed) f[2] = true;
  return m;
}

double spherePressureExact(const YeohMaterial& m, double thickness_m, double radius_m, double stretch) {
  return thickness_m / (radius_m * stretch * stretch) * m.equibiaxialEnergyDerivative(stretch);
}

double tubePressureExact(const YeohMaterial& m, double thickness_m, double radius_m, double stretch) {
  const double l2 = stretch * stretch;
  const double i1 = l2 + 1.0 + 1.0 / l2;
  return 2.0 * m.energyDerivative(i1) * (l2 - 1.0 / l2) * thickness_m / (l2 * radius_m);
}

Status VerificationCase::validate() const {
  std::ostringstream err;
  if (!(radius_m > 0.0)) err << "radius_m must be positive, got " << radius_m;
  else if (!(thickness_m > 0.0 && thickness_m < 0.1 * radius_m))
    err << "thickness_m must be positive and below radius_m/10 (a membrane), got " << thickness_m;
  else if (!(tube_length_m > 0.0)) err << "tube_length_m must be positive";
  else if (resolution < 0) err << "resolution must be >= 0";
  else if (stretches.empty()) err << "stretches must not be empty";
  for (double s : stretches) {
    if (err.tellp() == 0 && !(s > 1.0 && s <= 2.2)) err << "stretches must lie in (1, 2.2], got " << s;
  }
  return Status::fromMessage(err.str());
}

std::vector<VerificationPoint> runVerification(const VerificationCase& c, const FilmMaterial& material) {
  const Status valid = c.validate();
  if (!valid) throw std::invalid_argument("runVerification: " + valid.message());
  const bool sphere = c.shape == VerificationCase::Shape::kSphere;
  MembraneMesh mesh = sphere ? icosphereMesh(c.radius_m, c.resolution, c.thickness_m)
                             : tubeMesh(c.radius_m, c.tube_length_m, std::max(6, c.resolution), 2, c.thickness_m);
  MembraneOptions options;
  options.threads = 1;              // small meshes: one thread (the machine is shared)
  options.stiffening_factor = 4.0;  // stretches up to 2.2
  options.bed_contact = false;
  MembraneModel model(mesh, material, options);
  PressureControl control;
  control.volume_axes = sphere ? Eigen::Vector3d(1.0, 0.0, 0.0) : Eigen::Vector3d(0.5, 0.5, 0.0);
  const double dimension = sphere ? 3.0 : 2.0;
  const double v0 = model.volume(control.volume_axes);
  auto exact = [&](double s) {
    return sphere ? spherePressureExact(material.yeoh, c.thickness_m, c.radius_m, s)
                  : tubePressureExact(material.yeoh, c.thickness_m, c.radius_m, s);
  };
  // Volume stiffness well above the film's softening past the limit point.
  double p_scale = 0.0;
  const double s_max = *std::max_element(c.stretches.begin(), c.stretches.end());
  for (double s = 1.01; s < s_max; s += 0.01) p_scale = std::max(p_scale, exact(s));
  control.volume_stiffness_pa = 20.0 * p_scale;
  std::vector<VerificationPoint> points;
  double previous = 1.0;
  for (double target : c.stretches) {
    // Start from the previous state scaled to the target (continuation).
    Eigen::Matrix3Xd x = model.positions();
    const Eigen::Vector3d centre = sphere ? x.rowwise().mean() : Eigen::Vector3d(x.row(0).mean(), x.row(1).mean(), 0.0);
    for (int j = 0; j < x.cols(); ++j) {
      Eigen::Vector3d d = x.col(j) - centre;
      if (!sphere) d.z() = 0.0;
      x.col(j) += (target / previous - 1.0) * d;
    }
    model.setPositions(x);
    previous = target;
    control.target_volume_m3 = v0 * std::pow(target, dimension);
    control.gauge_pressure_pa = exact(target);  // offset only: the answer is the (p, V) pair
    const RelaxResult r = relax(&model, control);
    VerificationPoint p;
    p.stretch = std::pow(r.volume_m3 / v0, 1.0 / dimension);
    p.fe_pressure_pa = r.gauge_pressure_pa;
    p.exact_pressure_pa = exact(p.stretch);
    p.relative_error = p.fe_pressure_pa / p.exact_pressure_pa - 1.0;
    p.converged = r.converged;
    p.message = r.message;
    p.iterations = r.iterations;
    points.push_back(p);
  }
  return points;
}

}  // namespace fe
}  // namespace nursing_bed
