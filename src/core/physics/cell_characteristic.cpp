#include "nursing_bed/core/physics/cell_characteristic.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <mutex>

#include "nursing_bed/core/physics/cell_params_io.h"

namespace nursing_bed {

CellCharacteristic::CellCharacteristic(const CellParams& params, double height_max_m, double height_step_m,
                                       double load_max_n, double load_step_n)
    : params_(params), structure_(makeCellStructure(params)), height_step_m_(height_step_m), load_step_n_(load_step_n) {
  heights_ = static_cast<int>(std::lround(height_max_m / height_step_m)) + 1;
  loads_ = static_cast<int>(std::lround(load_max_n / load_step_n)) + 1;
  pressure_pa_.assign(heights_ * loads_, NAN);
  volume_m3_.assign(heights_ * loads_, NAN);
  invariant_.assign(heights_ * loads_, NAN);
  reachable_.assign(loads_, 0);
  const CellStructure& structure = *structure_;
  for (int j = 0; j < loads_; ++j) {
    const double load = std::max(j * load_step_n, 1e-3);
    for (int i = 0; i < heights_; ++i) {
      const StructureEquilibrium eq = structure.equilibriumAtHeight(i * height_step_m, load);
      // No rest here; an FE table may have rests again above such a gap (a fold that takes more
      // than the table's pressures to hold at this height): the plate passes it and snaps.
      if (!eq.converged) continue;
      pressure_pa_[j * heights_ + i] = eq.gauge_pressure_pa;
      volume_m3_[j * heights_ + i] = eq.eval.volume_m3;
      invariant_[j * heights_ + i] = invariant(eq.gauge_pressure_pa, eq.eval.volume_m3);
      reachable_[j] = i + 1;
    }
    // A closed cell filled slowly from flat rests on the equilibria in the order of their
    // invariant; where the invariant dips with height or has no rest at all (a snap: an FE
    // table's folds) the rest jumps over it. The running maximum keeps restingHeight()'s
    // search on that branch.
    for (int i = 1; i < reachable_[j]; ++i) {
      double& k = invariant_[j * heights_ + i];
      const double below = invariant_[j * heights_ + i - 1];
      k = std::isnan(k) ? below : std::max(k, below);
    }
  }
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
  const double v00 = table[j * heights_ + i], v01 = table[j * heights_ + i + 1];
  const double v10 = table[(j + 1) * heights_ + i], v11 = table[(j + 1) * heights_ + i + 1];
  return (1 - fy) * ((1 - fx) * v00 + fx * v01) + fy * ((1 - fx) * v10 + fx * v11);
}

double CellCharacteristic::pressureAt(double height_m, double load_n) const {
  return at(pressure_pa_, height_m, load_n);
}

double CellCharacteristic::volumeAt(double height_m, double load_n) const { return at(volume_m3_, height_m, load_n); }

CellCharacteristic::RelaxedCell CellCharacteristic::relaxedAt(double height_m, double gauge_pressure_pa,
                                                              double* stretch) const {
  // Not a bisection on the tabulated equilibria for the load: an FE table's force is not
  // monotone through its snaps, and there a bisection lands on any of several loads (a cell
  // held at 72 mm read 26 N for 15.6 N).
  const double h = std::max(height_m, 0.0);
  auto guess = structure_->restShape();
  if (stretch && *stretch > 0.0) guess[0] = *stretch;
  const auto q = structure_->relaxedShape(h, gauge_pressure_pa, guess.data());
  if (stretch) *stretch = q[0];
  const StructureEval e = structure_->evaluate(h, q.data());
  return {e.volume_m3, std::clamp(gauge_pressure_pa * e.effective_area_m2, 0.0, (loads_ - 1) * load_step_n_)};
}

double CellCharacteristic::relaxedVolume(double height_m, double gauge_pressure_pa, double* stretch) const {
  return relaxedAt(height_m, gauge_pressure_pa, stretch).volume_m3;
}

double CellCharacteristic::plateStiffness(double height_m, double load_n) const {
  // Force on the plate of the closed cell (adiabatic invariant K fixed, film relaxed to the
  // pressure, so its compliance softens the gas spring) around the rest at height_m.
  const double p0 = pressureAt(height_m, load_n);
  if (!(p0 > 0.0)) return NAN;
  double stretch = structure_->restShape()[0];
  const double k_inv = invariant(p0, relaxedVolume(height_m, p0, &stretch));
  auto force = [&](double h) {
    double p = p0, s = stretch;
    for (int i = 0; i < 30; ++i) {
      const double p_new =
          k_inv / std::pow(relaxedVolume(h, p, &s), params_.gas.heat_capacity_ratio) - params_.ambient_pressure_pa;
      if (std::fabs(p_new - p) < 1e-6) break;
      p = p_new;
    }
    auto q = structure_->restShape();
    q[0] = s;
    return p * structure_->evaluate(h, q.data()).effective_area_m2;
  };
  const double dh = 2e-4;
  return -(force(height_m + dh) - force(height_m - dh)) / (2.0 * dh);
}

double CellCharacteristic::maxHeight(double load_n) const {
  const double y = std::clamp(load_n / load_step_n_, 0.0, loads_ - 1.0);
  const int j = std::min(static_cast<int>(y), loads_ - 2);
  return (std::min(reachable_[j], reachable_[j + 1]) - 1) * height_step_m_;
}

double CellCharacteristic::loadAt(double height_m, double gauge_pressure_pa) const {
  return relaxedAt(height_m, gauge_pressure_pa).load_n;
}

double CellCharacteristic::restingHeight(double adiabatic_invariant, double load_n) const {
  // At a fixed load the table's interpolant is piecewise linear in the height, with the height
  // nodes as knots, and the invariant of the equilibria never falls with height: the first knot
  // above the invariant (binary search) brackets the rest, and the segment's line gives it.
  const double hi = maxHeight(load_n);
  const int last = static_cast<int>(std::lround(hi / height_step_m_));
  const double y = std::clamp(load_n / load_step_n_, 0.0, loads_ - 1.0);
  const int j = std::min(static_cast<int>(y), loads_ - 2);
  const double fy = y - j;
  auto knot = [&](int i) { return (1 - fy) * invariant_[j * heights_ + i] + fy * invariant_[(j + 1) * heights_ + i]; };
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
