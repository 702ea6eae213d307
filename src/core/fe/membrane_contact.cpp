// Self contact between the film's layers and the explicit step of MembraneModel.
#include <algorithm>
#include <cmath>
#include <unordered_map>

#include "nursing_bed/core/fe/membrane_model.h"

namespace nursing_bed {
namespace fe {
namespace {

constexpr double kSkinFraction = 0.5;  // Verlet skin of the neighbour list, times the radius

long long cellKey(const Eigen::Vector3d& p, double cell) {
  const long long i = static_cast<long long>(std::floor(p.x() / cell)) + (1 << 20);
  const long long j = static_cast<long long>(std::floor(p.y() / cell)) + (1 << 20);
  const long long k = static_cast<long long>(std::floor(p.z() / cell)) + (1 << 20);
  return (i << 42) | (j << 21) | k;
}

}  // namespace

void MembraneModel::buildContactExclusions() {
  // Nodes within a few rings of each other in the mesh (same layer, or across a seam) are
  // held apart by the film itself; only distant nodes (other layers) may touch.
  const int n = nodeCount();
  std::vector<std::vector<int>> adjacent(n);
  for (const auto& t : mesh_.triangles) {
    for (int a = 0; a < 3; ++a) {
      for (int b = 0; b < 3; ++b) {
        if (a != b) adjacent[t[a]].push_back(t[b]);
      }
    }
  }
  excluded_.assign(n, {});
  for (int i = 0; i < n; ++i) {
    std::vector<int> frontier{i}, seen{i};
    for (int ring = 0; ring < options_.self_contact_exclusion_rings; ++ring) {
      std::vector<int> next;
      for (int a : frontier) {
        for (int b : adjacent[a]) {
          if (std::find(seen.begin(), seen.end(), b) == seen.end()) {
            seen.push_back(b);
            next.push_back(b);
          }
        }
      }
      frontier.swap(next);
    }
    std::sort(seen.begin(), seen.end());
    excluded_[i] = std::move(seen);
  }
}

void MembraneModel::rebuildNeighbours() {
  const double radius = options_.self_contact_radius_m * (1.0 + kSkinFraction);
  std::unordered_map<long long, std::vector<int>> cells;
  for (int i = 0; i < nodeCount(); ++i) cells[cellKey(x_.col(i), radius)].push_back(i);
  neighbours_.assign(nodeCount(), {});
#pragma omp parallel for schedule(static) num_threads(options_.threads)
  for (int i = 0; i < nodeCount(); ++i) {
    const Eigen::Vector3d p = x_.col(i);
    for (int dx = -1; dx <= 1; ++dx) {
      for (int dy = -1; dy <= 1; ++dy) {
        for (int dz = -1; dz <= 1; ++dz) {
          const auto it = cells.find(cellKey(p + radius * Eigen::Vector3d(dx, dy, dz), radius));
          if (it == cells.end()) continue;
          for (int j : it->second) {
            if ((x_.col(j) - p).norm() >= radius) continue;
            if (std::binary_search(excluded_[i].begin(), excluded_[i].end(), j)) continue;
            neighbours_[i].push_back(j);
          }
        }
      }
    }
  }
  x_at_build_ = x_;
  neighbours_valid_ = true;
}

void MembraneModel::addSelfContact() {
  const double r = options_.self_contact_radius_m;
  if (!neighbours_valid_ || (x_ - x_at_build_).colwise().norm().maxCoeff() > 0.5 * kSkinFraction * r) {
    rebuildNeighbours();
  }
  // Penalty between nodes of different layers closer than r (a film pair's contact distance).
#pragma omp parallel for schedule(static) num_threads(options_.threads)
  for (int i = 0; i < nodeCount(); ++i) {
    for (int j : neighbours_[i]) {
      const Eigen::Vector3d d = x_.col(i) - x_.col(j);
      const double dist = d.norm();
      if (dist >= r || dist <= 0.0) continue;
      f_.col(i) += contact_k_ * (r - dist) / dist * d;
    }
  }
}

void MembraneModel::step(double dt, double film_damping_per_s) {
  const double decay = 1.0 / (1.0 + dt * film_damping_per_s);
#pragma omp parallel for schedule(static) num_threads(options_.threads)
  for (int j = 0; j < nodeCount(); ++j) {
    for (int c = 0; c < 3; ++c) {
      if (mesh_.fixed[j][c]) {
        v_(c, j) = 0.0;
        continue;
      }
      v_(c, j) = (v_(c, j) + dt * f_(c, j) / mass_[j]) * decay;
      x_(c, j) += dt * v_(c, j);
    }
  }
  if (plate_.mode == PlateState::Mode::kLoaded) {
    const double force = plate_.contact_force_n - plate_.load_n - plate_.damping_n_s_m * plate_.velocity_m_s;
    plate_.velocity_m_s += dt * force / plate_.mass_kg;
    plate_.height_m += dt * plate_.velocity_m_s;
  } else {
    plate_.velocity_m_s = 0.0;
  }
}

double MembraneModel::kineticEnergy() const {
  double e = 0.5 * (v_.colwise().squaredNorm().transpose().array() * mass_.array()).sum();
  if (plate_.mode == PlateState::Mode::kLoaded) e += 0.5 * plate_.mass_kg * plate_.velocity_m_s * plate_.velocity_m_s;
  return e;
}

double MembraneModel::residualRms() const {
  double sum = 0.0;
  long count = 0;
  for (int j = 0; j < nodeCount(); ++j) {
    for (int c = 0; c < 3; ++c) {
      if (mesh_.fixed[j][c]) continue;
      sum += f_(c, j) * f_(c, j);
      ++count;
    }
  }
  return count > 0 ? std::sqrt(sum / static_cast<double>(count)) : 0.0;
}

}  // namespace fe
}  // namespace nursing_bed
