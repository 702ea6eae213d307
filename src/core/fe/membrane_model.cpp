#include "nursing_bed/core/fe/membrane_model.h"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <unordered_map>

namespace nursing_bed {
namespace fe {

Status MembraneOptions::validate() const {
  std::ostringstream err;
  if (!(cfl > 0.0 && cfl <= 1.0)) err << "cfl must be in (0, 1], got " << cfl;
  else if (!(stiffening_factor >= 1.0 && stiffening_factor <= 100.0))
    err << "stiffening_factor must be in [1, 100], got " << stiffening_factor;
  else if (!(contact_stiffness_scale > 0.0 && contact_stiffness_scale <= 1.0))
    err << "contact_stiffness_scale must be in (0, 1], got " << contact_stiffness_scale;
  else if (!(contact_damping_ratio >= 0.0 && contact_damping_ratio <= 1.0))
    err << "contact_damping_ratio must be in [0, 1], got " << contact_damping_ratio;
  else if (!std::isfinite(bed_height_m)) err << "bed_height_m must be finite";
  else if (!(self_contact_radius_m >= 0.0) || !std::isfinite(self_contact_radius_m))
    err << "self_contact_radius_m must be >= 0, got " << self_contact_radius_m;
  else if (self_contact_exclusion_rings < 1) err << "self_contact_exclusion_rings must be >= 1";
  else if (threads < 1) err << "threads must be >= 1, got " << threads;
  return Status::fromMessage(err.str());
}

MembraneModel::MembraneModel(MembraneMesh mesh, FilmMaterial material, MembraneOptions options)
    : mesh_(std::move(mesh)), material_(material), options_(options) {
  for (const Status& s : {mesh_.validate(), material_.validate(), options_.validate()}) {
    if (!s) throw std::invalid_argument("MembraneModel: " + s.message());
  }
  x_ = mesh_.initial;
  v_.setZero(3, nodeCount());
  f_.setZero(3, nodeCount());
  buildReferences();
  if (options_.self_contact_radius_m > 0.0) buildContactExclusions();
}

void MembraneModel::buildReferences() {
  const int n = nodeCount();
  ref_.resize(mesh_.triangles.size());
  response_.resize(mesh_.triangles.size());
  mass_.setZero(n);
  node_elements_.assign(n, {});
  Eigen::VectorXd node_area = Eigen::VectorXd::Zero(n);
  // Explicit stability: dilatational wave speed of the film, with margin for the Yeoh
  // stiffening at large stretch (tangent modulus up to stiffening_factor x the initial 6 C10).
  const double wave_speed =
      std::sqrt(options_.stiffening_factor * material_.yeoh.youngsModulus() / material_.density_kg_m3);
  double dt = std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < mesh_.triangles.size(); ++i) {
    const auto& r = mesh_.rest[i];
    ref_[i] = triangleReference(r[0], r[1], r[2], mesh_.thickness_m[i]);
    const double longest = std::max({(r[1] - r[0]).norm(), (r[2] - r[1]).norm(), (r[0] - r[2]).norm()});
    const double altitude = 2.0 * ref_[i].area_m2 / longest;
    dt = std::min(dt, options_.cfl * altitude / wave_speed);
    for (int k = 0; k < 3; ++k) {
      const int node = mesh_.triangles[i][k];
      mass_[node] += material_.density_kg_m3 * ref_[i].thickness_m * ref_[i].area_m2 / 3.0;
      node_area[node] += ref_[i].area_m2 / 3.0;
      node_elements_[node].emplace_back(static_cast<int>(i), k);
    }
  }
  for (int i = 0; i < n; ++i) {
    if (!(mass_[i] > 0.0)) {
      throw std::invalid_argument("MembraneModel: mesh: node " + std::to_string(i) + " belongs to no triangle");
    }
  }
  dt_stable_ = dt;
  contact_k_ = options_.contact_stiffness_scale * mass_.minCoeff() / (dt * dt);
  contact_c_ = 2.0 * options_.contact_damping_ratio * std::sqrt(contact_k_ * mass_.minCoeff());
  mean_node_area_ = node_area.mean();
}

void MembraneModel::setPositions(const Eigen::Matrix3Xd& x) {
  if (x.cols() != nodeCount() || !x.allFinite()) {
    throw std::invalid_argument("MembraneModel::setPositions: need finite positions for every node");
  }
  x_ = x;
  neighbours_valid_ = false;
}

void MembraneModel::zeroVelocities() {
  v_.setZero();
  plate_.velocity_m_s = 0.0;
}

ForceSummary MembraneModel::computeForces(double gauge_pressure_pa) {
  ForceSummary summary;
  const int nt = mesh_.triangleCount();
  const int n = nodeCount();
#pragma omp parallel for schedule(static) num_threads(options_.threads)
  for (int i = 0; i < nt; ++i) {
    const Eigen::Vector3i& t = mesh_.triangles[i];
    response_[i] = triangleResponse(material_, ref_[i], x_.col(t[0]), x_.col(t[1]), x_.col(t[2]));
  }
#pragma omp parallel for schedule(static) num_threads(options_.threads)
  for (int j = 0; j < n; ++j) {
    Eigen::Vector3d f = Eigen::Vector3d::Zero();
    for (const auto& [tri, corner] : node_elements_[j]) f += response_[tri].force[corner];
    f_.col(j) = f;
  }
  for (const auto& r : response_) {
    summary.elastic_energy_j += r.energy_j;
    summary.wrinkled += r.state == FilmState::kWrinkled;
    summary.slack += r.state == FilmState::kSlack;
    summary.max_stretch = std::max(summary.max_stretch, r.stretch_max);
  }
  addPressure(gauge_pressure_pa);
  addBedAndPlate(&summary);
  if (options_.self_contact_radius_m > 0.0) addSelfContact();
  return summary;
}

void MembraneModel::addPressure(double gauge_pressure_pa) {
  // Gas pushes each pressurised triangle along its outward normal: p n A / 3 per corner.
  for (std::size_t i = 0; i < mesh_.triangles.size(); ++i) {
    if (!mesh_.pressurised[i]) continue;
    const Eigen::Vector3i& t = mesh_.triangles[i];
    const Eigen::Vector3d nodal =
        gauge_pressure_pa / 6.0 * (x_.col(t[1]) - x_.col(t[0])).cross(x_.col(t[2]) - x_.col(t[0]));
    for (int k = 0; k < 3; ++k) f_.col(t[k]) += nodal;
  }
}

void MembraneModel::addBedAndPlate(ForceSummary* summary) {
  double plate_force = 0.0, bed_force = 0.0;
  const bool plate_on = plate_.mode != PlateState::Mode::kNone;
  for (int j = 0; j < nodeCount(); ++j) {
    const double z = x_(2, j);
    if (options_.bed_contact && z < options_.bed_height_m) {
      const double fz = contact_k_ * (options_.bed_height_m - z) - contact_c_ * std::min(v_(2, j), 0.0);
      f_(2, j) += fz;
      bed_force += fz;
    }
    if (plate_on && z > plate_.height_m) {
      const double closing = v_(2, j) - plate_.velocity_m_s;
      const double fz = contact_k_ * (z - plate_.height_m) + contact_c_ * std::max(closing, 0.0);
      f_(2, j) -= fz;
      plate_force += fz;
    }
  }
  plate_.contact_force_n = plate_force;
  summary->plate_force_n = plate_force;
  summary->bed_force_n = bed_force;
}

}  // namespace fe
}  // namespace nursing_bed
