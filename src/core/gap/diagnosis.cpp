#include "nursing_bed/core/gap/diagnosis.h"

#include <ceres/ceres.h>

#include <Eigen/Cholesky>
#include <Eigen/Core>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <iomanip>
#include <limits>
#include <mutex>
#include <numeric>
#include <sstream>
#include <stdexcept>
#include <thread>
#include <cstdlib>

#include "nursing_bed/core/gap/effects.h"

namespace nursing_bed {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
/// Replay accuracy in the noise floor: this share of the signal's measured range (the replay of
/// noise-free nominal data comes back within about 2e-3 of the range).
constexpr double kModelAccuracyShare = 5.0e-4;
/// Residual of a sample whose replay failed (in noise-floor units): large, finite.
constexpr double kFailedResidual = 1.0e3;
/// Largest number of samples of one run in the fits.
constexpr std::size_t kMaxFitSamples = 600;
/// Forward-difference step in the fit coordinates (1 = the plausible range).
constexpr double kJacobianStep = 0.02;

// ---- fit coordinates ------------------------------------------------------------------------
// Each fitted parameter is mapped to u, with u = 0 .. 1 spanning its plausible range (on a log
// scale where the catalogue says so), so that one step size and one trust region suit all.

struct FitAxis {
  const EffectParamSpec* spec = nullptr;
  double u_min = 0.0, u_max = 1.0;  ///< bounds: the admissible range, at most 3 decades/widths past

