#include "nursing_bed/core/gap/fit_model.h"

#include "nursing_bed/core/gap/calibration.h"
#include "nursing_bed/core/gap/diagnosis_stages.h"

#include <ceres/ceres.h>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <stdexcept>

namespace nursing_bed {
namespace gap {
namespace {

/// Residual of a sample whose replay failed (in noise-floor units): large, finite.
constexpr double kFailedResidual = 1.0e3;
/// Forward-difference step in the fit coordinates (1 = the plausible range).
constexpr double kJacobianStep = 0.02;

}  // namespace

double FitAxis::toValue(double u) const {
  if (spec.log_scale) return spec.lo * std::pow(spec.hi / spec.lo, u);
  return spec.lo + u * (spec.hi - spec.lo);
}

double FitAxis::toU(double x) const {
  if (spec.log_scale) return std::log(std::max(x, 1e-300) / spec.lo) / std::log(spec.hi / spec.lo);
  return (x - spec.lo) / (spec.hi - spec.lo);
}

FitAxis makeAxis(const EffectParamSpec& p, bool calibration) {
  FitAxis a;
  a.spec = p;
  a.calibration = calibration;
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

ModelSpec makeModelSpec(const std::vector<std::string>& names, const std::vector<FitAxis>& calibration) {
  ModelSpec m;
  m.effects = names;
  for (const auto& a : calibration) {
    m.calibration.push_back(a.spec.name);
    m.axes.push_back(a);
  }
  for (const auto& n : names)
    for (const auto& p : effectSpec(n).params) m.axes.push_back(makeAxis(p));
  return m;
}

std::map<std::string, double> valuesOf(const ModelSpec& m, const std::vector<double>& u) {
  std::map<std::string, double> out;
  for (std::size_t i = 0; i < m.axes.size(); ++i) out[m.axes[i].spec.name] = m.axes[i].toValue(u[i]);
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

CellParams modelParams(const ModelSpec& m, const std::map<std::string, double>& values, const CellParams& base) {
  std::map<std::string, double> own = m.fixed_calibration;
  for (const auto& name : m.calibration) own[name] = values.at(name);
  return applyCalibration(own, base);
}

std::vector<double> coordinatesOf(const ModelSpec& m, const std::map<std::string, double>& values) {
  std::vector<double> u;
  for (const auto& a : m.axes) u.push_back(a.toU(values.at(a.spec.name)));
  return u;
}

bool plausibleValues(const ModelSpec& m, const std::map<std::string, double>& values, double slack) {
  for (const auto& a : m.axes) {
    if (a.calibration) continue;
    const double x = values.at(a.spec.name);
    if (a.spec.log_scale) {
      // Only too large is implausible: a small value is an effect that barely uses that
      // parameter (a short supply line), and the range's low end is what matters for a bed,
      // not a physical bound.
      if (x > a.spec.hi * slack) return false;
    } else {
      const double u = a.toU(x);
      if (u < -0.5 * (slack - 1.0) || u > 1.0 + 0.5 * (slack - 1.0)) return false;
    }
  }
  return true;
}

std::string joinNames(const std::vector<std::string>& names, const char* sep) {
  std::string s;
  for (const auto& n : names) s += (s.empty() ? "" : sep) + n;
  return s.empty() ? "nominal" : s;
}

int FitData::residualCount() const {
  int n = 0;
  for (const auto& r : runs) n += 2 * static_cast<int>(r.index.size());
  return n;
}

int FitData::informativeCount() const {
  int n = 0;
  for (const auto& r : runs) n += (r.has_height ? 2 : 1) * static_cast<int>(r.index.size());
  return n;
}

namespace {

/// One run's whitened residuals (2 per sample) into `out`; false when its replay failed (its
/// samples then count as kFailedResidual floors off).
bool runResiduals(const FitData::Run& r, const CellParams& params, const std::vector<CellEffectPtr>& effects,
                  double* out) {
  const Replay rep = replayRun(*r.data, params, effects, r.max_substeps);
  const int m = static_cast<int>(r.index.size());
  Eigen::Map<Eigen::VectorXd> e(out, 2 * m);
  bool ok = true;
  for (int j = 0; j < m; ++j) {
    const std::size_t i = r.index[j];
    double ep = (r.data->p_gauge_pa[i] - rep.p_gauge_pa[i]) / r.sigma_p_pa[j];
    double eh = r.has_height ? (r.data->h_m[i] - rep.h_m[i]) / r.sigma_h_m[j] : 0.0;
    if (!rep.ok || !std::isfinite(ep) || !std::isfinite(eh)) {
      ok = false;
      ep = eh = kFailedResidual;
    }
    e[2 * j] = ep;
    e[2 * j + 1] = eh;
  }
  r.correlation_cholesky.triangularView<Eigen::Lower>().solveInPlace(e);
  return ok;
}

}  // namespace

/// Whitened residuals of every fit sample (pressure then height per sample, scaled by the
/// floor, then decorrelated per run); `ok` false when a replay failed.
bool fitResiduals(const FitData& fit, const std::vector<CellEffectPtr>& effects, double* out) {
  return fitResiduals(fit, fit.params, effects, out);
}

bool fitResiduals(const FitData& fit, const CellParams& params, const std::vector<CellEffectPtr>& effects,
                  double* out) {
  const int runs = static_cast<int>(fit.runs.size());
  std::vector<int> offset(runs + 1, 0);
  for (int r = 0; r < runs; ++r) offset[r + 1] = offset[r] + 2 * static_cast<int>(fit.runs[r].index.size());
  std::vector<char> run_ok(runs, 1);
  parallelFor(runs, fit.threads,
              [&](int r) { run_ok[r] = runResiduals(fit.runs[r], params, effects, out + offset[r]); });
  return std::all_of(run_ok.begin(), run_ok.end(), [](char ok) { return ok != 0; });
}

double sumSquares(const std::vector<double>& r) {
  double s = 0.0;
  for (double x : r) s += x * x;
  return s;
}

namespace {

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
        // Forward, or backward at the upper bound; the other way where the replay fails there
        // (a failed column would stop the whole solve at its start).
        const double first = u[j] + kJacobianStep <= model_.axes[j].u_max ? kJacobianStep : -kJacobianStep;
        double step = 0.0;
        for (double s : {first, -first}) {
          std::vector<double> v = u;
          v[j] += s;
          if (v[j] < model_.axes[j].u_min || v[j] > model_.axes[j].u_max || !residualsAt(v, shifted.data())) continue;
          step = s;
          break;
        }
        if (step == 0.0) return false;
        for (int i = 0; i < n; ++i) jacobians[0][i * k + j] = (shifted[i] - residuals[i]) / step;
      }
    }
    return true;
  }

