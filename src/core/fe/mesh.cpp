#include "nursing_bed/core/fe/mesh.h"

#include <cmath>
#include <map>
#include <sstream>
#include <tuple>

namespace nursing_bed {
namespace fe {

Status MembraneMesh::validate() const {
  std::ostringstream err;
  const std::size_t n = static_cast<std::size_t>(initial.cols());
  const std::size_t t = triangles.size();
  if (n < 3 || t == 0) return Status::error("mesh: needs at least 3 nodes and 1 triangle");
  if (static_cast<std::size_t>(initial.cols()) != n || fixed.size() != n) {
    return Status::error("mesh: initial positions and fixed flags must have one entry per node");
  }
  if (rest.size() != t || thickness_m.size() != t || pressurised.size() != t || part.size() != t) {
    return Status::error("mesh: rest, thickness_m, pressurised and part must have one entry per triangle");
  }
  if (!initial.allFinite()) return Status::error("mesh: node positions must be finite");
  for (std::size_t i = 0; i < t; ++i) {
    const Eigen::Vector3i& tri = triangles[i];
    for (int k = 0; k < 3; ++k) {
      if (tri[k] < 0 || static_cast<std::size_t>(tri[k]) >= n) {
        err << "mesh: triangle " << i << " refers to node " << tri[k] << " of " << n;
        return Status::error(err.str());
      }
    }
    const auto& r = rest[i];
    const double area = 0.5 * (r[1] - r[0]).cross(r[2] - r[0]).norm();
    if (!(area > 0.0) || !std::isfinite(area)) {
      err << "mesh: triangle " << i << " has zero reference area (degenerate geometry)";
      return Status::error(err.str());
    }
    if (!(thickness_m[i] > 0.0) || !std::isfinite(thickness_m[i])) {
      err << "mesh: thickness_m of triangle " << i << " must be positive, got " << thickness_m[i];
      return Status::error(err.str());
    }
  }
  return Status::success();
}

double enclosedVolume(const MembraneMesh& mesh, const Eigen::Matrix3Xd& x, const Eigen::Vector3d& axis_weights) {
  double volume = 0.0;
  for (std::size_t i = 0; i < mesh.triangles.size(); ++i) {
    if (!mesh.pressurised[i]) continue;
    const Eigen::Vector3i& t = mesh.triangles[i];
    const Eigen::Vector3d a = x.col(t[0]), b = x.col(t[1]), c = x.col(t[2]);
    const Eigen::Vector3d area_vector = 0.5 * (b - a).cross(c - a);  // n_i A_i
    const Eigen::Vector3d centroid = (a + b + c) / 3.0;              // xbar_i
    volume += axis_weights.dot(centroid.cwiseProduct(area_vector));
  }
  return volume;
}

double surfaceArea(const MembraneMesh& mesh, const Eigen::Matrix3Xd& x) {
  double area = 0.0;
  for (const auto& t : mesh.triangles) {
    area += 0.5 * (x.col(t[1]) - x.col(t[0])).cross(x.col(t[2]) - x.col(t[0])).norm();
  }
  return area;
}

void appendMesh(MembraneMesh* mesh, const MembraneMesh& other, double merge_tol_m) {
  using Key = std::tuple<long, long, long>;
  auto key = [merge_tol_m](const Eigen::Vector3d& p, int dx, int dy, int dz) {
    return Key(std::lround(p.x() / merge_tol_m) + dx, std::lround(p.y() / merge_tol_m) + dy,
               std::lround(p.z() / merge_tol_m) + dz);
  };
  std::map<Key, std::vector<int>> existing;
  auto remember = [&](const Eigen::Vector3d& p, int id) { existing[key(p, 0, 0, 0)].push_back(id); };
  // Nodes closer than half the tolerance merge, whichever side of a grid line they fall.
  auto find = [&](const Eigen::Vector3d& p) {
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dz = -1; dz <= 1; ++dz) {
          const auto it = existing.find(key(p, dx, dy, dz));
          if (it == existing.end()) continue;
          for (int id : it->second) {
            const Eigen::Vector3d q =
                id < mesh->nodeCount() ? Eigen::Vector3d(mesh->initial.col(id)) : Eigen::Vector3d(p);
            if ((q - p).norm() < 0.5 * merge_tol_m) return id;
          }
        }
    return -1;
  };
  for (int i = 0; i < mesh->nodeCount(); ++i) remember(mesh->initial.col(i), i);
  std::vector<int> map(other.nodeCount());
  std::vector<int> added;
  for (int i = 0; i < other.nodeCount(); ++i) {
    const int found = find(other.initial.col(i));
    if (found >= 0) {
      map[i] = found;
    } else {
      map[i] = mesh->nodeCount() + static_cast<int>(added.size());
      added.push_back(i);
    }
  }
  const int old_n = mesh->nodeCount();
  mesh->initial.conservativeResize(3, old_n + static_cast<int>(added.size()));
  for (std::size_t k = 0; k < added.size(); ++k) {
    mesh->initial.col(old_n + k) = other.initial.col(added[k]);
    mesh->fixed.push_back(other.fixed[added[k]]);
  }
  for (std::size_t i = 0; i < other.triangles.size(); ++i) {
    const Eigen::Vector3i& t = other.triangles[i];
    mesh->triangles.emplace_back(map[t[0]], map[t[1]], map[t[2]]);
    mesh->rest.push_back(other.rest[i]);
    mesh->thickness_m.push_back(other.thickness_m[i]);
    mesh->pressurised.push_back(other.pressurised[i]);
    mesh->part.push_back(other.part[i]);
  }
}

}  // namespace fe
}  // namespace nursing_bed
