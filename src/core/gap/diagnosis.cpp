#include "nursing_bed/core/gap/diagnosis.h"

#include "nursing_bed/core/gap/identifiability.h"
#include "nursing_bed/core/gap/validation.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <iomanip>
#include <limits>
#include <mutex>
#include <numeric>
#include <set>
#include <sstream>
#include <stdexcept>
#include <thread>

#include "nursing_bed/core/gap/cycle_drift.h"
#include "nursing_bed/core/gap/diagnosis_stages.h"
#include "nursing_bed/core/gap/discovery.h"
#include "nursing_bed/core/gap/distortions.h"
#include "nursing_bed/core/gap/progress.h"

namespace nursing_bed {
namespace gap {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

}  // namespace

std::ptrdiff_t catalogPosition(const std::string& name) {
  const auto& c = effectCatalog();
  const auto& d = distortionCatalog();
  const auto i = std::find_if(c.begin(), c.end(), [&](const EffectSpec& e) { return e.name == name; }) - c.begin();
  if (i < static_cast<std::ptrdiff_t>(c.size())) return i;
  return i + (std::find_if(d.begin(), d.end(), [&](const EffectSpec& e) { return e.name == name; }) - d.begin());
}

bool isPhysicalCatalogEffect(const std::string& name) {
  const auto& c = effectCatalog();
  return std::any_of(c.begin(), c.end(), [&](const EffectSpec& e) { return e.name == name; });
}

namespace {

/// Indices of the fitted singles, best (lowest BIC) first, failed fits last.
std::vector<int> singlesByBic(const std::vector<ModelFit>& fits, int n) {
  std::vector<int> order(fits.size());
  std::iota(order.begin(), order.end(), 0);
  auto bic = [&](int i) {
    return fits[i].outcome.ok ? fits[i].outcome.chi2 + fits[i].model.axes.size() * std::log(n) : INFINITY;
  };
  std::sort(order.begin(), order.end(), [&](int a, int b) { return bic(a) < bic(b); });
  return order;
}

}  // namespace

ModelSpec pairSpec(const std::string& a, const std::string& b, const std::map<std::string, double>& calibration) {
  std::vector<std::string> names{a, b};
  std::sort(names.begin(), names.end(),
            [](const std::string& x, const std::string& y) { return catalogPosition(x) < catalogPosition(y); });
  ModelSpec m = makeModelSpec(names);
  m.fixed_calibration = calibration;
  return m;
}

std::vector<std::vector<double>> pairStarts(const ModelSpec& pair, const ModelFit& a, const ModelFit& b) {
  std::map<std::string, double> fitted;
  std::map<std::string, int> owner;  // 0: a's parameter, 1: b's
  for (int k = 0; k < 2; ++k) {
    const ModelFit* single = k == 0 ? &a : &b;
    for (std::size_t j = 0; j < single->model.axes.size(); ++j) {
      fitted[single->model.axes[j].spec.name] = single->outcome.u[j];
      owner[single->model.axes[j].spec.name] = k;
    }
  }
  std::vector<std::vector<double>> starts;
  for (int la = 0; la < 3; ++la)
    for (int lb = 0; lb < 3; ++lb) {
      std::vector<double> u;
      for (const auto& axis : pair.axes) {
        const int level = owner.at(axis.spec.name) == 0 ? la : lb;
        u.push_back(level == 0 ? fitted.at(axis.spec.name) : level == 1 ? 0.5 : std::max(axis.u_min, 0.0));
      }
      starts.push_back(u);
    }
  return starts;
}

namespace {

/// A fitted model's values split into the effects' parameters and the calibrated cell's (fixed
/// and fitted).
void splitValues(const ModelSpec& m, const std::map<std::string, double>& values, CandidateFit* c) {
  c->calibration = m.fixed_calibration;
  for (const auto& [name, v] : values) {
    const bool calibrated = std::find(m.calibration.begin(), m.calibration.end(), name) != m.calibration.end();
    (calibrated ? c->calibration : c->params)[name] = v;
  }
  c->joint = !m.calibration.empty();
}

/// Parameters a model fits beyond the baseline's: its effects' and the calibrated ones the
/// baseline holds at nominal; not those the fit holds (heldAxes()).
int extraParameters(const ModelSpec& m, const NoiseModel& noise) {
  int k = -static_cast<int>(heldAxes(noise.fit, m).size());
  for (const auto& a : m.axes) k += (!a.calibration || !noise.baseline_calibration.count(a.spec.name)) ? 1 : 0;
  return k;
}

/// The nominal model's score that decideVerdict() compares the candidates with.
NominalScore nominalScore(const NoiseModel& noise, double withheld_nrmse) {
  NominalScore s;
  s.chi2 = noise.baseline_chi2;
  s.fit_residuals = noise.fitResidualCount();
  s.withheld_chi2_per_sample = noise.baseline_withheld_chi2_per_sample;
  s.withheld_residuals = noise.heldResidualCount();
  s.withheld_nrmse = withheld_nrmse;
  return s;
}

/// nrmse of the nominal model over runs `indices`, from the replays already made.
double nominalNrmse(const PreparedRuns& prepared, const std::vector<Replay>& nominal,
                    const std::vector<std::size_t>& indices) {
  if (indices.empty()) return kNaN;
  std::vector<const Replay*> replays;
  for (std::size_t i : indices) replays.push_back(&nominal[i]);
  return pooledResidual(prepared.select(indices), replays).nrmse();
}

/// The first lines of the reasons: the nominal model's fit, and the gated flow meter.
void nominalReasons(const DiagnosisReport& rep, const PreparedRuns& prepared, const DiagnosisOptions& options,
                    bool withheld_residuals, std::vector<std::string>* reasons) {
  std::ostringstream why;
  why << "nominal model: chi2/n = " << fmt(rep.nominal_chi2_per_sample)
      << " in noise-floor units (within the noise up to " << fmt(options.within_noise_chi2) << ")"
      << (!withheld_residuals ? "" : ", " + fmt(rep.nominal_withheld_chi2_per_sample) + " on the withheld runs")
      << "; fit-run nrmse " << fmt(rep.nominal_fit_nrmse);
  reasons->push_back(why.str());
  if (rep.pressure_only)
    reasons->push_back(
        "no run has a height reading: the diagnosis works on pressure alone; effects whose "
        "signature lies in the height (plate_friction, membrane_viscoelasticity's creep) and the "
        "gusset height against the film's stiffness are then far harder to tell apart");
  if (prepared.gated_runs > 0)
    reasons->push_back("in " + std::to_string(prepared.gated_runs) + " of " + std::to_string(prepared.runs.size()) +
                       " runs the flow meter read noise around zero while the inlet was closed; the replay "
                       "takes zero flow there");
}

}  // namespace

// ---- stage 1: the runs ------------------------------------------------------------------------

std::vector<const RunData*> PreparedRuns::select(const std::vector<std::size_t>& indices) const {
  std::vector<const RunData*> out;
  for (std::size_t i : indices) out.push_back(&runs[i]);
  return out;
}

void chooseRoles(std::vector<RunData>* runs) {
  std::vector<std::size_t> order(runs->size());
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    const double la = (*runs)[a].loadAt(0), lb = (*runs)[b].loadAt(0);
    return la != lb ? la < lb : (*runs)[a].name < (*runs)[b].name;
  });
  for (std::size_t k = 0; k < order.size(); ++k) (*runs)[order[k]].role = (k % 4 == 1) ? "withheld" : "fit";
}

