#include "nursing_bed/core/physics/fold_table_structure.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace nursing_bed {
namespace {

constexpr double kShapeUnitPa = 1.0e4;  // q0: the relaxed pressure in 10 kPa, as TabulatedStructure's
constexpr double kFoldDampingJs = 1.0;  // any positive value: ds/dt = foldRate whatever it is

/// Linear interpolation of y over the strictly increasing x, clamped at the ends.
double interpolate(const std::vector<double>& x, const std::vector<double>& y, double at) {
  if (at <= x.front()) return y.front();
  if (at >= x.back()) return y.back();
  const std::size_t i = std::upper_bound(x.begin(), x.end(), at) - x.begin();
  const double a = (at - x[i - 1]) / (x[i] - x[i - 1]);
  return (1 - a) * y[i - 1] + a * y[i];
}

double logistic(double x) { return 1.0 / (1.0 + std::exp(-std::clamp(x, -50.0, 50.0))); }

StructureTableData readTable(const YAML::Node& node, const std::string& name) {
  if (!node) throw std::runtime_error("missing key '" + name + "'");
  StructureTableData t;
  for (const char* key : {"heights_m", "pressures_pa", "volume_m3", "plate_force_n"}) {
    if (!node[key]) throw std::runtime_error("missing key '" + name + "/" + key + "'");
  }
  t.description = name;
  t.heights_m = node["heights_m"].as<std::vector<double>>();
  t.pressures_pa = node["pressures_pa"].as<std::vector<double>>();
  t.volume_m3 = node["volume_m3"].as<std::vector<std::vector<double>>>();
  t.plate_force_n = node["plate_force_n"].as<std::vector<std::vector<double>>>();
  return t;
}

}  // namespace

Status FoldTableData::validate() const {
  for (const auto& [name, table] : {std::pair{"folded", &folded}, std::pair{"open", &open}}) {
    const Status s = table->validate();
    if (!s) return Status::error(std::string(name) + ": " + s.message());
  }
  const std::size_t n = snap_loads_n.size();
  for (std::size_t i = 0; i < n; ++i) {
    if (!std::isfinite(snap_loads_n[i]) || (i > 0 && !(snap_loads_n[i] > snap_loads_n[i - 1])))
      return Status::error("snap/loads_n must be finite and strictly increasing");
  }
  if (n < 1) return Status::error("snap/loads_n needs at least one load");
  if (open_pa.size() != n || close_pa.size() != n)
    return Status::error("snap/open_pa and snap/close_pa need one value per snap load");
  for (std::size_t i = 0; i < n; ++i) {
    if (!std::isfinite(open_pa[i]) || !std::isfinite(close_pa[i]) || close_pa[i] > open_pa[i])
      return Status::error("snap/close_pa must be finite and not above snap/open_pa");
  }
  if (!(fold_time_s > 0.0 && std::isfinite(fold_time_s))) return Status::error("fold_time_s must be positive");
  if (!(snap_width_pa > 0.0 && std::isfinite(snap_width_pa))) return Status::error("snap_width_pa must be positive");
  return Status::success();
}

namespace {
const FoldTableData& validated(const FoldTableData& d) {
  const Status valid = d.validate();
  if (!valid) throw std::invalid_argument("FoldTableStructure: " + valid.message());
  return d;
}
}  // namespace

FoldTableStructure::FoldTableStructure(FoldTableData data, double film_relaxation_time_s, double dead_volume_m3,
                                       double fold_fraction)
    : data_(validated(data)),
      folded_(data_.folded, film_relaxation_time_s, dead_volume_m3, fold_fraction),
      open_(data_.open, film_relaxation_time_s, dead_volume_m3, fold_fraction) {}

