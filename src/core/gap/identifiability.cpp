#include "nursing_bed/core/gap/identifiability.h"

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <random>
#include <sstream>
#include <utility>

#include <Eigen/Dense>

#include "nursing_bed/core/gap/calibration.h"
#include "nursing_bed/core/gap/fit_model.h"
#include "nursing_bed/core/gap/noise_model.h"
#include "nursing_bed/core/gap/replay.h"

namespace nursing_bed {
namespace gap {
namespace {

/// One explanation of the gap: a cell (calibrated where it moved) with effects.
struct Explanation {
  std::string name;  ///< "pressure_gain", "leak+heat_transfer", or a calibrated parameter's name
  CellParams params;
  std::vector<CellEffectPtr> effects;
  /// The same with each of its parameters moved a small step: the directions a refit may take.
  std::vector<std::pair<CellParams, std::vector<CellEffectPtr>>> moved;
  /// Columns: the whitened fit residuals' change along each of `moved` (what a refit costs there).
  Eigen::MatrixXd fit_sensitivity;
  double chi2 = 0.0;           ///< fit runs, whitened, summed
  double bic_delta = 0.0;      ///< against the baseline model, as CandidateFit::bic_delta
  double held_chi2 = NAN;      ///< withheld runs, whitened, summed (NaN: none)
  std::vector<double> change;  ///< its whitened fit residuals less the baseline's
};

/// What a proposed run is recorded with: the dataset's kind of run and its noise floor.
struct ProposalSetting {
  bool valve_driven = false;  ///< driven through the valves (no flow meter)
  bool has_height = true;
  double noise_p_pa = 30.0;      ///< the dataset's pressure noise (the height's scales with it)
  double supply_gauge_pa = NAN;  ///< what the dataset's supply gauge reads (valve-driven runs)
  double fit_sample_hz = 10.0;
  int threads = 1;
  double min_separation_chi2 = 20.0;  ///< a run is proposed where it leaves at least this
};

constexpr std::size_t kMaxConfusions = 3;
// The winner's best physical partners fitted beside it where the diagnosis fitted no pair.
constexpr int kExtensions = 6;
// A rival holding the winner and more counts where it moves the fit runs' readings by this
// (chi2 in noise floors, as much as the withheld runs must gain to decide): else what it adds is
// as good as off.
constexpr double kInPlayChi2 = 10.0;
// A calibration parameter's sensitivity: its move over this share of its prior range.
constexpr double kSensitivityStep = 0.02;

/// Whitened fit residuals of `cell` with `effects` (residualCount() values); empty when a replay
/// failed.
std::vector<double> residuals(const FitData& fit, const CellParams& cell, const std::vector<CellEffectPtr>& effects) {
  std::vector<double> r(fit.residualCount());
  if (!fitResiduals(fit, cell, effects, r.data())) return {};
  return r;
}

double heldChi2(const NoiseModel& noise, const CellParams& held_cell, const std::vector<CellEffectPtr>& effects) {
  if (noise.heldResidualCount() == 0) return NAN;
  std::vector<double> r(noise.held.residualCount());
  fitResiduals(noise.held, held_cell, effects, r.data());
  return sumSquares(r);
}

/// `e` scored on the fit runs: chi2, BIC against the baseline with `extra` parameters, and its
/// change of the fit residuals from `base`. False when a replay failed.
bool scoreFit(const NoiseModel& noise, const std::vector<double>& base, int extra, Explanation* e) {
  const std::vector<double> r = residuals(noise.fit, e->params, e->effects);
  if (r.empty()) return false;
  e->chi2 = sumSquares(r);
  e->bic_delta = (e->chi2 - noise.baseline_chi2) + extra * std::log(static_cast<double>(noise.fitResidualCount()));
  e->change.resize(r.size());
  for (std::size_t i = 0; i < r.size(); ++i) e->change[i] = r[i] - base[i];
  return true;
}

/// scoreFit(), and the withheld runs' chi2 on `held_cell`.
bool score(const NoiseModel& noise, const std::vector<double>& base, int extra, Explanation* e,
           const CellParams& held_cell) {
  if (!scoreFit(noise, base, extra, e)) return false;
  e->held_chi2 = heldChi2(noise, held_cell, e->effects);
  return true;
}

double correlation(const std::vector<double>& a, const std::vector<double>& b) {
  double ab = 0.0, aa = 0.0, bb = 0.0;
  for (std::size_t i = 0; i < a.size() && i < b.size(); ++i) {
    ab += a[i] * b[i];
    aa += a[i] * a[i];
    bb += b[i] * b[i];
  }
  return aa > 0.0 && bb > 0.0 ? ab / std::sqrt(aa * bb) : 0.0;
}

double distance2(const std::vector<double>& a, const std::vector<double>& b) {
  double d = 0.0;
  for (std::size_t i = 0; i < a.size() && i < b.size(); ++i) d += (a[i] - b[i]) * (a[i] - b[i]);
  return d;
}

/// Whether `rival` is one the runs do not tell from `winner`: within near_tie_bic on the fit
/// runs, and the withheld runs (where there are any) within min_withheld_gain of each other.
bool undecided(const Explanation& winner, const Explanation& rival, const DiagnosisOptions& options) {
  if (!(std::fabs(rival.bic_delta - winner.bic_delta) < options.near_tie_bic)) return false;
  if (std::isnan(winner.held_chi2) || std::isnan(rival.held_chi2)) return true;
  return std::fabs(rival.held_chi2 - winner.held_chi2) < options.min_withheld_gain;
}

/// Calibration parameter `axis` fitted alone on the cell with the calibration `calibration`,
/// scored against `base` (that cell's fit residuals); false when no replay succeeds.
bool oneParameterExplanation(const NoiseModel& noise, const std::map<std::string, double>& calibration,
                             const FitAxis& axis, const std::vector<double>& base, Explanation* e) {
  constexpr int kIterations = 4;  // from the calibrated value: a few steps reach a single minimum
  const std::string& name = axis.spec.name;
  const CellParams cell = applyCalibration(calibration, noise.fit.params);
  const double step = kSensitivityStep * (axis.spec.hi - axis.spec.lo);
  ModelSpec alone = makeModelSpec({}, {axis});
  alone.fixed_calibration = calibration;
  const FitOutcome f = fitModel(noise.fit, alone, {{axis.toU(calibrationParam(name).get(cell))}}, kIterations);
  if (!f.ok) return false;
  const double value = axis.toValue(f.u[0]);
  e->name = name;
  e->params = applyCalibration({{name, value}}, cell);
  e->moved.emplace_back(applyCalibration({{name, value + step}}, cell), std::vector<CellEffectPtr>{});
  std::map<std::string, double> held = calibration;
  held[name] = value;
  return score(noise, base, 1, e, applyCalibration(held, noise.held.params));
}

/// Whether `more` (the winner and another effect) is a rival: what it adds moves the readings,
/// it fits the fit runs within near_tie_bic of the winner or better, and the withheld runs do
/// not confirm the winner. The verdict names the simpler answer while it holds up alone, so a
/// better fit of the winner and more is left to a run that tells.
bool moreInPlay(const Explanation& winner, const Explanation& more, const DiagnosisOptions& options) {
  if (more.change.empty() || distance2(winner.change, more.change) < kInPlayChi2) return false;
  if (!(more.bic_delta < winner.bic_delta + options.near_tie_bic)) return false;
  return std::isnan(winner.held_chi2) || std::isnan(more.held_chi2) ||
         more.held_chi2 < winner.held_chi2 + options.min_withheld_gain;
}

/// Each calibration parameter not moved already, fitted alone on the baseline cell.
std::vector<Explanation> calibrationRivals(const NoiseModel& noise, const CellParams& params,
                                           const std::vector<std::string>& calibrated,
                                           const std::vector<double>& base) {
  std::vector<Explanation> out;
  for (const FitAxis& axis : calibrationAxes(calibrated, params)) {
    if (noise.baseline_calibration.count(axis.spec.name)) continue;  // moved already: the baseline's
    Explanation e;
    if (oneParameterExplanation(noise, noise.baseline_calibration, axis, base, &e)) out.push_back(std::move(e));
  }
  return out;
}

/// Columns of `e.fit_sensitivity`: the fit residuals' change along each of e.moved.
void fitSensitivity(const NoiseModel& noise, Explanation* e) {
  const std::vector<double> at = residuals(noise.fit, e->params, e->effects);
  e->fit_sensitivity.setZero(static_cast<Eigen::Index>(at.size()), static_cast<Eigen::Index>(e->moved.size()));
  if (at.empty()) return;
  for (std::size_t j = 0; j < e->moved.size(); ++j) {
    const std::vector<double> r = residuals(noise.fit, e->moved[j].first, e->moved[j].second);
    for (std::size_t i = 0; i < r.size(); ++i) e->fit_sensitivity(i, j) = r[i] - at[i];
  }
}

/// A candidate's effects with each effect parameter moved by a small step (a share of its
/// plausible range; on a log scale, a factor), the other way where that step is not admitted.
std::vector<std::pair<CellParams, std::vector<CellEffectPtr>>> movedEffects(const ScoredCandidate& c,
                                                                            const CellParams& cell) {
  std::vector<std::pair<CellParams, std::vector<CellEffectPtr>>> out;
  for (const FitAxis& axis : c.second.axes) {
    if (axis.calibration) continue;
    const EffectParamSpec& p = axis.spec;
    const double x = c.first.params.at(p.name);
    for (const double sign : {1.0, -1.0}) {
      std::map<std::string, double> values = c.first.params;
      values[p.name] = p.log_scale ? x * std::exp(sign * 0.05) : x + sign * kSensitivityStep * (p.hi - p.lo);
      try {
        out.emplace_back(cell, buildEffects(c.second, values));
        break;
      } catch (const std::invalid_argument&) {
        // outside what the effect admits: the step the other way
      }
    }
  }
  return out;
}

Explanation fromCandidate(const ScoredCandidate& c, const NoiseModel& noise, const std::vector<double>& base) {
  Explanation e;
  e.name = joinNames(c.first.effects);
  e.params = applyCalibration(c.first.calibration, noise.fit.params);
  e.effects = buildEffects(c.second, c.first.params);
  scoreFit(noise, base, 0, &e);
  // The diagnosis's own figures (its parameter count; its withheld replay).
  e.bic_delta = c.first.bic_delta;
  e.held_chi2 = c.first.withheld_chi2_per_sample * noise.heldResidualCount();
  e.moved = movedEffects(c, e.params);
  return e;
}

/// The median supply gauge reading of the runs driven through the valves (the parameter file's
/// supply without one): a proposed run reads what the dataset's gauge reads.
double recordedSupply(const PreparedRuns& prepared, const CellParams& params) {
  std::vector<double> readings;
  for (const RunData& r : prepared.runs)
    for (double p : r.p_supply_gauge_pa)
      if (std::isfinite(p)) readings.push_back(p);
  return readings.empty() ? params.supply_pressure_pa : median(readings);
}

/// The winner (a single) with each of the best `count` other physical singles beside it that the
/// diagnosis did not fit as a pair (it fits none where a single fits within the noise), fitted
/// together from their own fits.
std::vector<std::pair<Explanation, std::map<std::string, double>>> extensions(
    const std::vector<ScoredCandidate>& scored, int winner, const NoiseModel& noise, const DiagnosisOptions& options,
    const std::vector<double>& base, int count) {
  std::vector<std::pair<Explanation, std::map<std::string, double>>> out;
  const CandidateFit& w = scored[winner].first;
  if (w.effects.size() != 1) return out;
  auto single = [&](const CandidateFit& c) {
    ModelFit f;
    f.model = makeModelSpec(c.effects);
    f.model.fixed_calibration = w.calibration;
    f.outcome.u = coordinatesOf(f.model, c.params);
    f.outcome.ok = true;
    return f;
  };
  for (std::size_t i = 0; i < scored.size() && static_cast<int>(out.size()) < count; ++i) {
    const CandidateFit& c = scored[i].first;
    if (static_cast<int>(i) == winner || c.effects.size() != 1 || !c.ok || !c.plausible ||
        !isPhysicalCatalogEffect(c.effects[0]))
      continue;
    ScoredCandidate pair;
    pair.second = pairSpec(w.effects[0], c.effects[0], w.calibration);
    const std::vector<std::string>& names = pair.second.effects;
    if (std::any_of(scored.begin(), scored.end(), [&](const ScoredCandidate& s) { return s.first.effects == names; }))
      continue;  // fitted as a pair already
    const FitOutcome f =
        fitModel(noise.fit, pair.second, pairStarts(pair.second, single(w), single(c)), options.max_iterations);
    if (!f.ok) continue;
    const std::map<std::string, double> values = valuesOf(pair.second, f.u);
    if (!plausibleValues(pair.second, values, options.plausible_slack)) continue;
    pair.first.effects = names;
    pair.first.params = values;
    pair.first.calibration = w.calibration;
    Explanation e;
    e.name = joinNames(names);
    e.params = applyCalibration(w.calibration, noise.fit.params);
    e.effects = buildEffects(pair.second, values);
    const int k = static_cast<int>(pair.second.axes.size() - heldAxes(noise.fit, pair.second).size());
    if (!score(noise, base, k, &e, applyCalibration(w.calibration, noise.held.params))) continue;
    e.moved = movedEffects(pair, e.params);
    out.emplace_back(std::move(e), values);
  }
  return out;
}

bool containsAll(const std::vector<std::string>& outer, const std::vector<std::string>& inner) {
  return std::all_of(inner.begin(), inner.end(),
                     [&](const std::string& x) { return std::find(outer.begin(), outer.end(), x) != outer.end(); });
}

Confusion describe(const Explanation& a, const Explanation& b, const std::map<std::string, double>& b_params) {
  Confusion c;
  c.a = a.name;
  c.b = b.name;
  c.b_params = b_params;
  c.bic_a = a.bic_delta;
  c.bic_b = b.bic_delta;
  c.withheld_chi2_a = a.held_chi2;
  c.withheld_chi2_b = b.held_chi2;
  c.correlation = correlation(a.change, b.change);
  c.fit_separation_chi2 = distance2(a.change, b.change);
  return c;
}

/// A proposed run as the diagnosis would take it in: simulated on the nominal cell with sensor
/// noise at the dataset's floor (a fixed draw), then prepared for the fits like the dataset's
/// runs (its noise floor and the flow meter's random walk in its whitening).
struct ProposedRecording {
  PreparedRuns prepared;
  FitData fit;
};

void recordProposal(const SynthProtocol& protocol, const SynthRunPlan& plan, const CellParams& nominal,
                    const NoiseModel& noise, const ProposalSetting& setting, ProposedRecording* out) {
  std::mt19937 rng(0x5eed + static_cast<unsigned>(plan.load_n * 10.0));
  const SensorNoise sensors = SensorNoise{}.scaled(setting.noise_p_pa / SensorNoise{}.pressure_sd_pa);
  RunData run = simulateSynthRun(nominal, {}, protocol, plan, sensors, &rng, "proposed");
  if (protocol.valve_driven) {
    run.mdot_in_kg_s.assign(run.size(), NAN);
    run.p_supply_gauge_pa.assign(run.size(), setting.supply_gauge_pa);
  }
  if (!setting.has_height) run.h_m.assign(run.size(), NAN);
  run.role = "fit";
  out->prepared = prepareRuns({std::move(run)});
  out->fit.params = noise.fit.params;
  out->fit.runs.push_back(prepareFitRun(out->prepared.runs[0], out->prepared.measured_flow[0], out->prepared.noises[0],
                                        noise.fit.params, setting.fit_sample_hz));
}

/// x - y with a failed replay's slots as 0.
Eigen::VectorXd difference(const std::vector<double>& x, const std::vector<double>& y) {
  Eigen::VectorXd d = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(std::max(x.size(), y.size())));
  if (x.size() != y.size()) return d;
  for (std::size_t i = 0; i < x.size(); ++i)
    if (std::isfinite(x[i] - y[i])) d(static_cast<Eigen::Index>(i)) = x[i] - y[i];
  return d;
}

/// The chi2 `b` leaves on `a`'s readings of the run once refitted (Gauss-Newton along b.moved,
/// its move priced by b.fit_sensitivity on the fit runs); residuals whitened, `ra` and `rb`
/// with every reading, so their difference is the readings'.
double chi2AfterRefit(const std::vector<double>& ra, const std::vector<double>& rb,
                      const std::vector<std::vector<double>>& rb_moved, const Explanation& b) {
  const Eigen::VectorXd d = difference(ra, rb);
  const Eigen::Index k = static_cast<Eigen::Index>(rb_moved.size());
  if (k == 0) return d.squaredNorm();
  Eigen::MatrixXd s(d.size(), k);
  for (Eigen::Index j = 0; j < k; ++j) s.col(j) = difference(rb_moved[j], rb);
  Eigen::MatrixXd normal = s.transpose() * s;
  if (b.fit_sensitivity.cols() == k) normal += b.fit_sensitivity.transpose() * b.fit_sensitivity;
  const Eigen::VectorXd step = normal.ldlt().solve(s.transpose() * d);
  if (!step.allFinite()) return d.squaredNorm();
  return std::max(0.0, d.squaredNorm() - d.dot(s * step));
}

/// The grid's runs, each recorded once for every rival it is to judge.
struct GridRecordings {
  std::vector<SynthRunPlan> plans;
  std::vector<ProposedRecording> runs;  ///< in place: each FitData points into its own runs
  std::vector<char> ok;                 ///< false: the nominal cell does not replay it
};

void recordGrid(const CellParams& nominal, const NoiseModel& noise, const ProposalSetting& setting,
                const ExperimentGrid& grid, GridRecordings* out) {
  SynthProtocol protocol = synthProtocol("standard", nominal);
  protocol.valve_driven = setting.valve_driven;
  for (double load : grid.loads_n)
    for (const std::string& flow : grid.flows)
      for (double rise : grid.rise_scales) {
        try {
          out->plans.push_back(synthRunPlan(nominal, load, flow, rise));
        } catch (const std::exception&) {
          // a load the nominal cell cannot hold at that height: not proposed
        }
      }
  out->runs.resize(out->plans.size());
  out->ok.assign(out->plans.size(), 0);
  parallelFor(static_cast<int>(out->plans.size()), setting.threads, [&](int k) {
    try {
      recordProposal(protocol, out->plans[k], nominal, noise, setting, &out->runs[k]);
      out->ok[k] = 1;
    } catch (const std::invalid_argument&) {
      // the nominal cell does not replay it
    }
  });
}

/// The proposal for one confused pair: the run, and how far apart the two put its readings.
struct ProposedExperiment {
  SynthRunPlan run;
  double separation_chi2 = -1.0;
};

/// The run of `grid` that separates `a` and `b` best: each replayed on it, the other refitted
/// (Gauss-Newton along its `moved` directions, paying on the fit runs by its fit_sensitivity) to
/// the first's readings; the smaller of the two chi2 left.
ProposedExperiment proposeExperiment(const Explanation& a, const Explanation& b, const GridRecordings& grid,
                                     int threads) {
  std::vector<double> separation(grid.plans.size(), -1.0);
  parallelFor(static_cast<int>(grid.plans.size()), threads, [&](int k) {
    if (!grid.ok[k]) return;
    const FitData& fit = grid.runs[k].fit;
    const std::vector<double> ra = residuals(fit, a.params, a.effects), rb = residuals(fit, b.params, b.effects);
    if (ra.empty() || rb.empty()) return;
    std::vector<std::vector<double>> ra_moved, rb_moved;
    for (const auto& m : a.moved) ra_moved.push_back(residuals(fit, m.first, m.second));
    for (const auto& m : b.moved) rb_moved.push_back(residuals(fit, m.first, m.second));
    separation[k] = std::min(chi2AfterRefit(ra, rb, rb_moved, b), chi2AfterRefit(rb, ra, ra_moved, a));
  });
  ProposedExperiment best;
  for (std::size_t k = 0; k < grid.plans.size(); ++k)
    if (separation[k] > best.separation_chi2) best = {grid.plans[k], separation[k]};
  return best;
}

ProposalSetting proposalSetting(const PreparedRuns& prepared, const CellParams& params, double noise_p_pa,
                                const DiagnosisOptions& options) {
  ProposalSetting setting;
  setting.valve_driven =
      std::all_of(prepared.runs.begin(), prepared.runs.end(), [](const RunData& r) { return runIsValveDriven(r); });
  setting.has_height = !std::all_of(prepared.runs.begin(), prepared.runs.end(), runHasNoHeight);
  setting.noise_p_pa = noise_p_pa;
  setting.supply_gauge_pa = recordedSupply(prepared, params);
  setting.fit_sample_hz = options.fit_sample_hz;
  setting.threads = options.threads;
  setting.min_separation_chi2 = options.significant_bic_drop;
  return setting;
}

/// `a` against `b` in a Confusion, with the run of `grid` that separates them best.
Confusion proposed(const Explanation& a, const Explanation& b, const std::map<std::string, double>& b_params,
                   const ProposalSetting& setting, const GridRecordings& grid) {
  Confusion c = describe(a, b, b_params);
  const ProposedExperiment p = proposeExperiment(a, b, grid, setting.threads);
  c.proposed = p.separation_chi2 >= setting.min_separation_chi2;
  c.load_n = p.run.load_n;
  c.flow = p.run.flow;
  c.rise_scale = p.run.rise_scale;
  c.separation_chi2 = p.separation_chi2;
  return c;
}

}  // namespace

std::vector<Confusion> findConfusions(const std::vector<ScoredCandidate>& scored, int winner,
                                      const PreparedRuns& prepared, const NoiseModel& noise, const CellParams& params,
                                      const std::vector<std::string>& calibrated, const DiagnosisOptions& options,
                                      double noise_p_pa, const ExperimentGrid& grid) {
  std::vector<Confusion> out;
  if (winner < 0) return out;
  const std::vector<double> base =
      residuals(noise.fit, applyCalibration(noise.baseline_calibration, noise.fit.params), {});
  if (base.empty()) return out;
  Explanation w = fromCandidate(scored[winner], noise, base);
  if (w.change.empty()) return out;
  std::vector<std::pair<Explanation, std::map<std::string, double>>> rivals;
  for (std::size_t i = 0; i < scored.size(); ++i) {
    const CandidateFit& c = scored[i].first;
    if (static_cast<int>(i) == winner || !c.ok || !c.plausible) continue;
    // The winner and more: a rival only where what it adds moves the readings (moreInPlay()).
    const bool more = containsAll(c.effects, scored[winner].first.effects);
    if (!(c.bic_delta < w.bic_delta + options.near_tie_bic &&
          (more || c.bic_delta > w.bic_delta - options.near_tie_bic)))
      continue;
    Explanation e = fromCandidate(scored[i], noise, base);
    if (!e.change.empty() && (more ? moreInPlay(w, e, options) : undecided(w, e, options)))
      rivals.emplace_back(std::move(e), c.params);
  }
  for (auto& [e, values] : extensions(scored, winner, noise, options, base, kExtensions))
    if (moreInPlay(w, e, options)) rivals.emplace_back(std::move(e), std::move(values));
  for (Explanation& e : calibrationRivals(noise, params, calibrated, base)) {
    if (!undecided(w, e, options)) continue;
    std::map<std::string, double> value{{e.name, calibrationParam(e.name).get(e.params)}};
    rivals.emplace_back(std::move(e), std::move(value));
  }
  std::sort(rivals.begin(), rivals.end(),
            [](const auto& x, const auto& y) { return x.first.bic_delta < y.first.bic_delta; });
  if (rivals.size() > kMaxConfusions) rivals.resize(kMaxConfusions);
  const ProposalSetting setting = proposalSetting(prepared, params, noise_p_pa, options);
  if (rivals.empty()) return out;
  fitSensitivity(noise, &w);
  GridRecordings recordings;
  recordGrid(params, noise, setting, grid, &recordings);
  for (auto& [rival, rival_params] : rivals) {
    fitSensitivity(noise, &rival);
    out.push_back(proposed(w, rival, rival_params, setting, recordings));
  }
  return out;
}

std::vector<Confusion> findCalibrationConfusions(const PreparedRuns& prepared, const NoiseModel& noise,
                                                 const CellParams& params, const std::vector<std::string>& calibrated,
                                                 const CalibrationSummary& summary, const DiagnosisOptions& options,
                                                 double noise_p_pa, const ExperimentGrid& grid) {
  std::vector<Confusion> out;
  const std::vector<FitAxis> axes = calibrationAxes(calibrated, params);
  auto axis = [&](const std::string& name) -> const FitAxis* {
    const auto a = std::find_if(axes.begin(), axes.end(), [&](const FitAxis& x) { return x.spec.name == name; });
    return a == axes.end() ? nullptr : &*a;
  };
  const ProposalSetting setting = proposalSetting(prepared, params, noise_p_pa, options);
  GridRecordings recordings;  // recorded at the first pair that needs them
  for (const auto& group : summary.unidentifiable) {
    if (group.size() != 2 || !axis(group[0]) || !axis(group[1]) || out.size() >= kMaxConfusions) continue;
    // The cell with the calibration's other moves; each of the two alone on it.
    std::map<std::string, double> rest = noise.baseline_calibration;
    rest.erase(group[0]);
    rest.erase(group[1]);
    const std::vector<double> base = residuals(noise.fit, applyCalibration(rest, noise.fit.params), {});
    Explanation a, b;
    if (base.empty() || !oneParameterExplanation(noise, rest, *axis(group[0]), base, &a) ||
        !oneParameterExplanation(noise, rest, *axis(group[1]), base, &b))
      continue;
    if (b.bic_delta < a.bic_delta) std::swap(a, b);
    if (!undecided(a, b, options)) continue;
    fitSensitivity(noise, &a);
    fitSensitivity(noise, &b);
    if (recordings.plans.empty()) recordGrid(params, noise, setting, grid, &recordings);
    out.push_back(proposed(a, b, {{b.name, calibrationParam(b.name).get(b.params)}}, setting, recordings));
  }
  return out;
}

namespace {

/// The calibration's moved parameters as an explanation on the nominal cell (`base`: its fit
/// residuals), each parameter stepped for the refit's directions.
bool calibrationExplanation(const NoiseModel& noise, const CellParams& params,
                            const std::vector<std::string>& calibrated, const std::map<std::string, double>& moved,
                            const std::vector<double>& base, Explanation* e) {
  for (const auto& [name, value] : moved) e->name += (e->name.empty() ? "" : "+") + name;
  e->params = applyCalibration(moved, noise.fit.params);
  for (const FitAxis& axis : calibrationAxes(calibrated, params)) {
    if (!moved.count(axis.spec.name)) continue;
    std::map<std::string, double> step = moved;
    step[axis.spec.name] += kSensitivityStep * (axis.spec.hi - axis.spec.lo);
    e->moved.emplace_back(applyCalibration(step, noise.fit.params), std::vector<CellEffectPtr>{});
  }
  return score(noise, base, static_cast<int>(moved.size()), e, applyCalibration(moved, noise.held.params));
}

/// A channel distortion with its fitted `values` as an explanation on the nominal cell.
bool distortionExplanation(const NoiseModel& noise, const std::string& name,
                           const std::map<std::string, double>& values, const std::vector<double>& base,
                           Explanation* e) {
  ScoredCandidate c;
  c.first.effects = {name};
  c.first.params = values;
  c.second = makeModelSpec({name});
  e->name = name;
  e->params = noise.fit.params;
  e->effects = buildEffects(c.second, values);
  e->moved = movedEffects(c, e->params);
  return score(noise, base, static_cast<int>(c.second.axes.size()), e, noise.held.params);
}

}  // namespace

std::vector<Confusion> findCalibrationDistortionConfusions(const PreparedRuns& prepared, const NoiseModel& noise,
                                                           const CellParams& params,
                                                           const std::vector<std::string>& calibrated,
                                                           const CalibrationSummary& summary,
                                                           const DiagnosisOptions& options, double noise_p_pa,
                                                           const ExperimentGrid& grid) {
  std::vector<Confusion> out;
  const std::map<std::string, double> moved = summary.movedValues();
  if (summary.distortion_ties.empty() || moved.empty()) return out;
  const std::vector<double> base = residuals(noise.fit, noise.fit.params, {});
  if (base.empty()) return out;
  Explanation a;
  if (!calibrationExplanation(noise, params, calibrated, moved, base, &a)) return out;
  fitSensitivity(noise, &a);
  const ProposalSetting setting = proposalSetting(prepared, params, noise_p_pa, options);
  GridRecordings recordings;
  for (const auto& [name, values] : summary.distortion_ties) {
    Explanation b;
    if (out.size() >= kMaxConfusions || !distortionExplanation(noise, name, values, base, &b)) continue;
    fitSensitivity(noise, &b);
    if (recordings.plans.empty()) recordGrid(params, noise, setting, grid, &recordings);
    out.push_back(proposed(a, b, values, setting, recordings));
  }
  return out;
}

std::string addRunArgument(const Confusion& c) {
  std::ostringstream s;
  s << "load_n=" << c.load_n << ",flow=" << c.flow << ",rise_scale=" << c.rise_scale;
  return s.str();
}

std::string describeConfusion(const Confusion& c) {
  std::ostringstream s;
  const bool better = c.bic_b < c.bic_a;  // the winner and more: the verdict kept the simpler answer
  s << std::setprecision(4);
  if (better) s << c.b << " fits better than " << c.a << " (BIC " << c.bic_b << " against " << c.bic_a;
  else s << c.a << " and " << c.b << " fit alike (BIC " << c.bic_a << " and " << c.bic_b;
  s << " on the fit runs";
  if (std::isfinite(c.withheld_chi2_a))
    s << "; chi2 " << (better ? c.withheld_chi2_b : c.withheld_chi2_a) << (better ? " against " : " and ")
      << (better ? c.withheld_chi2_a : c.withheld_chi2_b) << " on the withheld runs";
  s << std::setprecision(3) << "; their changes to the readings correlate " << c.correlation << "): "
    << (better ? c.a + " holds up alone, and the verdict names the simpler answer while it does. "
               : std::string("these runs cannot tell them apart. "));
  if (!c.proposed) return s.str() + "No run of the proposal grid (loads, hold heights, rises) sets them apart.";
  s << "A run at " << c.load_n << " N, " << c.flow << " flow" << (c.rise_scale != 1.0 ? ", the rise " : "");
  if (c.rise_scale != 1.0) s << c.rise_scale << " times as long";
  s << std::setprecision(2) << " would set them chi2 " << c.separation_chi2 << " apart (" << c.fit_separation_chi2
    << " on these fit runs): gap synth --add-run " << addRunArgument(c);
  return s.str();
}

}  // namespace gap
}  // namespace nursing_bed