PreparedRuns prepareRuns(std::vector<RunData> runs) {
  if (runs.empty()) throw std::invalid_argument("no runs to diagnose");
  PreparedRuns p;
  bool any_role = false, all_roles = true;
  for (const auto& r : runs) {
    if (!r.role.empty() && r.role != "fit" && r.role != "withheld")
      throw std::invalid_argument(r.name + ": role must be fit or withheld, got '" + r.role + "'");
    any_role = any_role || !r.role.empty();
    all_roles = all_roles && !r.role.empty();
  }
  if (!any_role) {
    if (runs.size() < 2)
      throw std::invalid_argument("one run only: the diagnosis needs at least 2 (some to fit, some withheld)");
    chooseRoles(&runs);
    p.roles_chosen = true;
  } else if (!all_roles) {
    for (auto& r : runs)
      if (r.role.empty()) r.role = "fit";
  }
  // Noise of each run as measured; then the closed inlet's flow reading set to 0 where it is
  // noise around zero (zeroClosedInletFlow), keeping the measured flow for the traces.
  for (std::size_t i = 0; i < runs.size(); ++i) {
    p.noises.push_back(runNoise(runs[i]));
    p.measured_flow.push_back(runs[i].mdot_in_kg_s);
    p.gated_runs += zeroClosedInletFlow(&runs[i]) > 0 ? 1 : 0;
    (runs[i].role == "fit" ? p.fit : p.withheld).push_back(i);
  }
  if (p.fit.empty()) throw std::invalid_argument("no run has the role fit: nothing to fit the candidates on");
  p.runs = std::move(runs);
  return p;
}

std::vector<std::string> candidateList(const DiagnosisOptions& options) {
  std::vector<std::string> candidates = options.candidates.empty() ? candidateEffectNames() : options.candidates;
  for (const auto& c : candidates)
    if (!effectSpec(c).candidate) throw std::invalid_argument("'" + c + "' is not a candidate effect");
  return candidates;
}

std::vector<std::string> candidatesForStructure(const std::vector<std::string>& candidates, const CellParams& nominal,
                                                std::vector<std::string>* notes) {
  std::vector<std::string> kept;
  for (const auto& c : candidates) {
    const std::string& needs = effectSpec(c).structure;
    if (needs.empty() || needs == nominal.structure_type) {
      kept.push_back(c);
    } else if (notes) {
      notes->push_back(c + ": not fitted, it assumes the " + needs + " structure and the cell's is " +
                       nominal.structure_type);
    }
  }
  return kept;
}

// ---- stage 2: the nominal replay ----------------------------------------------------------------

std::vector<Replay> replayNominal(const PreparedRuns& prepared, const CellParams& params,
                                  const DiagnosisOptions& options, DiagnosisReport* report) {
  const std::vector<RunData>& runs = prepared.runs;
  std::vector<Replay> nominal(runs.size());
  parallelFor(static_cast<int>(runs.size()), options.threads,
              [&](int i) { nominal[i] = replayRun(runs[i], params, {}); });
  std::vector<double> noise_p, noise_h;
  for (std::size_t i = 0; i < runs.size(); ++i) {
    if (!nominal[i].ok) throw std::invalid_argument(nominal[i].message);
    const RunNoise& n = prepared.noises[i];
    noise_p.push_back(n.p_pa);
    noise_h.push_back(n.h_m);
    RunSummary s;
    s.name = runs[i].name;
    s.role = runs[i].role;
    s.load_n = runs[i].loadAt(0);
    s.duration_s = runs[i].t_s.back() - runs[i].t_s.front();
    s.noise_p_pa = n.p_pa;
    s.noise_h_m = n.h_m;
    s.before = runResidual(runs[i], nominal[i]);
    report->runs.push_back(s);
  }
  report->noise_p_pa = median(noise_p);
  report->noise_h_m = median(noise_h);
  report->localization = localizeGap(runs, nominal);
  std::vector<std::vector<GapEvent>> events(runs.size());
  parallelFor(static_cast<int>(runs.size()), options.threads, [&](int i) {
    events[i] = localiseInTime(runs[i], params, {}, prepared.noises[i].p_pa, prepared.noises[i].h_m);
  });
  for (const auto& run_events : events)
    report->events.insert(report->events.end(), run_events.begin(), run_events.end());
  return nominal;
}

// ---- stage 3: the noise model -------------------------------------------------------------------