FoldTableData FoldTableStructure::load(const std::string& path) {
  FoldTableData d;
  try {
    const YAML::Node root = YAML::LoadFile(path);
    if (root["description"]) d.description = root["description"].as<std::string>();
    d.folded = readTable(root["folded"], "folded");
    d.open = readTable(root["open"], "open");
    const YAML::Node snap = root["snap"];
    for (const char* key : {"loads_n", "open_pa", "close_pa"}) {
      if (!snap || !snap[key]) throw std::runtime_error(std::string("missing key 'snap/") + key + "'");
    }
    d.snap_loads_n = snap["loads_n"].as<std::vector<double>>();
    d.open_pa = snap["open_pa"].as<std::vector<double>>();
    d.close_pa = snap["close_pa"].as<std::vector<double>>();
    if (root["fold_time_s"]) d.fold_time_s = root["fold_time_s"].as<double>();
    if (root["snap_width_pa"]) d.snap_width_pa = root["snap_width_pa"].as<double>();
  } catch (const std::exception& e) {
    throw std::runtime_error("fold table " + path + ": " + e.what());
  }
  const Status valid = d.validate();
  if (!valid) throw std::runtime_error("fold table " + path + ": " + valid.message());
  return d;
}

std::array<double, kMaxShapeDofs> FoldTableStructure::restShape() const {
  return {data_.folded.pressures_pa.front() / kShapeUnitPa, 0.0};
}

double FoldTableStructure::foldRate(double s, double gauge_pressure_pa, double height_m) const {
  const double q = gauge_pressure_pa / kShapeUnitPa;
  const double p = std::clamp(gauge_pressure_pa, data_.folded.pressures_pa.front(), data_.folded.pressures_pa.back());
  // The load each branch would carry here: the snap pressures are the FE's per load.
  const double load_folded = folded_.evaluate(height_m, &q).plateForce(p);
  const double load_open = open_.evaluate(height_m, &q).plateForce(p);
  const double w = data_.snap_width_pa;
  const double a_open = logistic((gauge_pressure_pa - interpolate(data_.snap_loads_n, data_.open_pa, load_folded)) / w);
  const double a_close = logistic((interpolate(data_.snap_loads_n, data_.close_pa, load_open) - gauge_pressure_pa) / w);
  // Between the thresholds s = 0 and s = 1 are both stable (the cubic); past one the drive wins.
  return (a_open * (1.0 - s) - a_close * s + 4.0 * s * (1.0 - s) * (s - 0.5)) / data_.fold_time_s;
}

StructureEval FoldTableStructure::evaluate(double height_m, const double* shape) const {
  const double s = std::clamp(shape[1], 0.0, 1.0);
  const StructureEval f = folded_.evaluate(height_m, shape);
  const StructureEval o = open_.evaluate(height_m, shape);
  auto mix = [s](double a, double b) { return (1.0 - s) * a + s * b; };
  StructureEval e;
  e.volume_m3 = mix(f.volume_m3, o.volume_m3);
  e.effective_area_m2 = mix(f.effective_area_m2, o.effective_area_m2);
  e.dvolume_dshape[0] = mix(f.dvolume_dshape[0], o.dvolume_dshape[0]);
  e.elastic_force[0] = mix(f.elastic_force[0], o.elastic_force[0]);
  e.shape_damping[0] = mix(f.shape_damping[0], o.shape_damping[0]);
  e.plate_force_n = mix(f.plate_force_n, o.plate_force_n);
  e.contact_area_m2 = mix(f.contact_area_m2, o.contact_area_m2);
  e.surface_area_m2 = mix(f.surface_area_m2, o.surface_area_m2);
  // The fold moves at foldRate: its residual dW/ds - p dV/ds depends on s, q0 and h only (the
  // film's q0 standing for p, which it follows within the film's relaxation time), so the film
  // balance (relaxedShape) solves it beside q0. The coordinate is taken unclamped there: past 0
  // or 1 the cubic pulls it back (a flat drive would leave the Newton solve without a slope).
  // dV/ds is the tables' difference: the snap's volume change is p dV work of the gas (its
  // energy follows the volume), taken up by the fold's own balance.
  const double dvds = shape[1] >= 0.0 && shape[1] <= 1.0 ? o.volume_m3 - f.volume_m3 : 0.0;  // V holds past the ends
  e.dvolume_dshape[1] = dvds;
  e.shape_damping[1] = kFoldDampingJs;
  e.elastic_force[1] =
      -kFoldDampingJs * foldRate(shape[1], shape[0] * kShapeUnitPa, height_m) + shape[0] * kShapeUnitPa * dvds;
  return e;
}