  double toValue(double u) const {
    if (spec->log_scale) return spec->lo * std::pow(spec->hi / spec->lo, u);
    return spec->lo + u * (spec->hi - spec->lo);
  }
  double toU(double x) const {
    if (spec->log_scale) return std::log(std::max(x, 1e-300) / spec->lo) / std::log(spec->hi / spec->lo);
    return (x - spec->lo) / (spec->hi - spec->lo);
  }
};

FitAxis makeAxis(const EffectParamSpec& p) {
  FitAxis a;
  a.spec = &p;
  if (p.log_scale) {
    const double lo = std::max(p.min_value, p.lo * 1e-3);
    const double hi = std::min(p.max_value, p.hi * 1e3);
    a.u_min = a.toU(lo);
    a.u_max = a.toU(hi);
  } else {
    a.u_min = std::max(a.toU(p.min_value), -3.0);
    a.u_max = std::min(a.toU(p.max_value), 4.0);
  }
  return a;
}

struct ModelSpec {
  std::vector<std::string> effects;
  std::vector<FitAxis> axes;  ///< every parameter of every effect, in order
};

ModelSpec makeModelSpec(const std::vector<std::string>& names) {
  ModelSpec m;
  m.effects = names;
  for (const auto& n : names)
    for (const auto& p : effectSpec(n).params) m.axes.push_back(makeAxis(p));
  return m;
}

std::map<std::string, double> valuesOf(const ModelSpec& m, const std::vector<double>& u) {
  std::map<std::string, double> out;
  for (std::size_t i = 0; i < m.axes.size(); ++i) out[m.axes[i].spec->name] = m.axes[i].toValue(u[i]);
  return out;
}

std::vector<CellEffectPtr> buildEffects(const ModelSpec& m, const std::map<std::string, double>& values) {
  std::vector<CellEffectPtr> effects;
  for (const auto& n : m.effects) {
    std::map<std::string, double> own;
    for (const auto& p : effectSpec(n).params) own[p.name] = values.at(p.name);
    effects.push_back(makeEffect(n, own));
  }
  sortEffectsForModel(&effects);
  return effects;
}

bool plausibleValues(const ModelSpec& m, const std::map<std::string, double>& values, double slack) {
  for (const auto& a : m.axes) {
    const double x = values.at(a.spec->name);
    if (a.spec->log_scale) {
      // Only too large is implausible: a small value is an effect that barely uses that
      // parameter (a short supply line), and the range's low end is what matters for a bed,
      // not a physical bound.
      if (x > a.spec->hi * slack) return false;
    } else {
      const double u = a.toU(x);
      if (u < -0.5 * (slack - 1.0) || u > 1.0 + 0.5 * (slack - 1.0)) return false;
    }
  }
  return true;
}

std::string joinNames(const std::vector<std::string>& names, const char* sep = "+") {
  std::string s;
  for (const auto& n : names) s += (s.empty() ? "" : sep) + n;
  return s.empty() ? "nominal" : s;
}

// ---- the fit runs and their noise floor -------------------------------------------------------

/// The fit runs with the samples that enter the fit and their noise floor.
struct FitData {
  struct Run {
    const RunData* data = nullptr;
    std::vector<std::size_t> index;   ///< samples used
    std::vector<double> sigma_p_pa;   ///< noise floor at those samples (its diagonal)
    std::vector<double> sigma_h_m;
    /// Cholesky factor of the correlation of the floor-scaled residuals [p0, h0, p1, h1, ...]:
    /// the integrated flow-meter noise is one random walk of the gas mass, shared by all
    /// samples after it, so those residuals are correlated; the fit whitens them with it.
    Eigen::MatrixXd correlation_cholesky;
    long max_substeps = 0;            ///< integration budget of one replay (see replayRun)
  };
  std::vector<Run> runs;
  CellParams params;  ///< with the fit's integration settings
  int residualCount() const {
    int n = 0;
    for (const auto& r : runs) n += 2 * static_cast<int>(r.index.size());
    return n;
  }
};

/// Whitened residuals of every fit sample (pressure then height per sample, scaled by the
/// floor, then decorrelated per run); `ok` false when a replay failed (its samples then count as
/// kFailedResidual floors off).
bool fitResiduals(const FitData& fit, const std::vector<CellEffectPtr>& effects, double* out) {
  bool ok = true;
  int k = 0;
  for (const auto& r : fit.runs) {
    const Replay rep = replayRun(*r.data, fit.params, effects, r.max_substeps);
    const int m = static_cast<int>(r.index.size());
    Eigen::Map<Eigen::VectorXd> e(out + k, 2 * m);
    for (int j = 0; j < m; ++j) {
      const std::size_t i = r.index[j];
      double ep = (r.data->p_gauge_pa[i] - rep.p_gauge_pa[i]) / r.sigma_p_pa[j];
      double eh = (r.data->h_m[i] - rep.h_m[i]) / r.sigma_h_m[j];
      if (!rep.ok || !std::isfinite(ep) || !std::isfinite(eh)) {
        ok = false;
        ep = eh = kFailedResidual;
      }
      e[2 * j] = ep;
      e[2 * j + 1] = eh;
    }
    r.correlation_cholesky.triangularView<Eigen::Lower>().solveInPlace(e);
    k += 2 * m;
  }
  return ok;
}

double sumSquares(const std::vector<double>& r) {
  double s = 0.0;
  for (double x : r) s += x * x;
  return s;
}

/// The readings' response to a change of the run's inputs: (replay of `changed` - `nominal`) /
/// `unit` per sample (0 where either is not finite); false (and zeros) when the replay fails.
bool replayResponse(const RunData& changed, const CellParams& params, const Replay& nominal, double unit,
                    std::vector<double>* dp, std::vector<double>* dh) {
  dp->assign(nominal.p_gauge_pa.size(), 0.0);
  dh->assign(nominal.h_m.size(), 0.0);
  const Replay rep = replayRun(changed, params, {});
  if (!rep.ok) return false;
  for (std::size_t i = 0; i < dp->size(); ++i) {
    const double p = (rep.p_gauge_pa[i] - nominal.p_gauge_pa[i]) / unit, h = (rep.h_m[i] - nominal.h_m[i]) / unit;
    (*dp)[i] = std::isfinite(p) ? p : 0.0;
    (*dh)[i] = std::isfinite(h) ? h : 0.0;
  }
  return true;
}

/// The model's sensitivity of the readings to a mass error made at the start: replays the run
/// with a little more gas injected in its first sample interval.
void massSensitivity(const RunData& run, const CellParams& params, const Replay& nominal, std::vector<double>* dp_dm,
                     std::vector<double>* dh_dm) {
  double injected = 0.0;
  for (std::size_t i = 1; i < run.size(); ++i) {
    const double q0 = run.mdot_in_kg_s[i - 1], q1 = run.mdot_in_kg_s[i];
    if (std::isfinite(q0) && std::isfinite(q1)) injected += 0.5 * std::max(0.0, q0 + q1) * (run.t_s[i] - run.t_s[i - 1]);
  }
  dp_dm->assign(run.size(), 0.0);
  dh_dm->assign(run.size(), 0.0);
  if (injected <= 0.0 || run.size() < 2 || !std::isfinite(run.mdot_in_kg_s[0]) || !std::isfinite(run.mdot_in_kg_s[1]))
    return;
  const double dm = 1e-3 * injected;
  RunData bumped = run;
  const double extra = dm / (run.t_s[1] - run.t_s[0]);
  bumped.mdot_in_kg_s[0] += extra;
  bumped.mdot_in_kg_s[1] += extra;
  replayResponse(bumped, params, nominal, dm, dp_dm, dh_dm);
}

/// The start: a run that starts lifted starts from the mean of its first height readings
/// (initialHeight), whose noise stays in the replay's gas for the whole run. Fills the
/// readings' sensitivity to the start height (from a replay started one noise floor higher)
/// and returns the start height's variance (0 for a run that starts flat).
double startSensitivity(const RunData& run, const CellParams& params, const Replay& nominal, double noise_h_m,
                        std::vector<double>* dp_dh0, std::vector<double>* dh_dh0) {
  dp_dh0->assign(run.size(), 0.0);
  dh_dh0->assign(run.size(), 0.0);
  const InitialHeight h0 = initialHeight(run);
  if (h0.samples == 0 || !(h0.h_m > kLandedHeightM) || !(noise_h_m > 0.0)) return 0.0;
  RunData lifted = run;
  for (std::size_t i = 0; i < run.size() && run.t_s[i] <= run.t_s[0] + kInitialRestS; ++i) lifted.h_m[i] += noise_h_m;
  if (!replayResponse(lifted, params, nominal, noise_h_m, dp_dh0, dh_dh0)) return 0.0;
  return noise_h_m * noise_h_m / h0.samples;
}

struct RunNoise {
  double p_pa = 0.0, h_m = 0.0;
};

RunNoise runNoise(const RunData& run) {
  return {estimateNoise(run.p_gauge_pa), estimateNoise(run.h_m)};
}

/// Noise floor of each used sample: sensor noise, the replay's accuracy, and the flow meter's
/// noise integrated by the replay (a random walk of the gas mass, seen through the model's
/// sensitivity).
/// Interval means say how much gas came in over an interval, not when within it: a valve pulse
/// may have been at its start or its end. Where that matters (the lift-off, where the plate
/// rings on its gas spring after every pulse) the readings are uncertain by the replay's
/// response to that timing: a replay with every interval's gas (and vent opening) moved half an
/// interval earlier. A timing uniform over the interval has a third of that shift's variance.
/// Fills the variances per sample (zero for instantaneous readings).
void timingSpread(const RunData& run, const CellParams& params, const Replay& nominal, std::vector<double>* var_p,
                  std::vector<double>* var_h) {
  const std::size_t n = run.size();
  var_p->assign(n, 0.0);
  var_h->assign(n, 0.0);
  if (!run.flow_interval_means || n < 3) return;
  RunData early = run;
  const bool has_valve = run.valve_cmd.size() == n;
  for (std::size_t i = 1; i + 1 < n; ++i) {
    if (std::isfinite(run.mdot_in_kg_s[i]) && std::isfinite(run.mdot_in_kg_s[i + 1]))
      early.mdot_in_kg_s[i] = 0.5 * (run.mdot_in_kg_s[i] + run.mdot_in_kg_s[i + 1]);
    if (has_valve && std::isfinite(run.valve_cmd[i]) && std::isfinite(run.valve_cmd[i + 1])) {
      const double vent = 0.5 * (std::max(0.0, -run.valve_cmd[i]) + std::max(0.0, -run.valve_cmd[i + 1]));
      early.valve_cmd[i] = vent > 0.0 ? -vent : std::max(0.0, run.valve_cmd[i]);
    }
  }
  replayResponse(early, params, nominal, 1.0, var_p, var_h);
  for (std::size_t i = 0; i < n; ++i) {
    (*var_p)[i] = (*var_p)[i] * (*var_p)[i] / 3.0;
    (*var_h)[i] = (*var_h)[i] * (*var_h)[i] / 3.0;
  }
}

FitData::Run prepareFitRun(const RunData& run, const std::vector<double>& measured_flow, const RunNoise& noise,
                           const CellParams& params, double sample_hz) {
  FitData::Run r;
  r.data = &run;
  const Replay nominal = replayRun(run, params, {});
  if (!nominal.ok) throw std::invalid_argument(nominal.message);
  std::vector<double> dp_dm, dh_dm;
  massSensitivity(run, params, nominal, &dp_dm, &dh_dm);
  const RunResidual range = runResidual(run, nominal);
  const double duration = run.t_s.back() - run.t_s.front();
  const double interval = duration / std::max<std::size_t>(1, run.size() - 1);
  // A fit may try parameters that make the model far stiffer than needed: a replay may cost at
  // most 8 times the nominal one.
  r.max_substeps = 8 * nominal.substeps + 1000;
  // About sample_hz, and at most kMaxFitSamples per run (the correlation matrix is dense).
  std::size_t usable = 0;
  for (std::size_t i = 0; i < run.size(); ++i) usable += nominal.phases[i] != RunPhase::kLanded ? 1 : 0;
  const std::size_t stride =
      std::max({std::size_t{1}, static_cast<std::size_t>(std::lround(1.0 / (sample_hz * interval))),
                (usable + kMaxFitSamples - 1) / kMaxFitSamples});
  std::vector<double> start_p, start_h;
  const double start_var = startSensitivity(run, params, nominal, noise.h_m, &start_p, &start_h);
  const std::vector<double> flow_noise = meterNoise(run, measured_flow, 25);
  std::vector<double> timing_p, timing_h;
  timingSpread(run, params, nominal, &timing_p, &timing_h);
  double walk_var = 0.0;
  std::vector<double> walk, white_p, white_h, gain_p, gain_h, g0_p, g0_h;
  for (std::size_t i = 0; i < run.size(); ++i) {
    // Flow set to 0 where the inlet is closed (zeroClosedInletFlow) integrates no noise.
    if (i > 0 && run.mdot_in_kg_s[i] != 0.0)
      walk_var += std::pow(std::max(flow_noise[i], 0.0) * (run.t_s[i] - run.t_s[i - 1]), 2);
    if (i % stride != 0 || nominal.phases[i] == RunPhase::kLanded) continue;
    if (!std::isfinite(run.p_gauge_pa[i]) || !std::isfinite(run.h_m[i])) continue;
    r.index.push_back(i);
    walk.push_back(walk_var);
    white_p.push_back(std::pow(noise.p_pa, 2) + std::pow(kModelAccuracyShare * range.range_p_pa, 2) + timing_p[i]);
    white_h.push_back(std::pow(noise.h_m, 2) + std::pow(kModelAccuracyShare * range.range_h_m, 2) + timing_h[i]);
    gain_p.push_back(dp_dm[i]);
    gain_h.push_back(dh_dm[i]);
    g0_p.push_back(start_p[i]);
    g0_h.push_back(start_h[i]);
    r.sigma_p_pa.push_back(std::sqrt(white_p.back() + dp_dm[i] * dp_dm[i] * walk_var + start_p[i] * start_p[i] * start_var));
    r.sigma_h_m.push_back(std::sqrt(white_h.back() + dh_dm[i] * dh_dm[i] * walk_var + start_h[i] * start_h[i] * start_var));
  }
  // Covariance of the scaled residuals: white sensor noise on the diagonal plus the mass walk,
  // Cov(e_a(t_j), e_b(t_l)) = g_a(t_j) g_b(t_l) Var_m(min(t_j, t_l)), plus the start's
  // s_a(t_j) s_b(t_l) Var_h0.
  const int m = static_cast<int>(r.index.size());
  Eigen::MatrixXd cov(2 * m, 2 * m);
  for (int j = 0; j < m; ++j)
    for (int l = 0; l <= j; ++l) {
      const double v = walk[l];  // l <= j: the earlier sample's walk variance
      const double gj[2] = {gain_p[j] / r.sigma_p_pa[j], gain_h[j] / r.sigma_h_m[j]};
      const double gl[2] = {gain_p[l] / r.sigma_p_pa[l], gain_h[l] / r.sigma_h_m[l]};
      const double sj[2] = {g0_p[j] / r.sigma_p_pa[j], g0_h[j] / r.sigma_h_m[j]};
      const double sl[2] = {g0_p[l] / r.sigma_p_pa[l], g0_h[l] / r.sigma_h_m[l]};
      for (int a = 0; a < 2; ++a)
        for (int b = 0; b < 2; ++b) {
          double c = gj[a] * gl[b] * v + sj[a] * sl[b] * start_var;
          if (j == l && a == b) c += (a == 0 ? white_p[j] / std::pow(r.sigma_p_pa[j], 2) : white_h[j] / std::pow(r.sigma_h_m[j], 2));
          cov(2 * j + a, 2 * l + b) = c;
          cov(2 * l + b, 2 * j + a) = c;
        }
    }
  Eigen::LLT<Eigen::MatrixXd> llt(cov);
  if (llt.info() != Eigen::Success) throw std::invalid_argument(run.name + ": the noise model is not positive definite");
  r.correlation_cholesky = llt.matrixL();
  return r;
}

// ---- Ceres --------------------------------------------------------------------------------

/// All fit residuals as a function of the fit coordinates u; Jacobian by forward differences
/// of whole replays (a step of kJacobianStep, backwards at the upper bound).
class ReplayCost : public ceres::CostFunction {
 public:
  ReplayCost(const FitData& fit, const ModelSpec& model, std::atomic<int>* evaluations)
      : fit_(fit), model_(model), evaluations_(evaluations) {
    set_num_residuals(fit.residualCount());
    mutable_parameter_block_sizes()->push_back(static_cast<int>(model.axes.size()));
  }

  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override {
    const int k = static_cast<int>(model_.axes.size());
    std::vector<double> u(parameters[0], parameters[0] + k);
    if (!residualsAt(u, residuals)) return false;
    if (jacobians && jacobians[0]) {
      const int n = num_residuals();
      std::vector<double> shifted(n);
      for (int j = 0; j < k; ++j) {
        std::vector<double> v = u;
        const double step = v[j] + kJacobianStep <= model_.axes[j].u_max ? kJacobianStep : -kJacobianStep;
        v[j] += step;
        if (!residualsAt(v, shifted.data())) return false;
        for (int i = 0; i < n; ++i) jacobians[0][i * k + j] = (shifted[i] - residuals[i]) / step;
      }
    }
    return true;
  }