NoiseModel buildNoiseModel(const PreparedRuns& prepared, const CellParams& params, const DiagnosisOptions& options) {
  NoiseModel m;
  m.fit.params = params;
  m.fit.params.relative_tolerance = std::max(params.relative_tolerance, options.fit_relative_tolerance);
  m.fit.params.time_step_s = std::max(params.time_step_s, options.fit_time_step_s);
  // The withheld runs get the same noise model: the verdict must fit them too.
  m.held.params = m.fit.params;
  m.fit.threads = m.held.threads = options.threads;
  m.fit.runs.resize(prepared.fit.size());
  m.held.runs.resize(prepared.withheld.size());
  parallelFor(static_cast<int>(prepared.runs.size()), options.threads, [&](int k) {
    FitData::Run run = prepareFitRun(prepared.runs[k], prepared.measured_flow[k], prepared.noises[k], m.fit.params,
                                     options.fit_sample_hz);
    auto f = std::find(prepared.fit.begin(), prepared.fit.end(), static_cast<std::size_t>(k));
    if (f != prepared.fit.end()) m.fit.runs[f - prepared.fit.begin()] = std::move(run);
    else
      m.held.runs[std::find(prepared.withheld.begin(), prepared.withheld.end(), static_cast<std::size_t>(k)) -
                  prepared.withheld.begin()] = std::move(run);
  });
  const int n_held = m.held.informativeCount();
  std::vector<double> r_held(m.held.residualCount());
  fitResiduals(m.held, {}, r_held.data());
  m.withheld_chi2_per_sample = n_held > 0 ? sumSquares(r_held) / n_held : kNaN;
  std::vector<double> r_nominal(m.fit.residualCount());
  fitResiduals(m.fit, {}, r_nominal.data());
  m.chi2_nominal = sumSquares(r_nominal);
  m.baseline_chi2 = m.chi2_nominal;
  m.baseline_withheld_chi2_per_sample = m.withheld_chi2_per_sample;
  return m;
}

// ---- stage 4: the candidates' fits -----------------------------------------------------------

std::vector<ModelFit> fitCandidates(const NoiseModel& noise, const std::vector<std::string>& candidates,
                                    const DiagnosisOptions& options,
                                    const std::function<void(const std::string&)>& progress,
                                    const std::function<void(std::vector<ModelFit>*)>& after_singles,
                                    const std::vector<ModelFit>& fitted_singles) {
  auto say = [&](const std::string& line) {
    if (progress) progress(line);
  };
  const int n = noise.fitResidualCount();
  std::vector<ModelFit> fits = fitted_singles;
  std::mutex say_mutex;
  std::atomic<int> done{0};
  if (fits.empty()) {
    for (const auto& c : candidates) fits.push_back({makeModelSpec({c}), {}});
    for (auto& f : fits) f.model.fixed_calibration = noise.baseline_calibration;
    parallelFor(static_cast<int>(fits.size()), options.threads, [&](int i) {
      fits[i].outcome = fitModel(noise.fit, fits[i].model, fitStarts(noise.fit, fits[i].model), options.max_iterations);
      std::lock_guard<std::mutex> lock(say_mutex);
      say("fitted " + joinNames(fits[i].model.effects) + " (" + std::to_string(++done) + "/" +
          std::to_string(fits.size()) + "): chi2/n " + fmt(fits[i].outcome.chi2 / n) + ", " +
          std::to_string(fits[i].outcome.evaluations) + " replays" +
          (options.verbose ? " [" + fits[i].outcome.message + "]" : std::string()));
    });
  }
  const int singles = static_cast<int>(fits.size());
  if (after_singles) after_singles(&fits);
  const std::vector<std::pair<int, int>> pairs =
      pairsToFit(fits, singlesByBic(fits, n), options.pair_pool, n, options.joint_refit_chi2);
  const auto fitted = std::count_if(fits.begin(), fits.end(), [](const ModelFit& f) { return f.outcome.ok; });
  if (pairs.empty() && options.pair_pool > 0)
    say(fitted < 2 ? "no pairs fitted: fewer than two candidates fitted"
                   : "no pairs fitted: a single fits within the noise");
  for (const auto& [a, b] : pairs)
    fits.push_back({pairSpec(fits[a].model.effects[0], fits[b].model.effects[0], noise.baseline_calibration), {}});
  done = 0;
  const int pair_count = static_cast<int>(pairs.size());
  parallelFor(pair_count, options.threads, [&](int k) {
    ModelFit& f = fits[singles + k];
    f.outcome = fitModel(noise.fit, f.model, pairStarts(f.model, fits[pairs[k].first], fits[pairs[k].second]),
                         options.max_iterations);
    std::lock_guard<std::mutex> lock(say_mutex);
    say("fitted pair " + joinNames(f.model.effects) + " (" + std::to_string(++done) + "/" + std::to_string(pair_count) +
        "): chi2/n " + fmt(f.outcome.chi2 / n));
  });
  return fits;
}

std::vector<std::pair<int, int>> pairsToFit(const std::vector<ModelFit>& fits, const std::vector<int>& order, int pool,
                                            int n, double within_chi2) {
  std::vector<int> ok;
  for (int i : order)
    if (fits[i].outcome.ok) ok.push_back(i);
  std::vector<std::pair<int, int>> pairs;
  if (ok.empty() || fits[ok[0]].outcome.chi2 / n <= within_chi2) return pairs;
  // Partners: every physical effect, and the best kPairedDistortions channel distortions of the
  // new family (there are many; a pair of two costs a fit of its own each).
  constexpr int kPairedDistortions = 3;
  std::vector<int> members;
  for (int a = 0; a < std::min<int>(pool, ok.size()); ++a) members.push_back(a);
  // A channel distortion may imitate one of two physical effects alone (a load offset a plate's
  // friction): the best physical single joins the pool then, so that the two are tried together.
  const auto physical = [&](int k) { return isPhysicalCatalogEffect(fits[ok[k]].model.effects[0]); };
  if (!members.empty() && std::none_of(members.begin(), members.end(), physical))
    for (int k = static_cast<int>(members.size()); k < static_cast<int>(ok.size()); ++k)
      if (physical(k)) {
        members.push_back(k);
        break;
      }
  for (int a : members) {
    int distortions = 0;
    for (std::size_t b = a + 1; b < ok.size(); ++b) {
      const bool distortion = !isPhysicalCatalogEffect(fits[ok[b]].model.effects[0]);
      if (distortion && distortions++ >= kPairedDistortions) continue;
      pairs.emplace_back(ok[a], ok[b]);
    }
  }
  return pairs;
}