std::array<double, kMaxShapeDofs> FoldTableStructure::relaxedShape(double height_m, double gauge_pressure_pa,
                                                                   const double* initial_shape) const {
  std::array<double, kMaxShapeDofs> q = initial_shape ? std::array<double, kMaxShapeDofs>{} : restShape();
  if (initial_shape) std::copy(initial_shape, initial_shape + shapeDofs(), q.begin());
  // Both tables balance their film at q0 = p whatever the fold: solve it on one of them.
  q[0] = folded_.relaxedShape(height_m, gauge_pressure_pa, q.data())[0];
  // The fold follows its own flow from s to the first state where it stops: g(0) >= 0 and
  // g(1) <= 0, so a root lies between s and the end the flow heads for.
  auto rate = [&](double s) { return foldRate(s, q[0] * kShapeUnitPa, height_m); };
  double s = std::clamp(q[1], 0.0, 1.0);
  // A fold at rest (its flow below 1e-9 per fold time) stays: the controller asks every period.
  const double g0 = rate(s);
  if (std::fabs(g0) < 1e-9) return q;
  const double direction = g0 > 0.0 ? 1.0 : -1.0;
  double from = s, to = s;
  for (int i = 0; i < 40; ++i) {  // steps of 1/40: two roots closer than that are a snap setting in
    to = std::clamp(from + direction / 40.0, 0.0, 1.0);
    if (to == from || direction * rate(to) <= 0.0) break;
    from = to;
  }
  for (int i = 0; i < 50 && std::fabs(to - from) > 1e-9; ++i) {  // the root between them
    const double mid = 0.5 * (from + to);
    (direction * rate(mid) > 0.0 ? from : to) = mid;
  }
  q[1] = 0.5 * (from + to);
  return q;
}

std::array<double, kMaxShapeDofs> FoldTableStructure::shapeAfter(double height_m, double gauge_pressure_pa,
                                                                 const double* initial_shape, double dt_s) const {
  std::array<double, kMaxShapeDofs> q = relaxedShape(height_m, gauge_pressure_pa, initial_shape);
  const double s0 = std::clamp(initial_shape[1], 0.0, 1.0);
  const double rest = q[1];
  const int steps = std::max(1, static_cast<int>(std::ceil(dt_s / (0.2 * data_.fold_time_s))));
  const double h = dt_s / steps;
  double s = s0;
  for (int i = 0; i < steps; ++i) {
    const double mid = std::clamp(s + 0.5 * h * foldRate(s, q[0] * kShapeUnitPa, height_m), 0.0, 1.0);
    s = std::clamp(s + h * foldRate(mid, q[0] * kShapeUnitPa, height_m), 0.0, 1.0);
  }
  q[1] = std::clamp(s, std::min(s0, rest), std::max(s0, rest));
  return q;
}

void FoldTableStructure::enterBranch(int branch, double* shape) const { shape[1] = branch == 0 ? 0.0 : 1.0; }

int FoldTableStructure::branchOf(const double* shape) const { return shape[1] >= 0.5 ? 1 : 0; }

double FoldTableStructure::heightLimit(const double* shape) const {
  return std::min(folded_.heightLimit(shape), open_.heightLimit(shape));
}

bool FoldTableStructure::withinLimits(double height_m, const double* shape) const {
  return folded_.withinLimits(height_m, shape) && open_.withinLimits(height_m, shape);
}

std::string FoldTableStructure::describe() const {
  std::ostringstream s;
  s << "FE fold table (folded and open branches, " << data_.snap_loads_n.size()
    << " snap loads): " << data_.description;
  return s.str();
}

}  // namespace nursing_bed