  bool residualsAt(const std::vector<double>& u, double* out) const {
    ++*evaluations_;
    try {
      return fitResiduals(fit_, buildEffects(model_, valuesOf(model_, u)), out);
    } catch (const std::invalid_argument&) {
      return false;  // outside what makeEffect() admits: Ceres shrinks its step
    }
  }

 private:
  const FitData& fit_;
  const ModelSpec& model_;
  std::atomic<int>* evaluations_;
};

/// Starting points: a grid over the plausible range (5 points per parameter, 4 with two or
/// more parameters; plus one near off for log-scale ones).
std::vector<std::vector<double>> gridStarts(const ModelSpec& m) {
  const int k = static_cast<int>(m.axes.size());
  std::vector<std::vector<double>> out{{}};
  for (int j = 0; j < k; ++j) {
    // A log-scale parameter also starts near off (its lower bound, 3 decades below the range).
    std::vector<double> levels = k == 1 ? std::vector<double>{0.0, 0.25, 0.5, 0.75, 1.0}
                                        : std::vector<double>{0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0};
    if (m.axes[j].spec->log_scale) levels.insert(levels.begin(), m.axes[j].u_min);
    std::vector<std::vector<double>> next;
    for (const auto& prefix : out)
      for (double l : levels) {
        auto p = prefix;
        p.push_back(l);
        next.push_back(p);
      }
    out = next;
  }
  return out;
}

struct FitOutcome {
  std::vector<double> u;
  double chi2 = kNaN;
  bool ok = false;
  int evaluations = 0;
  std::string message;
};

/// Levenberg-Marquardt from the best `refined` points of `starts` (a grid); the best result.
/// With two or more parameters a valley can hold LM far from the optimum (an inflow_bias fit
/// stopped at chi2/n 578 from one start): the second-best grid point gives it a second way in.
FitOutcome fitModel(const FitData& fit, const ModelSpec& model, const std::vector<std::vector<double>>& starts,
                    int max_iterations) {
  std::atomic<int> evaluations{0};
  ReplayCost probe(fit, model, &evaluations);
  std::vector<double> r(fit.residualCount());
  std::vector<std::pair<double, std::vector<double>>> ranked;  // chi2, start
  for (const auto& s : starts)
    if (probe.residualsAt(s, r.data())) ranked.emplace_back(sumSquares(r), s);
  FitOutcome best;
  if (ranked.empty()) {
    best.evaluations = evaluations;
    best.message = "the model failed at every starting point";
    return best;
  }
  std::sort(ranked.begin(), ranked.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  const std::size_t refined = std::min<std::size_t>(ranked.size(), model.axes.size() >= 2 ? 2 : 1);
  best.ok = true;
  best.u = ranked[0].second;
  best.chi2 = ranked[0].first;
  for (std::size_t k = 0; k < refined; ++k) {
    ceres::Problem problem;
    std::vector<double> u = ranked[k].second;
    problem.AddResidualBlock(new ReplayCost(fit, model, &evaluations), nullptr, u.data());
    for (std::size_t j = 0; j < model.axes.size(); ++j) {
      problem.SetParameterLowerBound(u.data(), static_cast<int>(j), model.axes[j].u_min);
      problem.SetParameterUpperBound(u.data(), static_cast<int>(j), model.axes[j].u_max);
    }
    ceres::Solver::Options options;
    options.linear_solver_type = ceres::DENSE_QR;
    options.max_num_iterations = max_iterations;
    options.function_tolerance = 1e-5;
    options.parameter_tolerance = 1e-4;
    options.num_threads = 1;
    options.logging_type = ceres::SILENT;
    ceres::Solver::Summary summary;
    ceres::Solve(options, &problem, &summary);
    if (std::isfinite(summary.final_cost) && 2.0 * summary.final_cost <= best.chi2) {
      best.u = u;
      best.chi2 = 2.0 * summary.final_cost;
      best.message = summary.BriefReport();
    }
  }
  best.evaluations = evaluations;
  return best;
}

// ---- roles -------------------------------------------------------------------------------------

/// About a quarter of the runs withheld, spread over the loads: sorted by load then name, every
/// fourth starting with the second.
void chooseRoles(std::vector<RunData>* runs) {
  std::vector<std::size_t> order(runs->size());
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    const double la = (*runs)[a].loadAt(0), lb = (*runs)[b].loadAt(0);
    return la != lb ? la < lb : (*runs)[a].name < (*runs)[b].name;
  });
  for (std::size_t k = 0; k < order.size(); ++k) (*runs)[order[k]].role = (k % 4 == 1) ? "withheld" : "fit";
}