// ---- stage 5: scores ------------------------------------------------------------------------------

std::vector<ScoredCandidate> scoreCandidates(const std::vector<ModelFit>& fits, const PreparedRuns& prepared,
                                             const NoiseModel& noise, const CellParams& params,
                                             const DiagnosisOptions& options) {
  const int n = noise.fitResidualCount(), n_held = noise.heldResidualCount();
  std::vector<ScoredCandidate> scored;
  for (const ModelFit& f : fits) {
    CandidateFit c;
    c.effects = f.model.effects;
    c.ok = f.outcome.ok;
    c.evaluations = f.outcome.evaluations;
    c.message = f.outcome.message;
    c.chi2 = c.bic_delta = kNaN;
    c.plausible = false;
    if (c.ok) {
      splitValues(f.model, valuesOf(f.model, f.outcome.u), &c);
      c.chi2 = f.outcome.chi2;
      c.bic_delta = (c.chi2 - noise.baseline_chi2) + extraParameters(f.model, noise) * std::log(static_cast<double>(n));
      c.plausible = plausibleValues(f.model, c.params, options.plausible_slack);
      c.beyond_plausible = !c.plausible && timingResolved(f.model, c.params);
    }
    scored.emplace_back(c, f.model);
  }
  // nrmse of every candidate on fit and withheld runs (final integration settings).
  const auto fit_runs = prepared.select(prepared.fit), withheld_runs = prepared.select(prepared.withheld);
  parallelFor(static_cast<int>(scored.size()), options.threads, [&](int i) {
    CandidateFit& c = scored[i].first;
    if (!c.ok) {
      c.fit_nrmse = c.withheld_nrmse = kNaN;
      return;
    }
    const auto effects = buildEffects(scored[i].second, c.params);
    const CellParams cell = applyCalibration(c.calibration, params);
    c.fit_nrmse = setResidual(fit_runs, cell, effects).total;
    c.withheld_nrmse = setResidual(withheld_runs, cell, effects).total;
    if (n_held > 0) {
      std::vector<double> r(noise.held.residualCount());
      fitResiduals(noise.held, applyCalibration(c.calibration, noise.held.params), effects, r.data());
      c.withheld_chi2_per_sample = sumSquares(r) / n_held;
    }
  });
  std::sort(scored.begin(), scored.end(), [](const auto& a, const auto& b) {
    const double x = a.first.ok ? a.first.bic_delta : INFINITY, y = b.first.ok ? b.first.bic_delta : INFINITY;
    return x < y;
  });
  return scored;
}

// ---- stage 7: shrinkage -------------------------------------------------------------------------

void shrinkage(const PreparedRuns& prepared, const CellParams& nominal_params,
               const std::map<std::string, double>& calibration, const std::vector<CellEffectPtr>& effects,
               const std::vector<Replay>& nominal, const DiagnosisOptions& options, DiagnosisReport* rep) {
  const CellParams params = applyCalibration(calibration, nominal_params);
  const bool reuse = effects.empty() && calibration.empty();
  const std::vector<RunData>& runs = prepared.runs;
  std::vector<Replay> after(runs.size());
  parallelFor(static_cast<int>(runs.size()), options.threads,
              [&](int i) { after[i] = reuse ? nominal[i] : replayRun(runs[i], params, effects); });
  // Each named cause alone (a single's is the final model itself).
  const std::size_t causes = effects.size() == rep->verdict_effects.size() ? effects.size() : 0;
  std::vector<std::vector<Replay>> alone(causes > 1 ? causes : 0, std::vector<Replay>(runs.size()));
  parallelFor(static_cast<int>(alone.size() * runs.size()), options.threads, [&](int k) {
    const std::size_t c = k / runs.size(), i = k % runs.size();
    alone[c][i] = replayRun(runs[i], params, {effects[c]});
  });
  std::vector<const Replay*> replays_before, replays_after;
  for (std::size_t i = 0; i < runs.size(); ++i) {
    rep->runs[i].after = runResidual(runs[i], after[i]);
    if (runs[i].role == "withheld") {
      replays_before.push_back(&nominal[i]);
      replays_after.push_back(&after[i]);
    }
    RunTrace t;
    t.name = runs[i].name;
    t.role = runs[i].role;
    t.t_s = runs[i].t_s;
    t.mdot_in_kg_s = prepared.measured_flow[i];
    t.p_meas_pa = runs[i].p_gauge_pa;
    t.h_meas_m = runs[i].h_m;
    t.p_nominal_pa = nominal[i].p_gauge_pa;
    t.h_nominal_m = nominal[i].h_m;
    t.p_after_pa = after[i].p_gauge_pa;
    t.h_after_m = after[i].h_m;
    t.phases = nominal[i].phases;
    for (std::size_t c = 0; c < causes; ++c) {
      const Replay& r = causes > 1 ? alone[c][i] : after[i];
      t.causes.push_back(rep->verdict_effects[c]);
      t.p_cause_pa.push_back(r.p_gauge_pa);
      t.h_cause_m.push_back(r.h_m);
    }
    rep->traces.push_back(std::move(t));
  }
  rep->withheld_p_before = rep->withheld_h_before = rep->withheld_p_after = rep->withheld_h_after = kNaN;
  rep->withheld_before = rep->withheld_after = kNaN;
  if (replays_before.empty()) return;
  const auto held_runs = prepared.select(prepared.withheld);
  const RunResidual b = pooledResidual(held_runs, replays_before), a = pooledResidual(held_runs, replays_after);
  rep->withheld_p_before = b.nrmse_p;
  rep->withheld_h_before = b.nrmse_h;
  rep->withheld_p_after = a.nrmse_p;
  rep->withheld_h_after = a.nrmse_h;
  rep->withheld_before = b.nrmse();
  rep->withheld_after = a.nrmse();
}