  bool residualsAt(const std::vector<double>& u, double* out) const {
    ++*evaluations_;
    try {
      const auto values = valuesOf(model_, u);
      return fitResiduals(fit_, modelParams(model_, values, fit_.params), buildEffects(model_, values), out);
    } catch (const std::invalid_argument&) {
      return false;  // outside what makeEffect() admits: Ceres shrinks its step
    }
  }

 private:
  const FitData& fit_;
  const ModelSpec& model_;
  std::atomic<int>* evaluations_;
};

}  // namespace

std::vector<std::vector<double>> gridStarts(const ModelSpec& m) {
  const int k = static_cast<int>(m.axes.size());
  std::vector<std::vector<double>> out{{}};
  for (int j = 0; j < k; ++j) {
    // A log-scale parameter also starts near off (its lower bound, 3 decades below the range).
    std::vector<double> levels =
        k == 1 ? std::vector<double>{0.0, 0.25, 0.5, 0.75, 1.0} : std::vector<double>{0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0};
    if (m.axes[j].spec.log_scale) levels.insert(levels.begin(), m.axes[j].u_min);
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

/// Levenberg-Marquardt from the best `refined` points of `starts` (a grid); the best result.
/// With two or more parameters a valley can hold LM far from the optimum (an inflow_bias fit
/// stopped at chi2/n 578 from one start): the second-best grid point gives it a second way in.
std::vector<int> heldAxes(const FitData& fit, const ModelSpec& model) {
  std::vector<int> held;
  const bool pressure_only =
      std::none_of(fit.runs.begin(), fit.runs.end(), [](const FitData::Run& r) { return r.has_height; });
  if (!pressure_only || !calibrationParamApplies(calibrationParam("compliance_m3_pa"), fit.params)) return held;
  for (std::size_t j = 0; j < model.axes.size(); ++j)
    if (!model.axes[j].calibration && model.axes[j].spec.name == "scale_error") held.push_back(static_cast<int>(j));
  return held;
}

FitOutcome fitModel(const FitData& fit, const ModelSpec& model, const std::vector<std::vector<double>>& starts,
                    int max_iterations) {
  std::atomic<int> evaluations{0};
  ReplayCost probe(fit, model, &evaluations);
  std::vector<double> r(fit.residualCount());
  std::vector<std::pair<double, std::vector<double>>> ranked;  // chi2, start
  const std::vector<int> held = heldAxes(fit, model);
  std::vector<std::vector<double>> tried;
  for (auto s : starts) {
    for (int j : held) s[j] = model.axes[j].toU(model.axes[j].spec.off_value);
    if (!held.empty() && std::find(tried.begin(), tried.end(), s) != tried.end()) continue;  // merged by the hold
    tried.push_back(s);
    if (probe.residualsAt(s, r.data())) ranked.emplace_back(sumSquares(r), s);
  }
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
    if (held.size() == model.axes.size()) problem.SetParameterBlockConstant(u.data());
    else if (!held.empty()) problem.SetManifold(u.data(), new ceres::SubsetManifold(static_cast<int>(u.size()), held));
    ceres::Solver::Options options;
    options.linear_solver_type = ceres::DENSE_QR;
    options.max_num_iterations = max_iterations;
    options.function_tolerance = 1e-5;
    options.parameter_tolerance = 1e-4;
    options.num_threads = 1;
    options.logging_type = ceres::SILENT;
    ceres::Solver::Summary summary;
    ceres::Solve(options, &problem, &summary);
    // A solve that failed at its start reports final_cost -1: never a result.
    if (summary.IsSolutionUsable() && summary.final_cost >= 0.0 && std::isfinite(summary.final_cost) &&
        2.0 * summary.final_cost <= best.chi2) {
      best.u = u;
      best.chi2 = 2.0 * summary.final_cost;
      best.message = summary.BriefReport();
    }
  }
  best.evaluations = evaluations;
  return best;
}

bool fitCovariance(const FitData& fit, const ModelSpec& model, const std::vector<double>& u, Eigen::MatrixXd* cov) {
  std::atomic<int> evaluations{0};
  const ReplayCost cost(fit, model, &evaluations);
  const int k = static_cast<int>(u.size()), n = fit.residualCount();
  std::vector<double> r(n), jac(static_cast<std::size_t>(n) * k);
  const double* parameters[] = {u.data()};
  double* jacobians[] = {jac.data()};
  if (!cost.Evaluate(parameters, r.data(), jacobians)) return false;
  const Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> J(jac.data(), n, k);
  const Eigen::MatrixXd jtj = J.transpose() * J;
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(jtj);
  const Eigen::VectorXd lambda = eigen.eigenvalues();
  const Eigen::MatrixXd V = eigen.eigenvectors();
  const double largest = lambda.cwiseAbs().maxCoeff();
  cov->setZero(k, k);
  std::vector<bool> unidentified(k, false);
  for (int i = 0; i < k; ++i) {
    if (lambda[i] > 1e-9 * largest && largest > 0.0) {
      *cov += V.col(i) * V.col(i).transpose() / lambda[i];
      continue;
    }
    for (int j = 0; j < k; ++j) unidentified[j] = unidentified[j] || std::fabs(V(j, i)) > 0.1;
  }
  for (int j = 0; j < k; ++j)
    if (unidentified[j]) (*cov)(j, j) = INFINITY;
  return true;
}

}  // namespace gap
}  // namespace nursing_bed