double median(std::vector<double> v) {
  if (v.empty()) return kNaN;
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

/// Mean nrmse (and per signal) of a set of runs under a model.
struct SetResidual {
  double total = kNaN, p = kNaN, h = kNaN;
  bool ok = true;
};

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

/// Runs `tasks` on `threads` workers (each task its index).
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

std::string fmt(double v, int precision = 3) {
  std::ostringstream s;
  s << std::setprecision(precision) << v;
  return s.str();
}

}  // namespace

Verdict decideVerdict(const std::vector<CandidateFit>& candidates, const NominalScore& nominal,
                      const DiagnosisOptions& options) {
  Verdict v;
  const int n = nominal.fit_residuals, n_held = nominal.withheld_residuals;
  const double chi2n_nominal = nominal.chi2 / n;
  const double held_before = n_held > 0 ? nominal.withheld_chi2_per_sample : kNaN;
  auto drop = [&](const CandidateFit& c) { return (nominal.chi2 - c.chi2) / n; };
  auto significant = [&](const CandidateFit& c) {
    return c.ok && c.plausible && c.bic_delta < -options.significant_bic_drop && drop(c) >= options.min_chi2_drop;
  };
  auto fitsFitRuns = [&](const CandidateFit& c) {
    return c.chi2 / n <= options.explained_chi2 ||
           c.chi2 / n - 1.0 <= (1.0 - options.explained_excess_removed) * (chi2n_nominal - 1.0);
  };
  auto fitsWithheld = [&](const CandidateFit& c) {
    if (!std::isfinite(held_before)) return true;  // nothing withheld
    const double after = c.withheld_chi2_per_sample;
    const bool within = after <= options.withheld_chi2 ||
                        (after - 1.0) <= (1.0 - options.withheld_gap_removed) * (held_before - 1.0);
    return within && (held_before - after) * n_held >= options.min_withheld_gain;  // held-out likelihood
  };
  auto explainsAlone = [&](const CandidateFit& c) { return significant(c) && fitsFitRuns(c) && fitsWithheld(c); };
  // A pair only where it beats the better of its two singles significantly, and neither single
  // explains the gap alone (the simpler answer first).
  auto pairEarnsItsPlace = [&](const CandidateFit& pair) {
    bool first = true;
    for (const CandidateFit& c : candidates) {
      if (!c.ok || c.effects.size() != 1) continue;
      if (std::find(pair.effects.begin(), pair.effects.end(), c.effects[0]) == pair.effects.end()) continue;
      if (explainsAlone(c)) return false;
      if (first && (c.bic_delta - pair.bic_delta < options.significant_bic_drop ||
                    (c.chi2 - pair.chi2) / n < options.min_chi2_drop))
        return false;
      first = false;
    }
    return true;
  };
  v.reasons.push_back("a candidate is significant when BIC drops by more than " + fmt(options.significant_bic_drop) +
                      " and chi2/n by at least " + fmt(options.min_chi2_drop) + "; it explains the gap when it leaves " +
                      "chi2/n <= " + fmt(options.explained_chi2) + " on the fit runs (or removes " +
                      fmt(100.0 * options.explained_excess_removed) + " % of the excess over 1), <= " +
                      fmt(options.withheld_chi2) + " on the withheld runs (or removes " +
                      fmt(100.0 * options.withheld_gap_removed) + " %) and lowers their chi2 by at least " +
                      fmt(options.min_withheld_gain));
  // Candidates in BIC order; the first that is significant and holds up (fits the fit runs
  // within the noise, and the withheld runs too, better than the nominal model) wins.
  int significant_count = 0;
  for (std::size_t i = 0; i < candidates.size(); ++i) {
    const CandidateFit& c = candidates[i];
    if (!significant(c) || (c.effects.size() > 1 && !pairEarnsItsPlace(c))) continue;
    ++significant_count;
    std::ostringstream e;
    e << joinNames(c.effects) << ": BIC " << fmt(c.bic_delta, 4) << ", chi2/n " << fmt(c.chi2 / n) << " on the fit runs";
    if (std::isfinite(held_before))
      e << ", " << fmt(c.withheld_chi2_per_sample) << " on the withheld runs (chi2 " << fmt(held_before * n_held, 5)
        << " -> " << fmt(c.withheld_chi2_per_sample * n_held, 5) << ", nrmse " << fmt(nominal.withheld_nrmse) << " -> "
        << fmt(c.withheld_nrmse) << ")";
    const bool fit_ok = fitsFitRuns(c), held_ok = fitsWithheld(c);
    e << (fit_ok && held_ok ? ": explains the gap"
          : !fit_ok         ? ": leaves too much on the fit runs"
                            : ": does not hold up on the withheld runs");
    v.reasons.push_back(e.str());
    if (fit_ok && held_ok) {
      v.winner = static_cast<int>(i);
      break;
    }
    if (significant_count >= 4) break;  // the rest fit worse still
  }
  if (significant_count == 0) v.reasons.push_back("no candidate improves the fit significantly");
  // A near tie on the fit runs: a candidate (no more effects than the winner) that also
  // explains the gap and fits the fit runs about as well; the withheld runs decide.
  if (v.winner >= 0 && std::isfinite(held_before)) {
    const CandidateFit& w = candidates[v.winner];
    for (std::size_t i = 0; i < candidates.size(); ++i) {
      const CandidateFit& c = candidates[i];
      if (static_cast<int>(i) == v.winner || c.effects.size() > w.effects.size()) continue;
      if (!(std::fabs(c.bic_delta - w.bic_delta) < options.near_tie_bic)) continue;
      if (!explainsAlone(c) || (c.effects.size() > 1 && !pairEarnsItsPlace(c))) continue;
      const double gain = (w.withheld_chi2_per_sample - c.withheld_chi2_per_sample) * n_held;
      std::ostringstream e;
      e << joinNames(w.effects) << " and " << joinNames(c.effects) << " fit the fit runs about equally well (BIC "
        << fmt(w.bic_delta, 5) << " and " << fmt(c.bic_delta, 5) << "); on the withheld runs their chi2 is "
        << fmt(w.withheld_chi2_per_sample * n_held, 5) << " and " << fmt(c.withheld_chi2_per_sample * n_held, 5);
      if (gain >= options.min_withheld_gain) {
        e << ": the withheld runs decide for " << joinNames(c.effects);
        v.reasons.push_back(e.str());
        v.winner = static_cast<int>(i);
        break;
      }
      e << ": " << (gain <= -options.min_withheld_gain ? "the withheld runs confirm " + joinNames(w.effects)
                                                        : "the withheld runs do not tell them apart either; " +
                                                              joinNames(w.effects) + " by BIC");
      v.reasons.push_back(e.str());
    }
  }
  if (v.winner >= 0) {
    v.status = "explained";
  } else if (chi2n_nominal <= options.within_noise_chi2) {
    v.status = "none";
    v.reasons.push_back("the nominal model fits within the noise, and no candidate both improves it significantly "
                        "and holds up on the withheld runs");
  } else {
    v.status = "unexplained";
    v.reasons.push_back("a significant gap that no candidate accounts for");
  }
  return v;
}

