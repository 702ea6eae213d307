// The end-of-cycle residual, its trend through the runs, and the whole-breath rule that names a
// slow drift above the model-form floor (include/nursing_bed/core/gap/cycle_drift.h).
#include "nursing_bed/core/gap/cycle_drift.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "nursing_bed/core/gap/calibration.h"
#include "nursing_bed/core/gap/localisation.h"
#include "nursing_bed/core/gap/replay.h"

namespace nursing_bed {
namespace gap {
namespace {

constexpr double kWindowS = 0.2;      // the end of a cycle: the flow nearest rest
constexpr double kDriftZ = 3.0;       // the baseline's drift on the fit runs stands out
constexpr double kHeldZ = 2.0;        // ... and is there on the withheld runs
constexpr double kLeftOver = 0.25;    // the rescaled model leaves under this share of it
constexpr double kPeriodSlack = 0.1;  // a run's last cycle counts when this close to the median
constexpr int kTried = 4;             // candidates rescaled at most (the rest rank lower still)

/// cycleStarts() less any start within `min_cycle_s` of the one before (a run cut on a cycle
/// edge starts a sample before it: that sample is not a cycle of its own).
std::vector<double> distinctStarts(const RunData& run, double min_cycle_s) {
  std::vector<double> kept;
  for (double s : cycleStarts(run))
    if (kept.empty() || s - kept.back() >= min_cycle_s) kept.push_back(s);
  return kept;
}

/// Mean residual over [to - window_s, to) (NaN without a sample there).
double windowMean(const RunData& run, const std::vector<double>& model, double to, double window_s) {
  double sum = 0.0;
  int n = 0;
  for (std::size_t i = 0; i < run.size(); ++i)
    if (run.t_s[i] >= to - window_s && run.t_s[i] < to && std::isfinite(run.p_gauge_pa[i]) && std::isfinite(model[i])) {
      sum += run.p_gauge_pa[i] - model[i];
      ++n;
    }
  return n > 0 ? sum / n : NAN;
}

/// Each run's end-of-cycle residuals under `params` with `effects` (an empty list where a replay
/// fails or a run is not cyclic).
std::vector<std::vector<CyclePoint>> residualsOf(const std::vector<const RunData*>& runs, const CellParams& params,
                                                 const std::vector<CellEffectPtr>& effects, double period,
                                                 int threads) {
  std::vector<std::vector<CyclePoint>> out(runs.size());
  parallelFor(static_cast<int>(runs.size()), threads, [&](int i) {
    const Replay r = replayRun(*runs[i], params, effects);
    if (r.ok) out[i] = endOfCycleResiduals(*runs[i], r.p_gauge_pa, kWindowS, period);
  });
  return out;
}

/// The pressure sensor's noise over one end-of-cycle window (the scatter's floor).
double windowNoise(const PreparedRuns& prepared, const std::vector<std::size_t>& indices) {
  std::vector<double> noise;
  for (std::size_t i : indices) {
    const RunData& r = prepared.runs[i];
    const double dt = r.size() > 1 ? (r.t_s.back() - r.t_s.front()) / static_cast<double>(r.size() - 1) : kWindowS;
    noise.push_back(prepared.noises[i].p_pa / std::sqrt(std::max(1.0, kWindowS / dt)));
  }
  return noise.empty() ? 0.0 : median(noise);
}

/// The one effect parameter of a single candidate away from its off value; empty when none or
/// more than one (a one-parameter drift only: its trend is linear in that parameter's move).
std::string driftParameter(const ModelSpec& model, const std::map<std::string, double>& values) {
  std::string name;
  for (const FitAxis& a : model.axes) {
    if (a.calibration || !values.count(a.spec.name) || values.at(a.spec.name) == a.spec.off_value) continue;
    if (!name.empty()) return "";
    name = a.spec.name;
  }
  return name;
}

std::string driftInWords(const CycleDrift& d) { return fmt(d.slope_pa_s, 3) + " ± " + fmt(d.se_pa_s, 2) + " Pa/s"; }

/// What tryCandidate() found.
enum class DriftTry { kNotMoved, kRejected, kNamed };

/// The scored candidate `c` with its drift parameter rescaled to cancel the baseline's trend,
/// judged on the fit and withheld runs; fills `naming` when it is named.
DriftTry tryCandidate(const PreparedRuns& prepared, const CellParams& params, const ScoredCandidate& scored,
                      const DiagnosisOptions& options, const std::string& parameter, DriftNaming* naming) {
  const CandidateFit& c = scored.first;
  const ModelSpec& model = scored.second;
  const CellParams cell = applyCalibration(c.calibration, params);
  const auto fit_runs = prepared.select(prepared.fit), held_runs = prepared.select(prepared.withheld);
  const double floor_fit = windowNoise(prepared, prepared.fit), floor_held = windowNoise(prepared, prepared.withheld);
  const CycleDrift as_fitted = fitCycleDrift(
      residualsOf(fit_runs, cell, buildEffects(model, c.params), naming->period_s, options.threads), floor_fit);
  const double b0 = naming->fit_before.slope_pa_s, moved = b0 - as_fitted.slope_pa_s;
  const std::string name = joinNames(c.effects);
  if (!as_fitted.ok() || !(moved * b0 > 0.0)) {
    naming->reasons.push_back("whole breaths: " + name + " does not move the end-of-cycle drift towards zero");
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
  const auto effects = buildEffects(model, values);
  const CycleDrift after =
      fitCycleDrift(residualsOf(fit_runs, cell, effects, naming->period_s, options.threads), floor_fit);
  const CycleDrift held_after =
      fitCycleDrift(residualsOf(held_runs, cell, effects, naming->period_s, options.threads), floor_held);
  const bool plausible = plausibleValues(model, values, options.plausible_slack);
  const bool fit_ok = after.ok() && std::fabs(after.slope_pa_s) <= 2.0 * after.se_pa_s &&
                      std::fabs(after.slope_pa_s) <= kLeftOver * std::fabs(b0);
  const CycleDrift& hb = naming->held_before;
  const bool held_ok = hb.significant(kHeldZ) && held_after.ok() &&
                       std::fabs(held_after.slope_pa_s) <= (1.0 - options.floor_removed) * std::fabs(hb.slope_pa_s);
  naming->reasons.push_back("whole breaths: " + name + " with " + parameter + " " + fmt(values[parameter], 4) +
                            " (fitted " + fmt(c.params.at(parameter), 4) + ") leaves " + driftInWords(after) +
                            " on the fit runs, " + driftInWords(held_after) + " on the withheld runs" +
                            (!plausible          ? ": implausible"
                             : fit_ok && held_ok ? ": named"
                                                 : ": does not cancel the drift"));
  if (!plausible || !fit_ok || !held_ok) return DriftTry::kRejected;
  naming->params = values;
  naming->fit_after = after;
  naming->held_after = held_after;
  return DriftTry::kNamed;
}

}  // namespace

double medianCyclePeriod(const std::vector<const RunData*>& runs, double min_cycle_s) {
  std::vector<double> periods;
  for (const RunData* run : runs) {
    const std::vector<double> starts = distinctStarts(*run, min_cycle_s);
    for (std::size_t k = 1; k < starts.size(); ++k) periods.push_back(starts[k] - starts[k - 1]);
  }
  return periods.empty() ? NAN : median(periods);
}

std::vector<CyclePoint> endOfCycleResiduals(const RunData& run, const std::vector<double>& modelled_p_pa,
                                            double window_s, double period_s) {
  if (modelled_p_pa.size() != run.size())
    throw std::invalid_argument("end-of-cycle residuals: " + std::to_string(modelled_p_pa.size()) +
                                " modelled pressures for a run of " + std::to_string(run.size()) + " samples");
  if (!(window_s > 0.0)) throw std::invalid_argument("end-of-cycle residuals: window_s must be positive");
  std::vector<CyclePoint> out;
  if (run.size() == 0) return out;
  const std::vector<double> starts = distinctStarts(run, window_s);
  const double period = std::isfinite(period_s) ? period_s : medianCyclePeriod({&run}, window_s);
  std::vector<double> ends(starts.begin() + 1, starts.end());
  // The run's last sample closes its last cycle (a run cut at cycle boundaries): include it in
  // that cycle's window.
  const double last = run.t_s.back() - starts.back();
  if (std::isfinite(period) && std::fabs(last - period) <= kPeriodSlack * period)
    ends.push_back(std::nextafter(run.t_s.back(), INFINITY));
  const double t0 = run.t_s.front();
  for (double to : ends) {
    const double r = windowMean(run, modelled_p_pa, to, window_s);
    if (std::isfinite(r)) out.push_back({std::min(to, run.t_s.back()) - t0, r});
  }
  return out;
}

CycleDrift fitCycleDrift(const std::vector<std::vector<CyclePoint>>& runs, double floor_pa) {
  CycleDrift d;
  double st = 0.0, sr = 0.0;
  for (const auto& run : runs)
    for (const CyclePoint& p : run) {
      st += p.t_s;
      sr += p.residual_pa;
      ++d.points;
    }
  if (d.points < 3) return d;
  const double tm = st / d.points, rm = sr / d.points;
  double stt = 0.0, str = 0.0;
  for (const auto& run : runs)
    for (const CyclePoint& p : run) {
      stt += (p.t_s - tm) * (p.t_s - tm);
      str += (p.t_s - tm) * (p.residual_pa - rm);
    }
  if (!(stt > 0.0)) return d;
  d.slope_pa_s = str / stt;
  d.intercept_pa = rm - d.slope_pa_s * tm;
  double rss = 0.0;
  for (const auto& run : runs)
    for (const CyclePoint& p : run) rss += std::pow(p.residual_pa - d.intercept_pa - d.slope_pa_s * p.t_s, 2);
  const double scatter = std::max(std::sqrt(rss / (d.points - 2)), floor_pa);
  d.se_pa_s = scatter / std::sqrt(stt);
  return d;
}

DriftNaming nameDriftAboveFloor(const PreparedRuns& prepared, const CellParams& params,
                                const std::map<std::string, double>& baseline,
                                const std::vector<ScoredCandidate>& scored, const DiagnosisOptions& options) {
  DriftNaming naming;
  std::vector<const RunData*> all;
  for (const RunData& r : prepared.runs) all.push_back(&r);
  naming.period_s = medianCyclePeriod(all, kWindowS);
  if (!std::isfinite(naming.period_s)) return naming;  // not cyclic: nothing to say
  const CellParams cell = applyCalibration(baseline, params);
  naming.fit_before =
      fitCycleDrift(residualsOf(prepared.select(prepared.fit), cell, {}, naming.period_s, options.threads),
                    windowNoise(prepared, prepared.fit));
  if (!naming.fit_before.ok()) {  // a trend needs 3 points at 2 times or more on the fit runs
    naming.reasons.push_back("whole breaths: " + std::to_string(naming.fit_before.points) +
                             " end-of-cycle residual(s) on the fit runs; a trend needs at least 3, at two times or "
                             "more since a run's start: not measured");
    return naming;
  }
  naming.held_before =
      fitCycleDrift(residualsOf(prepared.select(prepared.withheld), cell, {}, naming.period_s, options.threads),
                    windowNoise(prepared, prepared.withheld));
  naming.reasons.push_back("whole breaths: the calibrated model's residual over the last " + fmt(kWindowS) +
                           " s of each cycle drifts by " + driftInWords(naming.fit_before) + " on the fit runs, " +
                           driftInWords(naming.held_before) + " on the withheld runs");
  if (!naming.fit_before.significant(kDriftZ)) return naming;
  int tried = 0;
  for (std::size_t i = 0; i < scored.size() && tried < kTried; ++i) {
    const CandidateFit& c = scored[i].first;
    if (!c.ok || c.effects.size() != 1 || !(c.bic_delta < 0.0)) continue;
    const std::string parameter = driftParameter(scored[i].second, c.params);
    if (parameter.empty()) continue;
    const DriftTry outcome = tryCandidate(prepared, params, scored[i], options, parameter, &naming);
    if (outcome == DriftTry::kNamed) {
      naming.winner = static_cast<int>(i);
      return naming;
    }
    if (outcome == DriftTry::kRejected) ++tried;
  }
  naming.reasons.push_back("whole breaths: no single candidate cancels the end-of-cycle drift");
  return naming;
}

}  // namespace gap
}  // namespace nursing_bed
