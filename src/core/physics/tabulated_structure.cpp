#include "nursing_bed/core/physics/tabulated_structure.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace nursing_bed {
namespace {

bool increasingPositive(const std::vector<double>& v) {
  for (std::size_t i = 0; i < v.size(); ++i) {
    if (!(v[i] > 0.0) || !std::isfinite(v[i]) || (i > 0 && !(v[i] > v[i - 1]))) return false;
  }
  return v.size() >= 2;
}

/// Success, or what is wrong with grid `name` (one row per height, one column per pressure).
Status checkGrid(const std::string& name, const std::vector<std::vector<double>>& g, std::size_t rows, std::size_t cols,
                 bool positive) {
  if (g.size() != rows) return Status::error(name + " needs one row per height");
  for (const auto& row : g) {
    if (row.size() != cols) return Status::error(name + " needs one column per pressure");
    for (double x : row) {
      if (!std::isfinite(x) || (positive && !(x > 0.0)))
        return Status::error(name + (positive ? " values must be positive" : " values must be finite"));
    }
  }
  return Status::success();
}

// Index i with axis[i] <= x < axis[i+1] (clamped) and the fraction within.
std::pair<std::size_t, double> locate(const std::vector<double>& axis, double x) {
  x = std::clamp(x, axis.front(), axis.back());
  std::size_t i = std::upper_bound(axis.begin(), axis.end(), x) - axis.begin();
  i = std::min(std::max<std::size_t>(i, 1), axis.size() - 1) - 1;
  return {i, (x - axis[i]) / (axis[i + 1] - axis[i])};
}

// The shape coordinate is the film's relaxed pressure in units of 10 kPa (an O(1) coordinate,
// as CellStructure's solvers expect).
constexpr double kShapeUnitPa = 1.0e4;

}  // namespace

Status StructureTableData::validate() const {
  if (!increasingPositive(heights_m))
    return Status::error("heights_m must have >= 2 positive, strictly increasing values");
  if (!increasingPositive(pressures_pa))
    return Status::error("pressures_pa must have >= 2 positive, strictly increasing values");
  const Status volume = checkGrid("volume_m3", volume_m3, heights_m.size(), pressures_pa.size(), true);
  if (!volume) return volume;
  return checkGrid("plate_force_n", plate_force_n, heights_m.size(), pressures_pa.size(), false);
}

namespace {
// The flat cell's effective area: the lowest row's at the lowest pressure (the rest shape), as
// A_eff takes it below the table. Checked first: the fold is built from it.
double flatArea(const StructureTableData& t) {
  const Status valid = t.validate();
  if (!valid) throw std::invalid_argument("TabulatedStructure: " + valid.message());
  const double area = t.plate_force_n.front().front() / t.pressures_pa.front();
  if (!(area > 0.0)) throw std::invalid_argument("TabulatedStructure: the lowest row's plate force must be positive");
  return area;
}
}  // namespace

TabulatedStructure::TabulatedStructure(StructureTableData table, double film_relaxation_time_s, double dead_volume_m3,
                                       double fold_fraction)
    : table_(std::move(table)),
      relaxation_time_s_(film_relaxation_time_s),
      dead_volume_m3_(dead_volume_m3),
      fold_(fold_fraction * dead_volume_m3, flatArea(table_)) {
  if (!(relaxation_time_s_ > 0.0))
    throw std::invalid_argument("TabulatedStructure: film_relaxation_time_s must be positive");
  if (!(dead_volume_m3_ > 0.0 && std::isfinite(dead_volume_m3_)))
    throw std::invalid_argument("TabulatedStructure: dead_volume_m3 must be positive");
  if (!(fold_fraction < 1.0)) throw std::invalid_argument("TabulatedStructure: fold_fraction must lie in (0, 1)");
  if (table_.heights_m.size() < 2)
    throw std::invalid_argument("TabulatedStructure: heights_m needs at least 2 heights");
}

StructureTableData TabulatedStructure::load(const std::string& path) {
  StructureTableData t;
  try {
    const YAML::Node root = YAML::LoadFile(path);
    for (const char* key : {"heights_m", "pressures_pa", "volume_m3", "plate_force_n"}) {
      if (!root[key]) throw std::runtime_error(std::string("missing key '") + key + "'");
    }
    if (root["description"]) t.description = root["description"].as<std::string>();
    t.heights_m = root["heights_m"].as<std::vector<double>>();
    t.pressures_pa = root["pressures_pa"].as<std::vector<double>>();
    t.volume_m3 = root["volume_m3"].as<std::vector<std::vector<double>>>();
    t.plate_force_n = root["plate_force_n"].as<std::vector<std::vector<double>>>();
  } catch (const std::exception& e) {
    throw std::runtime_error("structure table " + path + ": " + e.what());
  }
  const Status valid = t.validate();
  if (!valid) throw std::runtime_error("structure table " + path + ": " + valid.message());
  return t;
}

double TabulatedStructure::interpolate(const std::vector<std::vector<double>>& g, double h, double p) const {
  const auto [i, a] = locate(table_.heights_m, h);
  const auto [j, b] = locate(table_.pressures_pa, p);
  return (1 - a) * ((1 - b) * g[i][j] + b * g[i][j + 1]) + a * ((1 - b) * g[i + 1][j] + b * g[i + 1][j + 1]);
}

std::array<double, kMaxShapeDofs> TabulatedStructure::restShape() const {
  return {table_.pressures_pa.front() / kShapeUnitPa};
}