// ---- helpers ------------------------------------------------------------------------------------

double median(std::vector<double> v) {
  if (v.empty()) return kNaN;
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

SetResidual setResidual(const std::vector<const RunData*>& runs, const CellParams& params,
                        const std::vector<CellEffectPtr>& effects) {
  SetResidual s;
  if (runs.empty()) return s;
  std::vector<Replay> replays;
  std::vector<const Replay*> pointers;
  for (const RunData* run : runs) {
    replays.push_back(replayRun(*run, params, effects));
    s.ok = s.ok && replays.back().ok;
  }
  for (const auto& r : replays) pointers.push_back(&r);
  if (!s.ok) return s;
  const RunResidual pooled = pooledResidual(runs, pointers);
  s.p = pooled.nrmse_p;
  s.h = pooled.nrmse_h;
  s.total = pooled.nrmse();
  return s;
}

void parallelFor(int count, int threads, const std::function<void(int)>& task) {
  std::atomic<int> next{0};
  auto worker = [&]() {
    for (int i = next++; i < count; i = next++) task(i);
  };
  std::vector<std::thread> pool;
  for (int t = 1; t < std::max(1, threads); ++t) pool.emplace_back(worker);
  worker();
  for (auto& t : pool) t.join();
}

std::string fmt(double v, int precision) {
  std::ostringstream s;
  s << std::setprecision(precision) << v;
  return s.str();
}

}  // namespace gap

// ---- the pipeline -------------------------------------------------------------------------------

namespace {

std::vector<const std::map<std::string, std::string>*> runMetadata(const gap::PreparedRuns& prepared) {
  std::vector<const std::map<std::string, std::string>*> metas;
  for (const auto& r : prepared.runs) metas.push_back(&r.meta);
  return metas;
}

bool anySingleWithinNoise(const std::vector<gap::ModelFit>& fits, const gap::NoiseModel& noise,
                          const DiagnosisOptions& options) {
  return std::any_of(fits.begin(), fits.end(), [&](const gap::ModelFit& f) {
    return f.outcome.ok && f.model.effects.size() == 1 &&
           f.outcome.chi2 / noise.fitResidualCount() <= options.explained_chi2;
  });
}

/// decideVerdict(); where it names nothing on a recording the model never fits to the noise
/// (modelFloorApplies()), the decision above its model-form floor, and `above_floor` set.
Verdict judgeCandidates(const std::vector<CandidateFit>& candidates, const NominalScore& baseline,
                        const DiagnosisOptions& options, const gap::PreparedRuns& prepared, bool* above_floor) {
  Verdict verdict = decideVerdict(candidates, baseline, options);
  *above_floor = verdict.winner < 0 && baseline.chi2 / baseline.fit_residuals > options.within_noise_chi2 &&
                 modelFloorApplies(options, runMetadata(prepared));
  if (!*above_floor) return verdict;
  const Verdict above = decideVerdictAboveFloor(candidates, baseline, options);
  verdict.reasons.insert(verdict.reasons.end(), above.reasons.begin(), above.reasons.end());
  verdict.status = above.status;
  verdict.winner = above.winner;
  return verdict;
}

/// The named channel distortions of `winner` (fitted as `model`) in words, with standard errors
/// from the covariance of its fit (scaled by chi2/n where above 1).
std::vector<std::string> describeDistortions(const gap::NoiseModel& noise, const gap::ModelSpec& model,
                                             const CandidateFit& winner) {
  using namespace gap;
  std::vector<std::string> out;
  if (std::none_of(winner.effects.begin(), winner.effects.end(), isDistortionEffect)) return out;
  std::map<std::string, double> values = winner.params;
  values.insert(winner.calibration.begin(), winner.calibration.end());
  for (const auto& a : model.axes)
    if (!values.count(a.spec.name)) values[a.spec.name] = a.spec.off_value;
  std::map<std::string, double> se;
  Eigen::MatrixXd cov;
  const std::vector<double> u = coordinatesOf(model, values);
  if (fitCovariance(noise.fit, model, u, &cov)) {
    const double scale = std::sqrt(std::max(1.0, winner.chi2 / noise.fitResidualCount()));
    for (std::size_t j = 0; j < model.axes.size(); ++j) {
      const EffectParamSpec& p = model.axes[j].spec;
      const double du = std::sqrt(cov(j, j)) * scale;
      se[p.name] = p.log_scale ? values.at(p.name) * std::log(p.hi / p.lo) * du : (p.hi - p.lo) * du;
    }
  }
  for (const auto& e : winner.effects)
    if (isDistortionEffect(e)) out.push_back(describeDistortion(e, winner.params, se));
  return out;
}

/// Discovery (discovery.h) on top of the verdict's calibration: status "discovered" with the
/// terms as the verdict's effects when it finds a correction the withheld runs confirm.
void discoverWhatIsLeft(const gap::PreparedRuns& prepared, const gap::NoiseModel& noise, const CellParams& params,
                        const DiagnosisOptions& options, const std::function<void(const std::string&)>& say,
                        DiagnosisReport* rep, std::vector<CellEffectPtr>* verdict_effects) {
  const gap::DiscoveryResult d =
      gap::discoverTerms(prepared, noise, params, rep->calibration.movedValues(), options, say);
  rep->reasons.insert(rep->reasons.end(), d.reasons.begin(), d.reasons.end());
  if (!d.discovered) return;
  rep->status = "discovered";
  rep->verdict_effects = d.model.effects;
  rep->verdict_params.clear();
  for (const auto& t : d.terms) {
    rep->verdict_params[t.parameter] = t.coefficient;
    rep->discovered.push_back(t.equation);
  }
  *verdict_effects = gap::buildEffects(d.model, rep->verdict_params);
}

/// The runs prepared, replayed through the nominal model, and their noise model (the first
/// stages of both diagnoseRuns and calibrateRuns).
struct DiagnosisStart {
  gap::PreparedRuns prepared;
  std::vector<Replay> nominal;
  gap::NoiseModel noise;
  std::vector<std::string> calibrated;  ///< the parameters to calibrate
};

void startDiagnosis(std::vector<RunData> runs, const CellParams& params, const DiagnosisOptions& options,
                    DiagnosisReport* rep, DiagnosisStart* start) {
  using namespace gap;
  auto say = [&](const std::string& line) {
    if (options.progress) options.progress(line);
  };
  rep->options = options;
  rep->options.progress = nullptr;
  rep->options.status = nullptr;
  if (runs.empty()) throw std::invalid_argument("no runs to diagnose");
  const std::string params_problem = params.validate();
  if (!params_problem.empty()) throw std::invalid_argument("airbag parameters: " + params_problem);
  start->prepared = prepareRuns(std::move(runs));
  const PreparedRuns& prepared = start->prepared;
  rep->roles_chosen = prepared.roles_chosen;
  rep->pressure_only = std::all_of(prepared.runs.begin(), prepared.runs.end(), runHasNoHeight);
  for (std::size_t i : prepared.fit) rep->fit_runs.push_back(prepared.runs[i].name);
  for (std::size_t i : prepared.withheld) rep->withheld_runs.push_back(prepared.runs[i].name);
  start->calibrated = calibrationList(prepared, options, params);
  candidateList(options);                             // an unknown candidate before anything is replayed
  modelFloorApplies(options, runMetadata(prepared));  // an unknown model_floor word too
  say("replaying " + std::to_string(prepared.runs.size()) + " runs through the nominal model");
  start->nominal = replayNominal(prepared, params, options, rep);
  start->noise = buildNoiseModel(prepared, params, options);
  const int n = start->noise.fitResidualCount();
  rep->fit_samples = n;
  rep->nominal_chi2_per_sample = start->noise.chi2_nominal / n;
  rep->nominal_withheld_chi2_per_sample = start->noise.withheld_chi2_per_sample;
  rep->validation = validationTable(prepared, start->noise, start->nominal);
  rep->nominal_fit_nrmse = nominalNrmse(prepared, start->nominal, prepared.fit);
  say("noise floor: pressure " + fmt(rep->noise_p_pa) + " Pa, height " + fmt(rep->noise_h_m * 1e3) +
      " mm; nominal model: chi2/n = " + fmt(rep->nominal_chi2_per_sample) + " on " + std::to_string(n) +
      " fit residuals");
}

/// The progress lines of diagnoseRuns(), and after each the elapsed time and the time left on
/// DiagnosisOptions::status. Each stage plans its steps (a step costs `units` single fits); each
/// progress line within a stage is one step done; finish() drops what a stage did not run.
class StageClock {
 public:
  StageClock(const DiagnosisOptions& options, std::chrono::steady_clock::time_point started)
      : options_(options), started_(started) {}

