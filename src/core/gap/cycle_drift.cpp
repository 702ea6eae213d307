// The cycles' gas balance and the whole-breath rule that names a slow drift above the model-form
// floor (include/nursing_bed/core/gap/cycle_drift.h).
#include "nursing_bed/core/gap/cycle_drift.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>

#include "nursing_bed/core/gap/calibration.h"
#include "nursing_bed/core/gap/localisation.h"
#include "nursing_bed/core/gap/replay.h"
#include "nursing_bed/core/physics/cell_model.h"
#include "nursing_bed/core/physics/gas.h"

namespace nursing_bed {
namespace gap {
namespace {

constexpr double kMinCycleS = 0.2;       // a start this close to the one before is the same edge
constexpr double kDriftZ = 3.0;          // the calibrated cell's balance on the fit runs stands out
constexpr double kHeldZ = 1.645;         // ... and the withheld runs confirm its sign (one-sided 5 %)
constexpr double kLeftOver = 0.25;       // the rescaled model leaves under this share of it
constexpr double kPeriodSlack = 0.1;     // a cycle counts when this close to the median
constexpr double kContentStepPa = 10.0;  // central-difference step of the content's slope
constexpr int kTried = 4;                // candidates rescaled at most (the rest rank lower still)

/// cycleStarts() less any start within `min_cycle_s` of the one before (a run cut on a cycle
/// edge starts a sample before it: that sample is not a cycle of its own).
std::vector<double> distinctStarts(const RunData& run, double min_cycle_s) {
  std::vector<double> kept;
  for (double s : cycleStarts(run))
    if (kept.empty() || s - kept.back() >= min_cycle_s) kept.push_back(s);
  return kept;
}

/// Sample index of each whole cycle's two ends: the foot of each distinct start's setpoint rise
/// (the last sample before the setpoint climbs to it), the run's last sample closing its last
/// cycle; a cycle counts when it is `period` long within kPeriodSlack (NaN: the run's own).
std::vector<std::pair<std::size_t, std::size_t>> wholeCycles(const RunData& run, double period_s) {
  std::vector<std::pair<std::size_t, std::size_t>> cycles;
  if (run.size() < 2) return cycles;
  const double period = std::isfinite(period_s) ? period_s : medianCyclePeriod({&run}, kMinCycleS);
  if (!std::isfinite(period)) return cycles;
  const std::vector<double>& sp = run.p_setpoint_gauge_pa;
  std::vector<std::size_t> ends;
  for (double s : distinctStarts(run, kMinCycleS)) {
    std::size_t i = static_cast<std::size_t>(std::lower_bound(run.t_s.begin(), run.t_s.end(), s) - run.t_s.begin());
    if (sp.size() == run.size())
      while (i > 0 && sp[i - 1] < sp[i]) --i;
    if (ends.empty() || i > ends.back()) ends.push_back(i);
  }
  if (ends.back() + 1 < run.size()) ends.push_back(run.size() - 1);
  for (std::size_t k = 1; k < ends.size(); ++k) {
    const double length = run.t_s[ends[k]] - run.t_s[ends[k - 1]];
    if (std::fabs(length - period) <= kPeriodSlack * period) cycles.emplace_back(ends[k - 1], ends[k]);
  }
  return cycles;
}

/// The metered gas [kg] over samples a..b (NaN with a missing flow sample).
double meteredGas(const RunData& run, std::size_t a, std::size_t b) {
  double gas = 0.0;
  for (std::size_t i = a + 1; i <= b; ++i)
    gas += 0.5 * (run.mdot_in_kg_s[i] + run.mdot_in_kg_s[i - 1]) * (run.t_s[i] - run.t_s[i - 1]);
  return gas;
}

/// Each run's content rates under `params` with `effects`, from its replay (an empty list where
/// a replay fails or a run is not cyclic).
std::vector<std::vector<CycleRate>> replayedContentRates(const std::vector<const RunData*>& runs,
                                                         const CellParams& params,
                                                         const std::vector<CellEffectPtr>& effects,
                                                         const CellContent& content, double period, int threads) {
  std::vector<std::vector<CycleRate>> out(runs.size());
  parallelFor(static_cast<int>(runs.size()), threads, [&](int i) {
    const Replay r = replayRun(*runs[i], params, effects);
    if (r.ok) out[i] = contentRates(*runs[i], r.p_gauge_pa, content, period);
  });
  return out;
}

/// Each run's measured balance.
std::vector<std::vector<CycleRate>> measuredBalances(const std::vector<const RunData*>& runs,
                                                     const CellContent& content, double period) {
  std::vector<std::vector<CycleRate>> out;
  for (const RunData* r : runs) out.push_back(cycleBalances(*r, content, period));
  return out;
}

/// `balance` plus what a model adds to it: the change of content of its replay less the
/// calibrated model's, cycle by cycle (a cycle missing from either is left out).
std::vector<std::vector<CycleRate>> shifted(const std::vector<std::vector<CycleRate>>& balance,
                                            const std::vector<std::vector<CycleRate>>& model,
                                            const std::vector<std::vector<CycleRate>>& calibrated) {
  std::vector<std::vector<CycleRate>> out(balance.size());
  for (std::size_t r = 0; r < balance.size(); ++r)
    for (const CycleRate& b : balance[r]) {
      auto at = [&](const std::vector<CycleRate>& v) {
        return std::find_if(v.begin(), v.end(), [&](const CycleRate& c) { return std::fabs(c.t_s - b.t_s) < 1e-9; });
      };
      const auto m = at(model[r]), c = at(calibrated[r]);
      if (m == model[r].end() || c == calibrated[r].end()) continue;
      out[r].push_back({b.t_s, b.duration_s, b.rate_kg_s + m->rate_kg_s - c->rate_kg_s});
    }
  return out;
}

/// The balance's floor: one pressure sample's noise at each end of a cycle, in content, over the
/// cycle (identical cycles do not make a balance significant).
double balanceFloor(const PreparedRuns& prepared, const std::vector<std::size_t>& indices, const CellContent& content,
                    double period) {
  std::vector<double> floors;
  for (std::size_t i : indices) {
    const RunData& r = prepared.runs[i];
    const double slope = r.size() > 0 ? content.slopeKgPa(r.p_gauge_pa.front()) : NAN;
    if (std::isfinite(slope)) floors.push_back(std::sqrt(2.0) * prepared.noises[i].p_pa * slope / period);
  }
  return floors.empty() ? 0.0 : median(floors);
}

/// The one effect parameter of a single candidate away from its off value; empty when none or
/// more than one (a one-parameter drift only: its balance is linear in that parameter's move).
std::string driftParameter(const ModelSpec& model, const std::map<std::string, double>& values) {
  std::string name;
  for (const FitAxis& a : model.axes) {
    if (a.calibration || !values.count(a.spec.name) || values.at(a.spec.name) == a.spec.off_value) continue;
    if (!name.empty()) return "";
    name = a.spec.name;
  }
  return name;
}

/// A balance in mg/s (1 mL/s of air at 1.2 kg/m^3 is 1.2 mg/s).
std::string balanceInWords(const BalanceMean& b) {
  return fmt(b.mean_kg_s * 1e6, 3) + " ± " + fmt(b.se_kg_s * 1e6, 2) + " mg/s over " + std::to_string(b.points) +
         " cycle(s)";
}

/// What the rule measures once: the runs by role, their measured balances and the calibrated
/// model's replayed content rates, and the floors and scatter their means are judged with.
struct BalanceSets {
  BalanceSets(const CellContent& c, double period) : content(c), period_s(period) {}
  CellContent content;
  double period_s;
  std::vector<const RunData*> fit_runs, held_runs;
  std::vector<std::vector<CycleRate>> fit_balance, held_balance, fit_calibrated, held_calibrated;
  double fit_floor = 0.0, held_floor = 0.0, fit_scatter = NAN;

