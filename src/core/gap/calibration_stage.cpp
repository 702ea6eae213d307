// The calibration stage of the diagnosis (diagnosis_stages.h, doc/gap_calibration.md): the
// model's own parameters fitted alone or jointly with a candidate's effects, and each move judged.
#include <algorithm>
#include <cmath>
#include <limits>
#include <set>

#include "nursing_bed/core/gap/calibration.h"
#include "nursing_bed/core/gap/diagnosis_stages.h"
#include "nursing_bed/core/gap/distortions.h"

namespace nursing_bed {
namespace gap {
namespace {

/// Pairs of calibrated parameters whose estimates are this correlated cannot be told apart.
constexpr double kUnidentifiableCorrelation = 0.95;

/// The calibrated parameters' axes (they come first in a ModelSpec).
int calibrationAxisCount(const ModelSpec& m) { return static_cast<int>(m.calibration.size()); }

/// Correlations of the calibrated parameters, and the groups (pairs) the runs cannot tell apart.
void correlations(const ModelSpec& m, const Eigen::MatrixXd& cov, CalibrationSummary* s) {
  const int k = calibrationAxisCount(m);
  s->correlation_names = m.calibration;
  s->correlation = Eigen::MatrixXd::Identity(k, k);
  for (int i = 0; i < k; ++i)
    for (int j = 0; j < k; ++j) {
      if (i == j) continue;
      const double c = cov(i, j) / std::sqrt(cov(i, i) * cov(j, j));
      s->correlation(i, j) = std::isfinite(c) ? c : 0.0;
      if (j > i && std::fabs(s->correlation(i, j)) > kUnidentifiableCorrelation)
        s->unidentifiable.push_back({m.calibration[i], m.calibration[j]});
    }
  for (int i = 0; i < k; ++i)
    if (!std::isfinite(cov(i, i)))
      s->notes.push_back(m.calibration[i] + ": the runs do not tell it at all (no standard error)");
}

/// Starting point of a joint fit: calibrated parameters at `cal`, effects at the candidate's fit.
std::vector<double> jointStart(const ModelSpec& joint, const std::map<std::string, double>& cal,
                               const ModelFit& candidate) {
  std::map<std::string, double> values = valuesOf(candidate.model, candidate.outcome.u);
  for (const auto& a : joint.axes)
    if (a.calibration) values[a.spec.name] = cal.count(a.spec.name) ? cal.at(a.spec.name) : a.spec.off_value;
  return coordinatesOf(joint, values);
}

/// Levenberg-Marquardt iterations of a profile refit (a moved parameter held at nominal).
constexpr int kProfileIterations = 8;

/// `f`'s effects with the calibrated parameters `names` free (the others nominal), refitted from
/// `values`.
ModelFit refitWith(const NoiseModel& noise, const ModelFit& f, const std::vector<std::string>& names,
                   const std::map<std::string, double>& values, int max_iterations) {
  ModelFit r;
  r.model = makeModelSpec(f.model.effects, calibrationAxes(names, noise.fit.params));
  if (r.model.axes.empty()) {
    r.outcome.ok = true;
    r.outcome.chi2 = noise.chi2_nominal;
    return r;
  }
  r.outcome = fitModel(noise.fit, r.model, {jointStart(r.model, values, f)}, max_iterations);
  if (!r.outcome.ok) r.outcome.chi2 = INFINITY;
  return r;
}

/// The moved parameters' names, in axis order.
std::vector<std::string> movedNames(const ModelFit& f, const CalibrationSummary& s) {
  const auto moved = s.movedValues();
  std::vector<std::string> names;
  for (const auto& a : f.model.axes)
    if (a.calibration && moved.count(a.spec.name)) names.push_back(a.spec.name);
  return names;
}

/// The BIC gain of each moved parameter, by a profile refit with it held at nominal: a move
/// whose chi2 gain (scaled by chi2/n where above 1) does not exceed ln n by significant_bic_drop
/// is not kept. (The Wald z of judgeCalibration() rests on forward-difference derivatives, which
/// the replay's step control can make too steep for a weakly told parameter.)
void profileMoves(const NoiseModel& noise, const DiagnosisOptions& options, CalibrationFit* c) {
  const ModelFit& f = c->fit;
  const int n = noise.fitResidualCount();
  const double scale = std::max(1.0, f.outcome.chi2 / n), log_n = std::log(static_cast<double>(n));
  const auto values = valuesOf(f.model, f.outcome.u);
  const std::vector<std::string> moved = movedNames(f, c->summary);
  for (const auto& name : moved) {
    std::vector<std::string> others;
    for (const auto& m : moved)
      if (m != name) others.push_back(m);
    const double gain = (refitWith(noise, f, others, values, kProfileIterations).outcome.chi2 - f.outcome.chi2) / scale;
    if (gain - log_n > options.significant_bic_drop) continue;
    for (auto& p : c->summary.parameters)
      if (p.name == name) {
        p.moved = false;
        p.value = p.nominal;
      }
    c->summary.notes.push_back(name + ": fitted " + fmt(values.at(name), 4) +
                               ", but holding it at nominal costs chi2 " + fmt(gain, 3) + " only (ln n + " +
                               fmt(options.significant_bic_drop) + " needed): kept");
  }
}

/// Nothing moved: every parameter at nominal; a calibration alone is then the nominal model, and
/// a joint fit with effects that moved nothing this way is never taken (chi2 infinite).
void moveNothing(const NoiseModel& noise, CalibrationFit* c) {
  for (auto& p : c->summary.parameters) {
    p.moved = false;
    p.value = p.nominal;
  }
  c->moved_model = makeModelSpec(c->fit.model.effects);
  c->moved_u.clear();
  c->moved_chi2 = c->fit.model.effects.empty() ? noise.chi2_nominal : INFINITY;
}

/// The model with only the moved calibrated parameters free (and the effects), refitted from
/// `fit` when some did not move; fills moved_model, moved_u, moved_chi2.
void settleMoved(const NoiseModel& noise, const DiagnosisOptions& options, CalibrationFit* c) {
  if (!c->fit.outcome.ok) {  // judgeCalibration() moved nothing
    moveNothing(noise, c);
    return;
  }
  profileMoves(noise, options, c);
  const ModelFit& f = c->fit;
  const std::vector<std::string> names = movedNames(f, c->summary);
  if (names.size() == f.model.calibration.size()) {
    c->moved_model = f.model;
    c->moved_u = f.outcome.u;
    c->moved_chi2 = f.outcome.chi2;
    return;
  }
  const ModelFit refit = refitWith(noise, f, names, valuesOf(f.model, f.outcome.u), options.max_iterations);
  if (!refit.outcome.ok) {  // the moves alone do not replay: a cell that cannot run is no calibration
    c->summary.notes.push_back("the moved parameters alone do not replay (" + refit.outcome.message +
                               "): nominal kept");
    moveNothing(noise, c);
    return;
  }
  c->moved_model = refit.model;
  c->moved_u = refit.outcome.u;
  c->moved_chi2 = refit.outcome.chi2;
  // The moved parameters at their refitted values.
  const auto values = valuesOf(c->moved_model, c->moved_u);
  for (auto& p : c->summary.parameters)
    if (p.moved) p.value = values.at(p.name);
}

}  // namespace

CalibrationSummary judgeCalibration(const NoiseModel& noise, const ModelFit& f, const DiagnosisOptions& options) {
  CalibrationSummary s;
  s.done = true;
  const int n = noise.fitResidualCount(), k = calibrationAxisCount(f.model);
  const auto values = f.outcome.ok ? valuesOf(f.model, f.outcome.u) : std::map<std::string, double>{};
  Eigen::MatrixXd cov = Eigen::MatrixXd::Constant(f.model.axes.size(), f.model.axes.size(), INFINITY);
  if (!f.outcome.ok || !fitCovariance(noise.fit, f.model, f.outcome.u, &cov))
    s.notes.push_back("the calibration's covariance could not be computed: no parameter is reported as moved");
  const double scale = f.outcome.ok ? std::max(1.0, f.outcome.chi2 / n) : 1.0;
  for (int j = 0; j < k; ++j) {
    const FitAxis& a = f.model.axes[j];
    CalibratedParam p;
    p.name = a.spec.name;
    p.unit = a.spec.unit;
    p.nominal = a.spec.off_value;
    p.fitted = values.count(p.name) ? values.at(p.name) : p.nominal;
    const double dx_du = a.spec.log_scale ? p.fitted * std::log(a.spec.hi / a.spec.lo) : a.spec.hi - a.spec.lo;
    p.std_error = std::sqrt(cov(j, j) * scale) * std::fabs(dx_du);
    const double z = (p.fitted - p.nominal) / p.std_error;
    // Its chi2 gain, (move / SE)^2, must pay for it in BIC as an effect must: by more than
    // significant_bic_drop beyond ln n.
    p.moved = std::isfinite(z) && std::fabs(z) > options.calibration_z &&
              z * z - std::log(static_cast<double>(n)) > options.significant_bic_drop;
    p.value = p.moved ? p.fitted : p.nominal;
    s.parameters.push_back(p);
  }
  correlations(f.model, cov, &s);
  if (std::count(f.model.calibration.begin(), f.model.calibration.end(), "film_stiffness_scale"))
    for (const auto& g : structurallyUnidentifiable()) s.unidentifiable.push_back(g);
  return s;
}

CalibrationFit calibrateModel(const NoiseModel& noise, const std::vector<std::string>& names,
                              const DiagnosisOptions& options,
                              const std::function<void(const std::string&)>& progress) {
  CalibrationFit c;
  c.fit.model = makeModelSpec({}, calibrationAxes(names, noise.fit.params));
  std::vector<double> start;
  for (const auto& a : c.fit.model.axes) start.push_back(a.toU(a.spec.off_value));
  c.fit.outcome = fitModel(noise.fit, c.fit.model, {start}, options.max_iterations);
  if (!c.fit.outcome.ok) {  // the nominal cell stands (refitJointly() starts from these values)
    c.fit.outcome.u = start;
    c.fit.outcome.chi2 = noise.chi2_nominal;
  }
  c.summary = judgeCalibration(noise, c.fit, options);
  if (!c.fit.outcome.ok) c.summary.notes.push_back("the calibration's fit failed (" + c.fit.outcome.message + ")");
  settleMoved(noise, options, &c);
  const int n = noise.fitResidualCount();
  const int k = static_cast<int>(c.summary.movedValues().size());
  c.summary.chi2 = c.moved_chi2;
  c.summary.bic_delta = c.moved_chi2 - noise.chi2_nominal + k * std::log(static_cast<double>(n));
  const bool pays = c.summary.bic_delta < -options.significant_bic_drop &&
                    (noise.chi2_nominal - c.moved_chi2) / n >= options.min_chi2_drop;
  if (k > 0 && !pays) {
    c.summary.notes.push_back("the calibrated moves lower chi2/n by " + fmt((noise.chi2_nominal - c.moved_chi2) / n) +
                              " only (BIC " + fmt(c.summary.bic_delta, 4) + "): too little to count; nominal kept");
    moveNothing(noise, &c);
    c.summary.chi2 = c.moved_chi2;
    c.summary.bic_delta = 0.0;
  }
  std::string moved;
  for (const auto& p : c.summary.parameters)
    if (p.moved) moved += (moved.empty() ? "" : ", ") + p.name + " " + fmt(p.nominal, 4) + " -> " + fmt(p.value, 4);
  if (progress)
    progress("calibrated " + joinNames(names, ",") + ": chi2/n " + fmt(c.fit.outcome.chi2 / n) + " (nominal " +
             fmt(noise.chi2_nominal / n) + "), moved: " + (moved.empty() ? "none" : moved) + ", " +
             std::to_string(c.fit.outcome.evaluations) + " replays");
  return c;
}

CalibrationFit refitJointly(const NoiseModel& noise, const ModelFit& candidate, const CalibrationFit& base,
                            const DiagnosisOptions& options, const ModelFit* uncalibrated, double overtake_chi2) {
  CalibrationFit c;
  c.fit.model = makeModelSpec(candidate.model.effects, calibrationAxes(base.fit.model.calibration, noise.fit.params));
  const std::map<std::string, double> all = valuesOf(base.fit.model, base.fit.outcome.u);
  std::vector<std::vector<double>> starts{jointStart(c.fit.model, base.summary.movedValues(), candidate),
                                          jointStart(c.fit.model, all, candidate)};
  // The same effects fitted on the nominal cell: a calibration that imitated part of them starts
  // back at nominal.
  if (uncalibrated && uncalibrated->outcome.ok) starts.push_back(jointStart(c.fit.model, {}, *uncalibrated));
  c.fit.outcome = fitModel(noise.fit, c.fit.model, starts, options.max_iterations, overtake_chi2);
  if (c.fit.outcome.stopped) return c;
  c.summary = judgeCalibration(noise, c.fit, options);
  settleMoved(noise, options, &c);
  c.summary.chi2 = c.moved_chi2;
  return c;
}

double withheldChi2(const NoiseModel& noise, const std::map<std::string, double>& calibration,
                    const std::vector<CellEffectPtr>& effects) {
  const int n_held = noise.heldResidualCount();
  if (n_held == 0) return NAN;
  std::vector<double> r(noise.held.residualCount());
  if (!fitResiduals(noise.held, applyCalibration(calibration, noise.held.params), effects, r.data())) return NAN;
  return sumSquares(r) / n_held;
}

namespace {

/// `out`: the effects of `model` (a pair) at their singles' fits in `uncalibrated` (the nominal
/// cell's), with no calibration; false when a single is missing there.
bool nominalPairStart(const ModelSpec& model, const std::vector<ModelFit>& uncalibrated, ModelFit* out) {
  if (model.effects.size() < 2) return false;
  std::map<std::string, double> values;
  for (const auto& name : model.effects) {
    const auto single = std::find_if(uncalibrated.begin(), uncalibrated.end(), [&](const ModelFit& u) {
      return u.outcome.ok && u.model.effects == std::vector<std::string>{name};
    });
    if (single == uncalibrated.end()) return false;
    const auto v = valuesOf(single->model, single->outcome.u);
    values.insert(v.begin(), v.end());
  }
  out->model = makeModelSpec(model.effects);
  out->outcome.ok = true;
  out->outcome.u = coordinatesOf(out->model, values);
  return true;
}

}  // namespace

bool dropCalibrationForEffect(const NoiseModel& noise, const std::vector<ModelFit>& uncalibrated,
                              const DiagnosisOptions& options, CalibrationFit* c) {
  const std::map<std::string, double> moved = c->summary.movedValues();
  if (moved.empty() || noise.heldResidualCount() == 0) return false;
  const double log_n = std::log(static_cast<double>(noise.fitResidualCount()));
  const double cal_bic = c->moved_chi2 + moved.size() * log_n;
  const double cal_held = withheldChi2(noise, moved, {});
  for (const ModelFit& f : uncalibrated) {
    if (!f.outcome.ok || f.model.effects.size() != 1) continue;
    const std::map<std::string, double> values = valuesOf(f.model, f.outcome.u);
    if (!plausibleValues(f.model, values, options.plausible_slack)) continue;
    const double bic = f.outcome.chi2 + f.model.axes.size() * log_n;
    const double held = withheldChi2(noise, {}, buildEffects(f.model, values));
    const double held_gain = (cal_held - held) * noise.heldResidualCount();
    if (isDistortionEffect(f.model.effects[0]) && std::fabs(bic - cal_bic) < options.near_tie_bic &&
        std::fabs(held_gain) < options.min_withheld_gain) {
      // A channel distortion that fits fit and withheld runs as well as the moves: the runs
      // cannot tell a sensor's error from the cell's parameters, and the report says so.
      std::string moved_names;
      for (const auto& [name, value] : moved) moved_names += (moved_names.empty() ? "" : ", ") + name;
      c->summary.notes.push_back("cannot tell apart: " + moved_names + " vs " +
                                 describeDistortion(f.model.effects[0], values) + " (BIC " + fmt(bic - cal_bic) +
                                 ", withheld chi2 " + fmt(-held_gain) + " against the calibration)");
      c->summary.distortion_ties.emplace_back(f.model.effects[0], values);
      continue;
    }
    if (!(bic < cal_bic) || !(held_gain >= options.min_withheld_gain)) continue;
    c->summary.notes.push_back(joinNames(f.model.effects) +
                               " alone, on the nominal cell, fits the runs better than the "
                               "calibration (BIC " +
                               fmt(bic - cal_bic) +
                               " against it) and the withheld runs too "
                               "(chi2/n " +
                               fmt(held) + " against " + fmt(cal_held) +
                               "): the calibration imitated an effect, its moves are not kept");
    for (auto& p : c->summary.parameters) {
      p.moved = false;
      p.value = p.nominal;
    }
    c->moved_chi2 = noise.chi2_nominal;
    return true;
  }
  return false;
}

void rebaseNoiseModel(NoiseModel* noise, const std::map<std::string, double>& calibration, double chi2) {
  noise->baseline_calibration = calibration;
  noise->baseline_chi2 = chi2;
  const int n_held = noise->heldResidualCount();
  if (n_held == 0) return;
  std::vector<double> r(noise->held.residualCount());
  fitResiduals(noise->held, applyCalibration(calibration, noise->held.params), {}, r.data());
  noise->baseline_withheld_chi2_per_sample = sumSquares(r) / n_held;
}

std::vector<std::string> calibrationList(const PreparedRuns& prepared, const DiagnosisOptions& options,
                                         const CellParams& nominal) {
  if (!options.calibrate) return {};
  const std::vector<std::string> names = options.calibration_params.empty()
                                             ? defaultCalibrationParams(prepared.runs, nominal)
                                             : options.calibration_params;
  checkCalibrationParams(names, prepared.runs, nominal);
  calibrationAxes(names, nominal);  // unknown or repeated names
  return names;
}

std::vector<int> jointRefitOrder(const std::vector<ModelFit>& fits, std::size_t effects, int pool,
                                 const std::set<std::string>& also, double log_n,
                                 const std::vector<const ModelFit*>& on_nominal) {
  std::vector<int> order;
  for (std::size_t i = 0; i < fits.size(); ++i)
    if (fits[i].outcome.ok && fits[i].model.effects.size() == effects) order.push_back(static_cast<int>(i));
  auto chi2 = [&](int i) {
    const bool nominal = static_cast<std::size_t>(i) < on_nominal.size() && on_nominal[i];
    return std::min(fits[i].outcome.chi2, nominal ? on_nominal[i]->outcome.chi2 : INFINITY);
  };
  auto bic = [&](int i) { return chi2(i) + fits[i].model.axes.size() * log_n; };
  std::sort(order.begin(), order.end(), [&](int a, int b) { return bic(a) < bic(b); });
  auto contains_also = [&](int i) {
    const auto& e = fits[i].model.effects;
    return std::any_of(e.begin(), e.end(), [&](const std::string& name) { return also.count(name) > 0; });
  };
  std::vector<int> chosen;
  for (std::size_t k = 0; k < order.size(); ++k)
    if (static_cast<int>(k) < pool || contains_also(order[k])) chosen.push_back(order[k]);
  return chosen;
}

JointRefits refitBestJointly(const NoiseModel& noise, const CalibrationFit& base, std::vector<ModelFit>* fits,
                             std::size_t effects, int pool, const DiagnosisOptions& options,
                             const std::function<void(const std::string&)>& progress, const std::set<std::string>& also,
                             const std::vector<ModelFit>& uncalibrated) {
  const int n = noise.fitResidualCount();
  const double log_n = std::log(static_cast<double>(n));
  // Each fit's counterpart on the nominal cell, if it was fitted there.
  std::vector<const ModelFit*> nominal_fit(fits->size(), nullptr);
  for (std::size_t i = 0; i < fits->size(); ++i)
    for (const ModelFit& u : uncalibrated)
      if (u.outcome.ok && u.model.effects == (*fits)[i].model.effects) nominal_fit[i] = &u;
  std::vector<int> order = jointRefitOrder(*fits, effects, pool, also, log_n, nominal_fit);
  // A pair starts also from its singles' fits on the nominal cell (a calibration that imitated
  // one of its effects would else hold it from the start).
  std::vector<ModelFit> nominal_pair(fits->size());
  std::vector<const ModelFit*> start_from = nominal_fit;
  for (int i : order)
    if (!start_from[i] && nominalPairStart((*fits)[i].model, uncalibrated, &nominal_pair[i]))
      start_from[i] = &nominal_pair[i];
  // A fit already within the noise leaves the calibration nothing to settle -- except the best,
  // when the calibration moved: the effect may make a move needless (a plate friction and a
  // smaller vent both slow the vent phase).
  // And when the best already fits within the noise, the worse ones are not refitted either:
  // with the calibration free they could at most tie with it, at more parameters.
  const bool recheck_moves = base.summary.anyMoved();
  const auto within = [&](int i) { return (*fits)[i].outcome.chi2 / n <= options.joint_refit_chi2; };
  std::vector<int> kept;
  if (!order.empty() && within(order[0])) {
    if (recheck_moves) kept.push_back(order[0]);
  } else {
    for (int i : order)
      if (!within(i)) kept.push_back(i);
  }
  order = kept;
  // The best first: when it lands within the noise the others (worse on the biased calibration)
  // are not refitted.
  std::vector<CalibrationFit> joint(order.size());
  if (!order.empty()) joint[0] = refitJointly(noise, (*fits)[order[0]], base, options, start_from[order[0]]);
  if (!order.empty() && joint[0].moved_chi2 / n <= options.joint_refit_chi2) order.resize(1);
  // The others change the verdict only by overtaking the best, as refitted (or not, when its
  // refit did not pay; BIC's price of a parameter or two is the margin).
  const double best_chi2 = order.empty() ? INFINITY
                                         : std::min((*fits)[order[0]].outcome.chi2, joint[0].moved_chi2) +
                                               options.significant_bic_drop + 2.0 * log_n;
  parallelFor(static_cast<int>(order.size()) - 1, options.threads, [&](int k) {
    joint[k + 1] = refitJointly(noise, (*fits)[order[k + 1]], base, options, start_from[order[k + 1]], best_chi2);
  });
  JointRefits out;
  for (std::size_t k = 0; k < order.size(); ++k) {
    ModelFit& f = (*fits)[order[k]];
    const CalibrationFit& j = joint[k];
    if (j.fit.outcome.stopped) {
      if (progress)
        progress("refit of " + joinNames(f.model.effects) + " with the calibration free stopped at chi2/n " +
                 fmt(j.fit.outcome.chi2 / n) + ": at its pace it could not reach the best's " + fmt(best_chi2 / n));
      continue;
    }
    if (progress)
      progress("refitted " + joinNames(f.model.effects) + " with the calibration free: chi2/n " +
               fmt(f.outcome.chi2 / n) + " -> " + fmt(j.moved_chi2 / n) +
               (options.verbose
                    ? " [" + std::to_string(j.fit.outcome.evaluations) + " replays, " + j.fit.outcome.message + "]"
                    : std::string()));
    // Whole models compared: a joint fit that drops a needless move pays ln n less for it.
    const double k_base = base.summary.movedValues().size(), k_joint = j.summary.movedValues().size();
    if (!(j.moved_chi2 + k_joint * log_n < f.outcome.chi2 + k_base * log_n)) continue;
    // Scaled by chi2/n as the calibration's own moves are (profileMoves).
    const double gain = (f.outcome.chi2 - j.moved_chi2) / std::max(1.0, j.moved_chi2 / n);
    if (gain - log_n > options.significant_bic_drop)
      out.moved_calibration.insert(f.model.effects.begin(), f.model.effects.end());
    f.model = j.moved_model;
    f.outcome.u = j.moved_u;
    f.outcome.chi2 = j.moved_chi2;
    f.outcome.evaluations += j.fit.outcome.evaluations;
    out.summaries[joinNames(f.model.effects)] = j.summary;
  }
  return out;
}

void settleCalibratedStatus(const NoiseModel& noise, const DiagnosisOptions& options, DiagnosisReport* rep,
                            bool above_floor) {
  CalibrationSummary& cal = rep->calibration;
  if (!cal.done) return;
  for (const auto& p : cal.parameters)
    rep->reasons.push_back("calibration: " + p.name + " fitted " + fmt(p.fitted, 4) + " +- " + fmt(p.std_error, 2) +
                           " (nominal " + fmt(p.nominal, 4) +
                           "): " + (p.moved ? "moved" : "not significant, nominal kept"));
  if (!cal.anyMoved() || rep->status != "none") return;
  const int n_held = noise.heldResidualCount();
  const double before = noise.withheld_chi2_per_sample, after = noise.baseline_withheld_chi2_per_sample;
  const bool within = after <= options.withheld_chi2 ||
                      after - 1.0 <= (1.0 - options.withheld_gap_removed) * (before - 1.0) ||
                      (above_floor && after <= (1.0 - options.floor_removed) * before);
  if (n_held == 0 || (within && (before - after) * n_held >= options.min_withheld_gain)) {
    rep->status = "calibrated";
    rep->reasons.push_back(
        std::string(above_floor ? "the calibrated model removes the gap down to its model-form floor"
                                : "the calibrated model fits within the noise") +
        (n_held ? " and holds up on the withheld runs (chi2/n " + fmt(before) + " -> " + fmt(after) + ")"
                : std::string()) +
        ": calibration alone removes the gap, no effect is needed");
    return;
  }
  rep->reasons.push_back("the calibrated model does not hold up on the withheld runs (chi2/n " + fmt(before) + " -> " +
                         fmt(after) + "): its moves are not kept");
  for (auto& p : cal.parameters) {
    p.moved = false;
    p.value = p.nominal;
  }
  rep->status = rep->nominal_chi2_per_sample <= options.within_noise_chi2 ? "none" : "unexplained";
}

void settleNoneOnWithheld(const NoiseModel& noise, const DiagnosisOptions& options, DiagnosisReport* rep,
                          bool above_floor) {
  const double held = noise.withheld_chi2_per_sample;  // the nominal model's: "none" keeps it
  if (rep->status != "none" || above_floor || noise.heldResidualCount() == 0 || !(held > options.withheld_chi2)) return;
  rep->status = "unexplained";
  rep->reasons.push_back("the fit runs are within the noise but the withheld runs are not (chi2/n " + fmt(held) +
                         ", above " + fmt(options.withheld_chi2) +
                         "): the fit runs do not exercise what the withheld runs show; fit runs like the "
                         "withheld ones (their loads, flows and heights) would let it be named");
}

void calibratedOutcome(const PreparedRuns& prepared, const NoiseModel& noise, const CellParams& params,
                       DiagnosisReport* rep) {
  const auto moved = rep->calibration.movedValues();
  const CellParams cell = applyCalibration(moved, params);
  rep->calibration.fit_nrmse = setResidual(prepared.select(prepared.fit), cell, {}).total;
  rep->calibration.withheld_nrmse = setResidual(prepared.select(prepared.withheld), cell, {}).total;
  rep->withheld_calibrated = rep->calibration.withheld_nrmse;
  const int n_held = noise.heldResidualCount();
  if (n_held > 0) {
    std::vector<double> r(noise.held.residualCount());
    fitResiduals(noise.held, applyCalibration(moved, noise.held.params), {}, r.data());
    rep->calibration.withheld_chi2_per_sample = sumSquares(r) / n_held;
  }
  rep->calibrated_yaml = calibratedParamsYaml(cell, rep->calibration, rep->dataset);
}

}  // namespace gap
}  // namespace nursing_bed