StructureEval TabulatedStructure::evaluate(double height_m, const double* shape) const {
  if (height_m < 0.0) {
    // Pressed into the film stack the gas lifts the plate over the folds' area (FlatFold, which
    // is energy-consistent by itself; its area is the lowest row's force per pressure, so the
    // force is continuous at flat) and the films' own force is the bed contact's.
    StructureEval flat = evaluate(0.0, shape);
    flat.plate_force_n = 0.0;
    return fold_.below(height_m, flat);
  }
  StructureEval e;
  const double q_raw = shape[0] * kShapeUnitPa;
  const double q = std::clamp(q_raw, table_.pressures_pa.front(), table_.pressures_pa.back());
  // The FE bag's plate force per pressure (its force scales with the pressure the film holds).
  const double force_area = std::max(interpolate(table_.plate_force_n, height_m, q) / q, 0.0);
  const VolumeAt v = volumeAt(height_m, q_raw);
  e.volume_m3 = v.volume_m3;
  const double dvdh = v.dvdh_m2;
  // The gas works through its own volume: A_eff = dV/dh of the volume the cell has, so its
  // energy follows p dV exactly (paper eq. 14). The FE bag's plate force is not p dV/dh (its
  // film's tension pushes or pulls the plate too): the rest is the film's own force on the
  // plate, scaled by the film's pressure as the FE force is, so plate and FE still agree.
  e.effective_area_m2 = dvdh;
  e.plate_force_n = shape[0] * kShapeUnitPa * (force_area - dvdh);
  const double dvdq = v.dvdq_m3_pa;
  const double dvdp = std::max(dvdq, 1e-3 * e.volume_m3 / table_.pressures_pa.back());
  e.dvolume_dshape[0] = dvdp * kShapeUnitPa;
  e.elastic_force[0] = shape[0] * kShapeUnitPa * e.dvolume_dshape[0];  // balance at q = p
  // dq/dt = (p - q) dV/dq / damping: q follows p with the film's relaxation time.
  e.shape_damping[0] = relaxation_time_s_ * e.dvolume_dshape[0] * kShapeUnitPa;
  e.contact_area_m2 = force_area;
  // Rough: for heat exchange only.
  e.surface_area_m2 = 4.0 * e.volume_m3 / std::max(height_m, table_.heights_m.front());
  return e;
}

TabulatedStructure::VolumeAt TabulatedStructure::volumeAt(double height_m, double q_pa) const {
  // Each row's volume is linear in the film's pressure between the columns and, below the lowest,
  // along the first two (the film goes slack towards q = 0), so V and dV/dq are continuous there.
  const std::vector<double>& ps = table_.pressures_pa;
  const double q = std::clamp(q_pa, 0.0, ps.back());
  std::size_t j = std::upper_bound(ps.begin(), ps.end(), q) - ps.begin();
  j = std::min(std::max<std::size_t>(j, 1), ps.size() - 1) - 1;
  const double dp = ps[j + 1] - ps[j];
  const bool held = q_pa >= ps.back() || q_pa <= 0.0;  // clamped: the volume holds
  auto row = [&](std::size_t r, double* slope) {
    const double v0 = table_.volume_m3[r][j], v1 = table_.volume_m3[r][j + 1];
    *slope = held ? 0.0 : (v1 - v0) / dp;
    return v0 + (q - ps[j]) * (v1 - v0) / dp;
  };
  // The table (bilinear), with its slope from the same two rows.
  const auto [i, a] = locate(table_.heights_m, height_m);
  const double h_lo = table_.heights_m[i], h_hi = table_.heights_m[i + 1];
  double s_lo = 0.0, s_hi = 0.0;
  const double v_lo = row(i, &s_lo), v_hi = row(i + 1, &s_hi);
  VolumeAt v;
  double volume = (1 - a) * v_lo + a * v_hi;
  v.dvdh_m2 = (v_hi - v_lo) / (h_hi - h_lo);
  v.dvdq_m3_pa = (1 - a) * s_lo + a * s_hi;
  if (height_m > table_.heights_m.back()) v.dvdh_m2 = 0.0;  // the table's volume is held there
  // Below the lowest height V follows the lowest rows' dV/dh down to the dead volume (fitting,
  // tube, folds). Not F/q: near flat the plate force is the film stack's contact (F/q reached
  // 2.7x the face area at 3 mm, 1 kPa), which would empty the flat cell to nothing.
  if (height_m < h_lo && v.dvdh_m2 > 0.0) {
    const double below = h_lo - std::max(height_m, 0.0);
    volume -= below * v.dvdh_m2;
    v.dvdq_m3_pa -= below * (s_hi - s_lo) / (h_hi - h_lo);
  }
  v.dvdh_m2 = std::max(v.dvdh_m2, 0.0);
  // Joined to the dead volume by a softplus over 2 % of it: a kink in V makes A_eff jump, and a
  // plate bouncing across it integrates p dV one-sidedly.
  const double width = 0.02 * dead_volume_m3_, x = (volume - dead_volume_m3_) / width;
  const double share = 1.0 / (1.0 + std::exp(-std::clamp(x, -50.0, 50.0)));
  v.volume_m3 = dead_volume_m3_ + width * (x > 30.0 ? x : std::log1p(std::exp(x)));
  v.dvdh_m2 *= share;
  v.dvdq_m3_pa *= share;
  return v;
}

double TabulatedStructure::heightLimit(const double* /*shape*/) const { return table_.heights_m.back(); }

bool TabulatedStructure::withinLimits(double height_m, const double* shape) const {
  return height_m <= table_.heights_m.back() * (1.0 + 1e-9) &&
         shape[0] * kShapeUnitPa <= table_.pressures_pa.back() * (1.0 + 1e-9);
}

std::string TabulatedStructure::describe() const {
  std::ostringstream s;
  s << "FE table (" << table_.heights_m.size() << " heights x " << table_.pressures_pa.size()
    << " pressures): " << table_.description;
  return s.str();
}

}  // namespace nursing_bed