  void plan(int stage, int steps, double units) {
    std::lock_guard<std::mutex> lock(mutex_);
    stages_[stage] = {steps, units, 0};
    estimate_.plan(steps, units);
  }
  /// Lines from now on are steps of `stage`; the first stage starts the clock of the estimate.
  void enter(int stage) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!estimating_) estimate_.start(elapsed());
    estimating_ = true;
    current_ = stage;
  }
  void finish(int stage) {
    std::lock_guard<std::mutex> lock(mutex_);
    Stage& st = stages_[stage];
    estimate_.unplan(st.planned - st.seen, st.units);
    st.seen = st.planned;
    if (current_ == stage) current_ = kNoStage;
  }
  void say(const std::string& line) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (options_.progress) options_.progress(line);
    if (current_ != kNoStage && stages_[current_].seen < stages_[current_].planned) {
      ++stages_[current_].seen;
      estimate_.done(stages_[current_].units, elapsed());
    }
    if (options_.status) options_.status(estimate_.line(elapsed()));
  }

 private:
  static constexpr int kNoStage = -1;
  struct Stage {
    int planned = 0;
    double units = 1.0;
    int seen = 0;
  };
  double elapsed() const { return std::chrono::duration<double>(std::chrono::steady_clock::now() - started_).count(); }
  const DiagnosisOptions& options_;
  const std::chrono::steady_clock::time_point started_;
  std::mutex mutex_;
  std::map<int, Stage> stages_;
  int current_ = kNoStage;
  bool estimating_ = false;
  gap::ProgressEstimate estimate_;
};

/// The stages of the fitting work, and what one step of each costs against a single's fit (a
/// calibration or joint refit fits four or more parameters, a pair two effects).
enum FitStage { kCalibration, kNominalSingles, kSingles, kJointSingles, kPairs, kJointPairs };
constexpr double kStageUnits[] = {2.0, 1.0, 1.0, 4.0, 3.0, 5.0};

/// The calibration, the singles and the pairs, with their joint refits (diagnoseRuns()).
struct FittedModels {
  gap::CalibrationFit calibration;
  std::vector<gap::ModelFit> fits;
  std::map<std::string, CalibrationSummary> joint;  ///< joint refits' summaries by model name
};

