#include "nursing_bed/core/physics/cell_characteristic.h"

#include <algorithm>
#include <cmath>
#include <future>
#include <map>
#include <mutex>

#include "nursing_bed/core/physics/cell_params_io.h"

namespace nursing_bed {

CellCharacteristic::CellCharacteristic(const CellParams& params, double height_max_m, double height_step_m,
                                       double load_max_n, double load_step_n)
    : params_(params), structure_(makeCellStructure(params)), height_step_m_(height_step_m), load_step_n_(load_step_n) {
  heights_ = static_cast<int>(std::lround(height_max_m / height_step_m)) + 1;
  loads_ = static_cast<int>(std::lround(load_max_n / load_step_n)) + 1;
  // A fold's two branches are tabulated side by side (a structure is immutable, so its solvers
  // may run in two threads): on the FE fold table each takes seconds, and a bed waits for them.
  std::vector<std::future<Table>> branches;
  for (int b = 0; b < structure_->branchCount(); ++b)
    branches.push_back(std::async(std::launch::async, [this, b] { return tabulate(b); }));
  for (auto& branch : branches) tables_.push_back(branch.get());
}

namespace {

// A closed cell filled slowly from flat rests on the equilibria in the order of their
// invariant; where the invariant dips with height or has no rest at all (a snap: an FE table's
// folds) the rest jumps over it: the running maximum from below keeps restingHeight()'s search
// on that path. A falling branch is reached from above (vented slowly from the top, the cell
// stays on the highest rest of its gas): the running minimum from the top.
void monotoneEnvelope(double* k, int count, bool from_top) {
  if (from_top) {
    for (int i = count - 2; i >= 0; --i) k[i] = std::isnan(k[i]) ? k[i + 1] : std::min(k[i], k[i + 1]);
  } else {
    for (int i = 1; i < count; ++i) k[i] = std::isnan(k[i]) ? k[i - 1] : std::max(k[i], k[i - 1]);
  }
}

}  // namespace

CellCharacteristic::Table CellCharacteristic::tabulate(int branch) const {
  Table t;
  t.pressure_pa.assign(heights_ * loads_, NAN);
  t.volume_m3.assign(heights_ * loads_, NAN);
  t.invariant.assign(heights_ * loads_, NAN);
  t.reachable.assign(loads_, 0);
  for (int j = 0; j < loads_; ++j) {
    const double load = std::max(j * load_step_n_, 1e-3);
    for (int i = 0; i < heights_; ++i) {
      const StructureEquilibrium eq = structure_->equilibriumAtHeight(i * height_step_m_, load, branch);
      // No rest here; an FE table may have rests again above such a gap (a fold that takes more
      // than the table's pressures to hold at this height): the plate passes it and snaps.
      if (!eq.converged) continue;
      t.pressure_pa[j * heights_ + i] = eq.gauge_pressure_pa;
      t.volume_m3[j * heights_ + i] = eq.eval.volume_m3;
      t.invariant[j * heights_ + i] = invariant(eq.gauge_pressure_pa, eq.eval.volume_m3);
      t.reachable[j] = i + 1;
    }
    monotoneEnvelope(&t.invariant[j * heights_], t.reachable[j], branch > 0);
  }
  return t;
}

const CellCharacteristic::Table& CellCharacteristic::table(int branch) const {
  return tables_[std::clamp(branch, 0, branches() - 1)];
}

std::shared_ptr<const CellCharacteristic> CellCharacteristic::shared(const CellParams& params) {
  static std::mutex mutex;
  // Kept for the life of the process: a bed has one or a few cell types, each ~0.1 MB.
  static std::map<std::string, std::shared_ptr<const CellCharacteristic>> cache;
  // The structure selection is text, not among the numbers cellParamsToYaml writes.
  const std::string key = cellParamsToYaml(params) + params.structure_type + "\n" + params.structure_table_file;
  std::lock_guard<std::mutex> lock(mutex);
  auto& entry = cache[key];
  if (!entry) entry = std::make_shared<const CellCharacteristic>(params);
  return entry;
}

double CellCharacteristic::invariant(double gauge_pressure_pa, double volume_m3) const {
  return (params_.ambient_pressure_pa + gauge_pressure_pa) * std::pow(volume_m3, params_.gas.heat_capacity_ratio);
}

double CellCharacteristic::invariantRate(double volume_m3, double mass_flow_kg_s, double temperature_k) const {
  // At fixed volume dU = cp T dm gives dp = gamma R T dm / V, so dK/dt = V^gamma gamma R T mdot / V.
  const double g = params_.gas.heat_capacity_ratio;
  return std::pow(volume_m3, g - 1.0) * g * params_.gas.gas_constant_j_kg_k * temperature_k * mass_flow_kg_s;
}

double CellCharacteristic::at(const std::vector<double>& table, double height_m, double load_n) const {
  const double x = std::clamp(height_m / height_step_m_, 0.0, heights_ - 1.0);
  const double y = std::clamp(load_n / load_step_n_, 0.0, loads_ - 1.0);
  const int i = std::min(static_cast<int>(x), heights_ - 2), j = std::min(static_cast<int>(y), loads_ - 2);
  const double fx = x - i, fy = y - j;
  // A node with no weight does not enter: at the edge of a load's reach its neighbour is NaN.
  auto lerp = [](double a, double b, double f) { return f == 0.0 ? a : (1 - f) * a + f * b; };
  auto row = [&](int jj) { return lerp(table[jj * heights_ + i], table[jj * heights_ + i + 1], fx); };
  return fy == 0.0 ? row(j) : lerp(row(j), row(j + 1), fy);
}

double CellCharacteristic::pressureAt(double height_m, double load_n, int branch) const {
  return at(table(branch).pressure_pa, height_m, load_n);
}

double CellCharacteristic::volumeAt(double height_m, double load_n, int branch) const {
  return at(table(branch).volume_m3, height_m, load_n);
}

CellCharacteristic::RelaxedCell CellCharacteristic::relaxedAt(double height_m, double gauge_pressure_pa,
                                                              Shape* shape) const {
  // Not a bisection on the tabulated equilibria for the load: an FE table's force is not
  // monotone through its snaps, and there a bisection lands on any of several loads (a cell
  // held at 72 mm read 26 N for 15.6 N).
  const double h = std::max(height_m, 0.0);
  const Shape q = structure_->relaxedShape(h, gauge_pressure_pa, shape ? shape->data() : nullptr);
  if (shape) *shape = q;
  const StructureEval e = structure_->evaluate(h, q.data());
  return {e.volume_m3, std::clamp(e.plateForce(gauge_pressure_pa), 0.0, (loads_ - 1) * load_step_n_),
          structure_->branchOf(q.data())};
}

double CellCharacteristic::relaxedVolume(double height_m, double gauge_pressure_pa, Shape* shape) const {
  return relaxedAt(height_m, gauge_pressure_pa, shape).volume_m3;
}

double CellCharacteristic::plateStiffness(double height_m, double load_n, int branch) const {
  // The closed cell's compliance is how far its rest moves per newton with the gas kept (K
  // fixed; the film relaxed, so its compliance softens the gas spring): from the tabulated
  // rests one load step either side, so over the table's cells rather than the film's local
  // slopes (an FE table's bilinear cells make those jump by orders of magnitude).
  const double k = restInvariant(height_m, load_n, branch);
  if (!(pressureAt(height_m, load_n, branch) > 0.0) || !std::isfinite(k)) return NAN;
  const double lighter = std::max(load_n - load_step_n_, 0.0), heavier = load_n + load_step_n_;
  const double rise = restingHeight(k, lighter, branch) - restingHeight(k, heavier, branch);
  return rise > 0.0 ? (heavier - lighter) / rise : NAN;
}

double CellCharacteristic::maxHeight(double load_n, int branch) const {
  const double y = std::clamp(load_n / load_step_n_, 0.0, loads_ - 1.0);
  const int j = std::min(static_cast<int>(y), loads_ - 2);
  const std::vector<int>& reachable = table(branch).reachable;
  return (std::min(reachable[j], reachable[j + 1]) - 1) * height_step_m_;
}

double CellCharacteristic::loadAt(double height_m, double gauge_pressure_pa) const {
  return relaxedAt(height_m, gauge_pressure_pa).load_n;
}

double CellCharacteristic::restInvariant(double height_m, double load_n, int branch) const {
  const double h = std::clamp(height_m, 0.0, std::max(maxHeight(load_n, branch), 0.0));
  return at(table(branch).invariant, h, load_n);
}

bool CellCharacteristic::gapBetween(double height_a_m, double height_b_m, double load_n, int branch) const {
  const Table& t = table(branch);
  const double y = std::clamp(load_n / load_step_n_, 0.0, loads_ - 1.0);
  const int j = std::min(static_cast<int>(y), loads_ - 2);
  const int from = static_cast<int>(std::floor(std::min(height_a_m, height_b_m) / height_step_m_));
  const int to = static_cast<int>(std::ceil(std::max(height_a_m, height_b_m) / height_step_m_));
  for (int jj : {j, j + 1}) {
    const double* k = &t.invariant[jj * heights_];
    for (int a = std::max(from, 0); a < std::min(to, t.reachable[jj] - 1); ++a)
      if (!(k[a + 1] > k[a])) return true;
  }
  return false;
}

double CellCharacteristic::restingHeight(double adiabatic_invariant, double load_n, int branch) const {
  // At a fixed load the table's interpolant is piecewise linear in the height, with the height
  // nodes as knots, and the invariant of the equilibria never falls with height: the first knot
  // above the invariant (binary search) brackets the rest, and the segment's line gives it.
  const double hi = maxHeight(load_n, branch);
  const std::vector<double>& invariants = table(branch).invariant;
  const int last = static_cast<int>(std::lround(hi / height_step_m_));
  const double y = std::clamp(load_n / load_step_n_, 0.0, loads_ - 1.0);
  const int j = std::min(static_cast<int>(y), loads_ - 2);
  const double fy = y - j;
  auto knot = [&](int i) { return (1 - fy) * invariants[j * heights_ + i] + fy * invariants[(j + 1) * heights_ + i]; };
  if (std::isnan(adiabatic_invariant)) return hi;  // nothing bounds an unknown invariant from above
  if (adiabatic_invariant <= knot(0)) return 0.0;
  if (last <= 0 || adiabatic_invariant >= knot(last)) return std::max(hi, 0.0);
  int below = 0, above = last;  // knot(below) <= K < knot(above)
  while (above - below > 1) {
    const int mid = (below + above) / 2;
    (knot(mid) > adiabatic_invariant ? above : below) = mid;
  }
  const double k0 = knot(below), k1 = knot(above);
  return (below + (adiabatic_invariant - k0) / (k1 - k0)) * height_step_m_;
}

}  // namespace nursing_bed