  BalanceMean fitMean(const std::vector<std::vector<CycleRate>>& b) const { return meanBalance(b, fit_floor); }
  BalanceMean heldMean(const std::vector<std::vector<CycleRate>>& b) const {
    return meanBalance(b, held_floor, fit_scatter);
  }
};

/// What tryCandidate() found.
enum class DriftTry { kNotMoved, kRejected, kNamed };

/// The scored candidate with its drift parameter rescaled to cancel the calibrated cell's
/// balance on the fit runs, judged on the fit and withheld runs; fills `naming` when named.
DriftTry tryCandidate(const BalanceSets& sets, const CellParams& params, const ScoredCandidate& scored,
                      const DiagnosisOptions& options, const std::string& parameter, DriftNaming* naming) {
  const CandidateFit& c = scored.first;
  const ModelSpec& model = scored.second;
  const CellParams cell = applyCalibration(c.calibration, params);
  auto balanceWith = [&](const std::map<std::string, double>& values, bool fit) {
    const auto& runs = fit ? sets.fit_runs : sets.held_runs;
    return shifted(
        fit ? sets.fit_balance : sets.held_balance,
        replayedContentRates(runs, cell, buildEffects(model, values), sets.content, sets.period_s, options.threads),
        fit ? sets.fit_calibrated : sets.held_calibrated);
  };
  const BalanceMean as_fitted = sets.fitMean(balanceWith(c.params, true));
  const double b0 = naming->fit_before.mean_kg_s, moved = b0 - as_fitted.mean_kg_s;
  const std::string name = joinNames(c.effects);
  if (!as_fitted.ok() || !(moved * b0 > 0.0)) {
    naming->reasons.push_back("whole breaths: " + name + " does not move the cycles' balance towards zero");
    return DriftTry::kNotMoved;
  }
  const FitAxis& axis = *std::find_if(model.axes.begin(), model.axes.end(),
                                      [&](const FitAxis& a) { return !a.calibration && a.spec.name == parameter; });
  std::map<std::string, double> values = c.params;
  values[parameter] = axis.spec.off_value + (c.params.at(parameter) - axis.spec.off_value) * b0 / moved;
  const double u = axis.toU(values[parameter]);
  if (!(u >= axis.u_min && u <= axis.u_max)) {
    naming->reasons.push_back("whole breaths: " + name + " would need " + parameter + " " + fmt(values[parameter], 4) +
                              ", outside its admissible range");
    return DriftTry::kRejected;
  }
  const BalanceMean after = sets.fitMean(balanceWith(values, true));
  const BalanceMean held_after = sets.heldMean(balanceWith(values, false));
  const bool plausible = plausibleValues(model, values, options.plausible_slack);
  const bool fit_ok = after.ok() && std::fabs(after.mean_kg_s) <= 2.0 * after.se_kg_s &&
                      std::fabs(after.mean_kg_s) <= kLeftOver * std::fabs(b0);
  const BalanceMean& hb = naming->held_before;
  const bool held_ok = hb.ok() && hb.mean_kg_s * b0 > 0.0 && hb.significant(kHeldZ) && held_after.ok() &&
                       std::fabs(held_after.mean_kg_s) <= (1.0 - options.floor_removed) * std::fabs(hb.mean_kg_s);
  naming->reasons.push_back("whole breaths: " + name + " with " + parameter + " " + fmt(values[parameter], 4) +
                            " (fitted " + fmt(c.params.at(parameter), 4) + ") leaves " + balanceInWords(after) +
                            " on the fit runs, " + balanceInWords(held_after) + " on the withheld runs" +
                            (!plausible          ? ": implausible"
                             : fit_ok && held_ok ? ": named"
                                                 : ": does not cancel the balance"));
  if (!plausible || !fit_ok || !held_ok) return DriftTry::kRejected;
  naming->params = values;
  naming->fit_after = after;
  naming->held_after = held_after;
  return DriftTry::kNamed;
}

/// The measured balances and the calibrated model's replays of `prepared`'s runs.
BalanceSets measureSets(const PreparedRuns& prepared, const CellParams& calibrated, double period, int threads) {
  BalanceSets sets(CellContent(calibrated, prepared.runs.front().loadAt(0)), period);
  sets.fit_runs = prepared.select(prepared.fit);
  sets.held_runs = prepared.select(prepared.withheld);
  sets.fit_balance = measuredBalances(sets.fit_runs, sets.content, period);
  sets.held_balance = measuredBalances(sets.held_runs, sets.content, period);
  sets.fit_calibrated = replayedContentRates(sets.fit_runs, calibrated, {}, sets.content, period, threads);
  sets.held_calibrated = replayedContentRates(sets.held_runs, calibrated, {}, sets.content, period, threads);
  sets.fit_floor = balanceFloor(prepared, prepared.fit, sets.content, period);
  sets.held_floor = balanceFloor(prepared, prepared.withheld, sets.content, period);
  sets.fit_scatter = cycleScatter(sets.fit_balance);
  return sets;
}

}  // namespace

CellContent::CellContent(const CellParams& params, double load_n)
    : params_(params), structure_(makeCellStructure(params)), load_n_(load_n) {}

double CellContent::massKg(double gauge_pressure_pa) const {
  if (!std::isfinite(gauge_pressure_pa)) return NAN;
  const StructureEquilibrium eq = structure_->equilibriumAtPressure(gauge_pressure_pa, load_n_);
  if (!eq.converged) return NAN;
  const double p = params_.ambient_pressure_pa + gauge_pressure_pa, t = params_.ambient_temperature_k;
  return massFromState(params_.gas, p, t, eq.eval.volume_m3) +
         massFromState(params_.gas, p, t, params_.airway.volume_m3);
}

double CellContent::slopeKgPa(double gauge_pressure_pa) const {
  return (massKg(gauge_pressure_pa + kContentStepPa) - massKg(gauge_pressure_pa - kContentStepPa)) /
         (2.0 * kContentStepPa);
}

double medianCyclePeriod(const std::vector<const RunData*>& runs, double min_cycle_s) {
  std::vector<double> periods;
  for (const RunData* run : runs) {
    const std::vector<double> starts = distinctStarts(*run, min_cycle_s);
    for (std::size_t k = 1; k < starts.size(); ++k) periods.push_back(starts[k] - starts[k - 1]);
  }
  return periods.empty() ? NAN : median(periods);
}

std::vector<CycleRate> contentRates(const RunData& run, const std::vector<double>& p_pa, const CellContent& content,
                                    double period_s) {
  if (p_pa.size() != run.size())
    throw std::invalid_argument("content rates: " + std::to_string(p_pa.size()) + " pressures for a run of " +
                                std::to_string(run.size()) + " samples");
  std::vector<CycleRate> out;
  for (const auto& [a, b] : wholeCycles(run, period_s)) {
    const double duration = run.t_s[b] - run.t_s[a];
    const double change = content.massKg(p_pa[b]) - content.massKg(p_pa[a]);
    if (std::isfinite(change)) out.push_back({run.t_s[b] - run.t_s.front(), duration, change / duration});
  }
  return out;
}

std::vector<CycleRate> cycleBalances(const RunData& run, const CellContent& content, double period_s) {
  std::vector<CycleRate> out;
  for (const auto& [a, b] : wholeCycles(run, period_s)) {
    const double duration = run.t_s[b] - run.t_s[a];
    const double held = content.massKg(run.p_gauge_pa[b]) - content.massKg(run.p_gauge_pa[a]);
    const double balance = meteredGas(run, a, b) - held;
    if (std::isfinite(balance)) out.push_back({run.t_s[b] - run.t_s.front(), duration, balance / duration});
  }
  return out;
}

double cycleScatter(const std::vector<std::vector<CycleRate>>& runs) {
  std::vector<double> x;
  for (const auto& run : runs)
    for (const CycleRate& c : run) x.push_back(c.rate_kg_s);
  if (x.size() < 2) return NAN;
  const double m = std::accumulate(x.begin(), x.end(), 0.0) / static_cast<double>(x.size());
  double ss = 0.0;
  for (double v : x) ss += (v - m) * (v - m);
  return std::sqrt(ss / static_cast<double>(x.size() - 1));
}

BalanceMean meanBalance(const std::vector<std::vector<CycleRate>>& runs, double floor_kg_s, double scatter_kg_s) {
  BalanceMean m;
  double sum = 0.0;
  for (const auto& run : runs)
    for (const CycleRate& c : run) {
      sum += c.rate_kg_s;
      ++m.points;
    }
  if (m.points == 0) return m;
  m.mean_kg_s = sum / m.points;
  const double own = cycleScatter(runs), scatter = m.points >= 2 ? own : scatter_kg_s;
  if (std::isfinite(scatter)) m.se_kg_s = std::max(scatter, floor_kg_s) / std::sqrt(static_cast<double>(m.points));
  return m;
}

DriftNaming nameDriftAboveFloor(const PreparedRuns& prepared, const CellParams& params,
                                const std::map<std::string, double>& baseline,
                                const std::vector<ScoredCandidate>& scored, const DiagnosisOptions& options) {
  DriftNaming naming;
  std::vector<const RunData*> all;
  for (const RunData& r : prepared.runs) all.push_back(&r);
  naming.period_s = medianCyclePeriod(all, kMinCycleS);
  if (!std::isfinite(naming.period_s)) return naming;  // not cyclic: nothing to say
  const BalanceSets sets = measureSets(prepared, applyCalibration(baseline, params), naming.period_s, options.threads);
  naming.fit_before = sets.fitMean(sets.fit_balance);
  naming.held_before = sets.heldMean(sets.held_balance);
  if (naming.fit_before.points < 2) {  // a mean with its scatter needs 2 cycles on the fit runs
    naming.reasons.push_back("whole breaths: " + std::to_string(naming.fit_before.points) +
                             " whole cycle(s) on the fit runs; a balance with its scatter needs at least 2: not "
                             "measured");
    return naming;
  }
  naming.reasons.push_back("whole breaths: the calibrated cell's gas balance (metered less held) is " +
                           balanceInWords(naming.fit_before) + " on the fit runs, " +
                           balanceInWords(naming.held_before) + " on the withheld runs");
  if (!naming.fit_before.significant(kDriftZ)) return naming;
  int tried = 0;
  for (std::size_t i = 0; i < scored.size() && tried < kTried; ++i) {
    const CandidateFit& c = scored[i].first;
    if (!c.ok || c.effects.size() != 1 || !(c.bic_delta < 0.0)) continue;
    const std::string parameter = driftParameter(scored[i].second, c.params);
    if (parameter.empty()) continue;
    const DriftTry outcome = tryCandidate(sets, params, scored[i], options, parameter, &naming);
    if (outcome == DriftTry::kNamed) {
      naming.winner = static_cast<int>(i);
      return naming;
    }
    if (outcome == DriftTry::kRejected) ++tried;
  }
  naming.reasons.push_back("whole breaths: no single candidate cancels the cycles' balance");
  return naming;
}

}  // namespace gap
}  // namespace nursing_bed