FittedModels fitModels(DiagnosisStart& s, const std::vector<std::string>& candidates, const DiagnosisOptions& options,
                       StageClock* clock) {
  using namespace gap;
  auto say = [&](const std::string& line) { clock->say(line); };
  NoiseModel& noise = s.noise;
  const int singles = static_cast<int>(candidates.size());
  const bool calibrating = !s.calibrated.empty();
  clock->plan(kCalibration, calibrating ? 1 : 0, kStageUnits[kCalibration]);
  clock->plan(kSingles, singles, kStageUnits[kSingles]);
  clock->plan(kJointSingles, calibrating ? options.joint_pool : 0, kStageUnits[kJointSingles]);
  clock->plan(kPairs, options.pair_pool > 0 ? singles - 1 : 0, kStageUnits[kPairs]);
  clock->plan(kJointPairs, calibrating && options.pair_pool > 0 ? 2 : 0, kStageUnits[kJointPairs]);
  FittedModels out;
  CalibrationFit& calibration = out.calibration;
  std::vector<ModelFit> uncalibrated;  // the singles on the nominal cell, when the calibration moved
  bool baseline_nominal = true;        // the effects are fitted on the nominal cell
  if (calibrating) {
    clock->enter(kCalibration);
    calibration = calibrateModel(noise, s.calibrated, options, say);
    clock->finish(kCalibration);
    if (!calibration.summary.movedValues().empty()) {
      // A calibration may imitate part of an effect (a larger vent area the gas a leak loses
      // while the controller holds); fitted on top of it the effect then fits badly. Its fit on
      // the nominal cell ranks it for, and starts, the joint refit.
      DiagnosisOptions nominal_singles = options;
      nominal_singles.pair_pool = 0;
      clock->plan(kNominalSingles, singles, kStageUnits[kNominalSingles]);
      clock->enter(kNominalSingles);
      uncalibrated = fitCandidates(noise, candidates, nominal_singles,
                                   [&](const std::string& line) { say(line + " (nominal cell)"); });
      clock->finish(kNominalSingles);
      if (dropCalibrationForEffect(noise, uncalibrated, options, &calibration)) say(calibration.summary.notes.back());
    }
    rebaseNoiseModel(&noise, calibration.summary.movedValues(), calibration.moved_chi2);
    baseline_nominal = calibration.summary.movedValues().empty();
  }
  if (baseline_nominal && !uncalibrated.empty()) clock->finish(kSingles);  // the same fits, reused
  // The best singles, then the best pair and every pair with a single that moved the
  // calibration, refitted with the calibration free as well.
  std::set<std::string> moved_calibration;
  auto settle = [&](std::vector<ModelFit>* fits, std::size_t effects, int pool) {
    const JointRefits more =
        refitBestJointly(noise, calibration, fits, effects, pool, options, say, moved_calibration, uncalibrated);
    out.joint.insert(more.summaries.begin(), more.summaries.end());
    if (effects == 1) moved_calibration = more.moved_calibration;
  };
  clock->enter(kSingles);
  out.fits = fitCandidates(
      noise, candidates, options, say,
      [&](std::vector<ModelFit>* fitted_singles) {
        clock->finish(kSingles);
        clock->enter(kJointSingles);
        if (calibrating) settle(fitted_singles, 1, options.joint_pool);
        clock->finish(kJointSingles);
        if (anySingleWithinNoise(*fitted_singles, noise, options)) clock->finish(kPairs);
        clock->enter(kPairs);
      },
      baseline_nominal ? uncalibrated : std::vector<ModelFit>{});
  clock->finish(kPairs);
  // A pair is named only where no single fits within the noise (verdict.cpp): else no pair refit.
  clock->enter(kJointPairs);
  if (calibrating && !anySingleWithinNoise(out.fits, noise, options)) settle(&out.fits, 2, 1);
  clock->finish(kJointPairs);
  return out;
}

/// The explanations the runs cannot tell from the verdict's (`winner`, -1 for none to judge),
/// from the calibration's own pairs, and from its moves (identifiability.h), each with its run.
std::vector<Confusion> whatTheRunsCannotTellApart(const std::vector<gap::ScoredCandidate>& scored, int winner,
                                                  const DiagnosisStart& s, const CellParams& params,
                                                  const DiagnosisOptions& options, const DiagnosisReport& rep) {
  using namespace gap;
  std::vector<Confusion> out;
  if (winner >= 0)
    out = findConfusions(scored, winner, s.prepared, s.noise, params, s.calibrated, options, rep.noise_p_pa);
  if (!rep.calibration.done) return out;
  for (auto& c :
       findCalibrationConfusions(s.prepared, s.noise, params, s.calibrated, rep.calibration, options, rep.noise_p_pa))
    out.push_back(std::move(c));
  for (auto& c : findCalibrationDistortionConfusions(s.prepared, s.noise, params, s.calibrated, rep.calibration,
                                                     options, rep.noise_p_pa))
    out.push_back(std::move(c));
  return out;
}

}  // namespace

double DiagnosisReport::withheldGapInFloors(bool after) const {
  const double chi2 = after ? withheld_chi2_after : nominal_withheld_chi2_per_sample;
  return std::isfinite(chi2) ? std::sqrt(std::max(0.0, chi2 - 1.0)) : NAN;
}

DiagnosisReport calibrateRuns(std::vector<RunData> runs, const CellParams& params, const DiagnosisOptions& options,
                              const std::string& dataset_name) {
  using namespace gap;
  const auto started = std::chrono::steady_clock::now();
  DiagnosisReport rep;
  rep.dataset = dataset_name;
  DiagnosisStart s;
  startDiagnosis(std::move(runs), params, options, &rep, &s);
  if (s.calibrated.empty()) throw std::invalid_argument("nothing to calibrate");
  const CalibrationFit calibration = calibrateModel(s.noise, s.calibrated, options, options.progress);
  rebaseNoiseModel(&s.noise, calibration.summary.movedValues(), calibration.moved_chi2);
  rep.calibration = calibration.summary;
  nominalReasons(rep, s.prepared, options, s.noise.heldResidualCount() > 0, &rep.reasons);
  // A recording the model never fits to the noise: the calibrated model is its model-form floor.
  const bool above_floor = s.noise.baseline_chi2 / s.noise.fitResidualCount() > options.within_noise_chi2 &&
                           modelFloorApplies(options, runMetadata(s.prepared));
  rep.status = s.noise.baseline_chi2 / s.noise.fitResidualCount() <= options.within_noise_chi2 || above_floor
                   ? "none"
                   : "unexplained";
  settleCalibratedStatus(s.noise, options, &rep, above_floor);
  settleNoneOnWithheld(s.noise, options, &rep, above_floor);
  if (above_floor)
    rep.reasons.push_back("model-form floor: the calibrated model stays at chi2/n " +
                          fmt(s.noise.baseline_chi2 / s.noise.fitResidualCount()) +
                          " (a recording of real hardware); gap diagnose judges the candidates above it");
  if (rep.status == "unexplained")
    rep.reasons.push_back("calibration alone leaves a significant gap: run gap diagnose");
  if (options.propose_runs)
    rep.confusions =
        findCalibrationConfusions(s.prepared, s.noise, params, s.calibrated, rep.calibration, options, rep.noise_p_pa);
  for (const auto& c : rep.confusions) rep.reasons.push_back(describeConfusion(c));
  shrinkage(s.prepared, params, rep.calibration.movedValues(), {}, s.nominal, options, &rep);
  rep.withheld_chi2_after = withheldChi2(s.noise, rep.calibration.movedValues(), {});
  calibratedOutcome(s.prepared, s.noise, params, &rep);
  rep.elapsed_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  return rep;
}