DiagnosisReport diagnoseRuns(std::vector<RunData> runs, const CellParams& params, const DiagnosisOptions& options,
                             const std::string& dataset_name) {
  const auto started = std::chrono::steady_clock::now();
  auto say = [&](const std::string& line) {
    if (options.progress) options.progress(line);
  };
  DiagnosisReport rep;
  rep.dataset = dataset_name;
  rep.options = options;
  rep.options.progress = nullptr;
  if (runs.empty()) throw std::invalid_argument("no runs to diagnose");
  const std::string params_problem = params.validate();
  if (!params_problem.empty()) throw std::invalid_argument("airbag parameters: " + params_problem);

  // Roles: as given, or chosen here when no run has one.
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
    rep.roles_chosen = true;
  } else if (!all_roles) {
    for (auto& r : runs)
      if (r.role.empty()) r.role = "fit";
  }
  // Noise of each run as measured; then the closed inlet's flow reading set to 0 where it is
  // noise around zero (zeroClosedInletFlow), keeping the measured flow for the traces.
  std::vector<RunNoise> noises;
  std::vector<std::vector<double>> measured_flow;
  int gated_runs = 0;
  for (auto& r : runs) {
    noises.push_back(runNoise(r));
    measured_flow.push_back(r.mdot_in_kg_s);
    gated_runs += zeroClosedInletFlow(&r) > 0 ? 1 : 0;
  }
  std::vector<const RunData*> fit_runs, withheld_runs;
  for (const auto& r : runs) {
    (r.role == "fit" ? fit_runs : withheld_runs).push_back(&r);
    (r.role == "fit" ? rep.fit_runs : rep.withheld_runs).push_back(r.name);
  }
  if (fit_runs.empty()) throw std::invalid_argument("no run has the role fit: nothing to fit the candidates on");

  std::vector<std::string> candidates = options.candidates.empty() ? candidateEffectNames() : options.candidates;
  for (const auto& c : candidates)
    if (!effectSpec(c).candidate) throw std::invalid_argument("'" + c + "' is not a candidate effect");

  // 1. Nominal replay of every run; noise; where the gap lies.
  say("replaying " + std::to_string(runs.size()) + " runs through the nominal model");
  std::vector<Replay> nominal(runs.size());
  parallelFor(static_cast<int>(runs.size()), options.threads,
              [&](int i) { nominal[i] = replayRun(runs[i], params, {}); });
  std::vector<double> noise_p, noise_h;
  for (std::size_t i = 0; i < runs.size(); ++i) {
    if (!nominal[i].ok) throw std::invalid_argument(nominal[i].message);
    const RunNoise& n = noises[i];
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
    rep.runs.push_back(s);
  }
  rep.noise_p_pa = median(noise_p);
  rep.noise_h_m = median(noise_h);
  rep.localization = localizeGap(runs, nominal);

  // 2. Fit data: subsampled residuals with their noise floor, the fit's integration settings.
  FitData fit;
  fit.params = params;
  fit.params.relative_tolerance = std::max(params.relative_tolerance, options.fit_relative_tolerance);
  fit.params.time_step_s = std::max(params.time_step_s, options.fit_time_step_s);
  // The withheld runs get the same noise model: the verdict must fit them too.
  FitData held;
  held.params = fit.params;
  fit.runs.resize(fit_runs.size());
  held.runs.resize(withheld_runs.size());
  parallelFor(static_cast<int>(runs.size()), options.threads, [&](int k) {
    const RunData* run = &runs[k];
    auto f = std::find(fit_runs.begin(), fit_runs.end(), run);
    FitData::Run prepared = prepareFitRun(*run, measured_flow[k], noises[k], fit.params, options.fit_sample_hz);
    if (f != fit_runs.end()) fit.runs[f - fit_runs.begin()] = std::move(prepared);
    else held.runs[std::find(withheld_runs.begin(), withheld_runs.end(), run) - withheld_runs.begin()] = std::move(prepared);
  });
  const int n_held = held.residualCount();
  std::vector<double> r_held(n_held);
  fitResiduals(held, {}, r_held.data());
  rep.nominal_withheld_chi2_per_sample = n_held > 0 ? sumSquares(r_held) / n_held : kNaN;
  const int n = fit.residualCount();
  rep.fit_samples = n;
  std::vector<double> r_nominal(n);
  fitResiduals(fit, {}, r_nominal.data());
  const double chi2_nominal = sumSquares(r_nominal);
  rep.nominal_chi2_per_sample = chi2_nominal / n;
  // nrmse of the nominal model over a set of runs, from the replays already made.
  auto nominalNrmse = [&](const std::vector<const RunData*>& set) {
    std::vector<const Replay*> replays;
    for (const RunData* r : set) replays.push_back(&nominal[r - runs.data()]);
    return set.empty() ? kNaN : pooledResidual(set, replays).nrmse();
  };
  rep.nominal_fit_nrmse = nominalNrmse(fit_runs);
  say("noise floor: pressure " + fmt(rep.noise_p_pa) + " Pa, height " + fmt(rep.noise_h_m * 1e3) +
      " mm; nominal model: chi2/n = " + fmt(rep.nominal_chi2_per_sample) + " on " + std::to_string(n) +
      " fit residuals");

  // 3. Candidates: singles from a grid, then pairs of the best singles from their fits.
  std::vector<ModelSpec> models;
  for (const auto& c : candidates) models.push_back(makeModelSpec({c}));
  std::vector<FitOutcome> outcomes(models.size());
  std::mutex say_mutex;
  std::atomic<int> done{0};
  const int singles = static_cast<int>(models.size());
  parallelFor(singles, options.threads, [&](int i) {
    outcomes[i] = fitModel(fit, models[i], gridStarts(models[i]), options.max_iterations);
    std::lock_guard<std::mutex> lock(say_mutex);
    say("fitted " + joinNames(models[i].effects) + " (" + std::to_string(++done) + "/" + std::to_string(singles) +
        "): chi2/n " + fmt(outcomes[i].chi2 / n) + ", " + std::to_string(outcomes[i].evaluations) + " replays" +
        (std::getenv("NB_GAP_VERBOSE") ? " [" + outcomes[i].message + "]" : std::string()));
  });
  std::vector<int> order(singles);
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](int a, int b) {
    const double ca = outcomes[a].ok ? outcomes[a].chi2 + models[a].axes.size() * std::log(n) : INFINITY;
    const double cb = outcomes[b].ok ? outcomes[b].chi2 + models[b].axes.size() * std::log(n) : INFINITY;
    return ca < cb;
  });
  const int pool = std::min(options.pair_pool, singles);
  std::vector<std::pair<int, int>> pairs;
  for (int a = 0; a < pool; ++a)
    for (int b = a + 1; b < pool; ++b)
      if (outcomes[order[a]].ok && outcomes[order[b]].ok) pairs.emplace_back(order[a], order[b]);
  const int pair_offset = singles;
  for (const auto& [a, b] : pairs) {
    std::vector<std::string> names{models[a].effects[0], models[b].effects[0]};
    // Catalogue order, so the parameters line up with the singles' fits below.
    std::sort(names.begin(), names.end(), [](const std::string& x, const std::string& y) {
      const auto& c = effectCatalog();
      auto pos = [&](const std::string& s) {
        return std::find_if(c.begin(), c.end(), [&](const EffectSpec& e) { return e.name == s; }) - c.begin();
      };
      return pos(x) < pos(y);
    });
    models.push_back(makeModelSpec(names));
  }
  outcomes.resize(models.size());
  done = 0;
  const int pair_count = static_cast<int>(pairs.size());
  parallelFor(pair_count, options.threads, [&](int k) {
    const ModelSpec& m = models[pair_offset + k];
    // Start from the two singles' fits (and from each alone with the other near off).
    std::map<std::string, double> start;
    for (int idx : {pairs[k].first, pairs[k].second})
      for (std::size_t j = 0; j < models[idx].axes.size(); ++j)
        start[models[idx].axes[j].spec->name] = outcomes[idx].u[j];
    std::vector<double> u;
    for (const auto& a : m.axes) u.push_back(start.at(a.spec->name));
    outcomes[pair_offset + k] = fitModel(fit, m, {u}, options.max_iterations);
    std::lock_guard<std::mutex> lock(say_mutex);
    say("fitted pair " + joinNames(m.effects) + " (" + std::to_string(++done) + "/" + std::to_string(pair_count) +
        "): chi2/n " + fmt(outcomes[pair_offset + k].chi2 / n));
  });

  // 4. Scores: BIC of the whitened residuals, chi2 + k ln n, against the nominal model's.
  std::vector<std::pair<CandidateFit, ModelSpec>> scored;
  for (std::size_t i = 0; i < models.size(); ++i) {
    CandidateFit c;
    c.effects = models[i].effects;
    c.ok = outcomes[i].ok;
    c.evaluations = outcomes[i].evaluations;
    c.message = outcomes[i].message;
    if (c.ok) {
      c.params = valuesOf(models[i], outcomes[i].u);
      c.chi2 = outcomes[i].chi2;
      c.bic_delta = (c.chi2 - chi2_nominal) + models[i].axes.size() * std::log(static_cast<double>(n));
      c.plausible = plausibleValues(models[i], c.params, options.plausible_slack);
    } else {
      c.chi2 = kNaN;
      c.bic_delta = kNaN;
      c.plausible = false;
    }
    scored.emplace_back(c, models[i]);
  }
  // nrmse of every candidate on fit and withheld runs (final integration settings).
  parallelFor(static_cast<int>(scored.size()), options.threads, [&](int i) {
    CandidateFit& c = scored[i].first;
    if (!c.ok) {
      c.fit_nrmse = c.withheld_nrmse = kNaN;
      return;
    }
    const auto effects = buildEffects(scored[i].second, c.params);
    c.fit_nrmse = setResidual(fit_runs, params, effects).total;
    c.withheld_nrmse = setResidual(withheld_runs, params, effects).total;
    if (n_held > 0) {
      std::vector<double> r(n_held);
      fitResiduals(held, effects, r.data());
      c.withheld_chi2_per_sample = sumSquares(r) / n_held;
    }
  });
  std::sort(scored.begin(), scored.end(), [](const auto& a, const auto& b) {
    const double x = a.first.ok ? a.first.bic_delta : INFINITY, y = b.first.ok ? b.first.bic_delta : INFINITY;
    return x < y;
  });
  for (const auto& s : scored) rep.candidates.push_back(s.first);

  // 5. Verdict (decideVerdict).
  NominalScore nominal_score;
  nominal_score.chi2 = chi2_nominal;
  nominal_score.fit_residuals = n;
  nominal_score.withheld_chi2_per_sample = rep.nominal_withheld_chi2_per_sample;
  nominal_score.withheld_residuals = n_held;
  nominal_score.withheld_nrmse = nominalNrmse(withheld_runs);
  std::ostringstream why;
  why << "nominal model: chi2/n = " << fmt(rep.nominal_chi2_per_sample) << " in noise-floor units (within the noise up to "
      << fmt(options.within_noise_chi2) << ")"
      << (n_held > 0 ? ", " + fmt(rep.nominal_withheld_chi2_per_sample) + " on the withheld runs" : "")
      << "; fit-run nrmse " << fmt(rep.nominal_fit_nrmse);
  rep.reasons.push_back(why.str());
  if (gated_runs > 0)
    rep.reasons.push_back("in " + std::to_string(gated_runs) + " of " + std::to_string(runs.size()) +
                          " runs the flow meter read noise around zero while the inlet was closed; the replay "
                          "takes zero flow there");
  const Verdict verdict = decideVerdict(rep.candidates, nominal_score, options);
  rep.reasons.insert(rep.reasons.end(), verdict.reasons.begin(), verdict.reasons.end());
  rep.status = verdict.status;
  const bool explained = verdict.winner >= 0;
  const ModelSpec* winner_model = explained ? &scored[verdict.winner].second : nullptr;
  if (explained) {
    rep.verdict_effects = rep.candidates[verdict.winner].effects;
    rep.verdict_params = rep.candidates[verdict.winner].params;
  }

  // 6. Shrinkage and traces with the verdict model (the nominal one when nothing is named).
  std::vector<CellEffectPtr> verdict_effects;
  if (explained) verdict_effects = buildEffects(*winner_model, rep.verdict_params);
  std::vector<Replay> after(runs.size());
  parallelFor(static_cast<int>(runs.size()), options.threads,
              [&](int i) { after[i] = explained ? replayRun(runs[i], params, verdict_effects) : nominal[i]; });
  std::vector<const RunData*> held_runs;
  std::vector<const Replay*> replays_before, replays_after;
  for (std::size_t i = 0; i < runs.size(); ++i) {
    rep.runs[i].after = runResidual(runs[i], after[i]);
    if (runs[i].role == "withheld") {
      held_runs.push_back(&runs[i]);
      replays_before.push_back(&nominal[i]);
      replays_after.push_back(&after[i]);
    }
    RunTrace t;
    t.name = runs[i].name;
    t.role = runs[i].role;
    t.t_s = runs[i].t_s;
    t.mdot_in_kg_s = measured_flow[i];
    t.p_meas_pa = runs[i].p_gauge_pa;
    t.h_meas_m = runs[i].h_m;
    t.p_nominal_pa = nominal[i].p_gauge_pa;
    t.h_nominal_m = nominal[i].h_m;
    t.p_after_pa = after[i].p_gauge_pa;
    t.h_after_m = after[i].h_m;
    t.phases = nominal[i].phases;
    rep.traces.push_back(std::move(t));
  }
  if (!held_runs.empty()) {
    const RunResidual b = pooledResidual(held_runs, replays_before), a = pooledResidual(held_runs, replays_after);
    rep.withheld_p_before = b.nrmse_p;
    rep.withheld_h_before = b.nrmse_h;
    rep.withheld_p_after = a.nrmse_p;
    rep.withheld_h_after = a.nrmse_h;
    rep.withheld_before = b.nrmse();
    rep.withheld_after = a.nrmse();
  } else {
    rep.withheld_p_before = rep.withheld_h_before = rep.withheld_p_after = rep.withheld_h_after = kNaN;
    rep.withheld_before = rep.withheld_after = kNaN;
  }
  rep.elapsed_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  say("verdict: " + rep.status + (explained ? " by " + joinNames(rep.verdict_effects) : std::string()) +
      "; withheld nrmse " + fmt(rep.withheld_before) + " -> " + fmt(rep.withheld_after) + " (" +
      fmt(rep.elapsed_s) + " s)");
  return rep;
}

}  // namespace nursing_bed