DiagnosisReport diagnoseRuns(std::vector<RunData> runs, const CellParams& params, const DiagnosisOptions& options,
                             const std::string& dataset_name) {
  using namespace gap;
  const auto started = std::chrono::steady_clock::now();
  StageClock clock(options, started);
  auto say = [&](const std::string& line) { clock.say(line); };
  DiagnosisReport rep;
  rep.dataset = dataset_name;
  DiagnosisStart s;
  startDiagnosis(std::move(runs), params, options, &rep, &s);
  const PreparedRuns& prepared = s.prepared;
  NoiseModel& noise = s.noise;
  std::vector<std::string> structure_notes;
  std::vector<std::string> candidates = candidatesForStructure(candidateList(options), params, &structure_notes);
  if (options.candidates.empty()) {
    // The channel distortions of the channels these runs have (distortions.h).
    std::vector<const RunData*> all;
    for (const auto& r : prepared.runs) all.push_back(&r);
    const std::vector<std::string> distortions = distortionCandidatesFor(all);
    candidates.insert(candidates.end(), distortions.begin(), distortions.end());
  }
  const FittedModels fitted = fitModels(s, candidates, options, &clock);
  const std::vector<ModelFit>& fits = fitted.fits;
  const CalibrationFit& calibration = fitted.calibration;
  const std::map<std::string, CalibrationSummary>& joint = fitted.joint;
  const std::vector<ScoredCandidate> scored = scoreCandidates(fits, prepared, noise, params, options);
  for (const auto& c : scored) rep.candidates.push_back(c.first);

  nominalReasons(rep, prepared, options, noise.heldResidualCount() > 0, &rep.reasons);
  rep.reasons.insert(rep.reasons.end(), structure_notes.begin(), structure_notes.end());
  const NominalScore baseline = nominalScore(noise, nominalNrmse(prepared, s.nominal, prepared.withheld));
  bool above_floor = false;
  Verdict verdict = judgeCandidates(rep.candidates, baseline, options, prepared, &above_floor);
  // Above the floor, a slow drift the whitened likelihood discounts: judged over whole breaths.
  DriftNaming drift;
  if (above_floor && verdict.winner < 0) {
    drift = nameDriftAboveFloor(prepared, params, noise.baseline_calibration, scored, options);
    verdict.reasons.insert(verdict.reasons.end(), drift.reasons.begin(), drift.reasons.end());
    if (drift.winner >= 0) verdict.winner = drift.winner, verdict.status = "explained";
  }
  rep.reasons.insert(rep.reasons.end(), verdict.reasons.begin(), verdict.reasons.end());
  rep.status = verdict.status;
  rep.calibration = calibration.summary;
  std::vector<CellEffectPtr> verdict_effects;
  if (verdict.winner >= 0) {
    const CandidateFit& w = rep.candidates[verdict.winner];
    rep.verdict_effects = w.effects;
    rep.verdict_params = drift.winner >= 0 ? drift.params : w.params;
    verdict_effects = buildEffects(scored[verdict.winner].second, rep.verdict_params);
    // A joint refit may have moved every parameter back to nominal (w.joint false): its summary
    // still replaces the calibration-only one the winner was not fitted with.
    if (joint.count(joinNames(w.effects))) rep.calibration = joint.at(joinNames(w.effects));
    CandidateFit named = w;  // the whole-breath rule's rescaled parameter, where it named it
    named.params = rep.verdict_params;
    rep.verdict_distortions = describeDistortions(noise, scored[verdict.winner].second, named);
    for (const auto& d : rep.verdict_distortions) rep.reasons.push_back("channel distortion named: " + d);
  }
  for (const auto& note : rep.calibration.notes)
    if (note.rfind("cannot tell apart: ", 0) == 0) rep.reasons.push_back(note);
  if (options.propose_runs) {
    if (drift.winner < 0 && verdict.winner >= 0)
      say("identifiability: the explanations within " + fmt(options.near_tie_bic) + " BIC of the verdict's");
    rep.confusions =
        whatTheRunsCannotTellApart(scored, drift.winner < 0 ? verdict.winner : -1, s, params, options, rep);
  }
  for (const auto& c : rep.confusions) rep.reasons.push_back(describeConfusion(c));
  settleCalibratedStatus(noise, options, &rep, above_floor);
  if (rep.status == "unexplained" && options.discover)
    discoverWhatIsLeft(prepared, noise, params, options, say, &rep, &verdict_effects);
  settleNoneOnWithheld(noise, options, &rep, above_floor);
  shrinkage(prepared, params, rep.calibration.movedValues(), verdict_effects, s.nominal, options, &rep);
  rep.withheld_chi2_after = withheldChi2(noise, rep.calibration.movedValues(), verdict_effects);
  calibratedOutcome(prepared, noise, params, &rep);
  rep.elapsed_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  say("verdict: " + rep.status + (verdict.winner >= 0 ? " by " + joinNames(rep.verdict_effects) : std::string()) +
      "; withheld nrmse " + fmt(rep.withheld_before) + " -> " + fmt(rep.withheld_after) + " (" + fmt(rep.elapsed_s) +
      " s)");
  return rep;
}

}  // namespace nursing_bed
