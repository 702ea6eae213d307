#include "nursing_bed/core/gap/fit_model.h"

#include "nursing_bed/core/gap/calibration.h"
#include "nursing_bed/core/gap/diagnosis_stages.h"
#include "nursing_bed/core/gap/distortions.h"

#include <ceres/ceres.h>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <condition_variable>
#include <deque>
#include <limits>
#include <map>
#include <memory>
#include <mutex>
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

namespace {

/// A channel's time shift or lag below this is below what a replay resolves (its fits integrate
/// in 10 ms steps, the runs' intervals are 10-20 ms): the replay's own timing, not the channel's.
constexpr double kMinChannelTimingS = 1e-3;

/// Whether parameter `name` is the time of a channel's shift or lag (distortions.h).
bool channelTiming(const ModelSpec& m, const std::string& name) {
  for (const auto& e : m.effects) {
    const EffectSpec& spec = effectSpec(e);
    if ((spec.kind == "shift" || spec.kind == "lag") && spec.param(name)) return true;
  }
  return false;
}

}  // namespace

bool timingResolved(const ModelSpec& m, const std::map<std::string, double>& values) {
  for (const auto& a : m.axes)
    if (!a.calibration && channelTiming(m, a.spec.name) && std::fabs(values.at(a.spec.name)) < kMinChannelTimingS)
      return false;
  return true;
}

bool plausibleValues(const ModelSpec& m, const std::map<std::string, double>& values, double slack) {
  if (!timingResolved(m, values)) return false;
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
/// `base`, when given, is the run's replay without `effects`, which are output-side channel
/// distortions only: their readings are then `base`'s transformed, with no new replay, unless
/// they move the replay's start (a height offset that makes a lifted start flat).
bool runResiduals(const FitData::Run& r, const CellParams& params, const std::vector<CellEffectPtr>& effects,
                  double* out, const Replay* base = nullptr) {
  Replay rep;
  if (base && !distortionsMoveTheStart(*r.data, effects)) {
    rep = *base;
    applyOutputDistortions(effects, r.data->t_s, &rep.p_gauge_pa, &rep.h_m);
  } else {
    rep = replayRun(*r.data, params, effects, r.max_substeps);
  }
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

/// Whitened residuals at points of the fit coordinates, remembered: Levenberg-Marquardt evaluates
/// a point it accepts once more with its Jacobian, and a solve starts at a grid point the probe
/// has replayed. A replay is a pure function of the coordinates, so a remembered vector is
/// exactly what a new replay would give. Each batch of points is replayed run by run across
/// FitData::threads (a Jacobian's columns and the runs together keep both cores busy); every
/// value lands in its own slot, so the result does not depend on the threads' scheduling.
class ResidualEvaluator {
 public:
  ResidualEvaluator(const FitData& fit, const ModelSpec& model) : fit_(fit), model_(model) {
    offset_.push_back(0);
    for (const auto& r : fit.runs) offset_.push_back(offset_.back() + 2 * static_cast<int>(r.index.size()));
    output_only_ = model.calibration.empty() && !model.effects.empty() &&
                   std::all_of(model.effects.begin(), model.effects.end(), [](const std::string& e) {
                     const EffectSpec& spec = effectSpec(e);
                     return (spec.channel == "pressure" || spec.channel == "height") && e != "pressure_sensor_lag";
                   });
  }
  /// One for a solve of its own, starting with what `probe` remembers and no replays counted
  /// (a solve's own memory: what it finds there does not depend on another solve beside it).
  explicit ResidualEvaluator(const ResidualEvaluator& probe)
      : fit_(probe.fit_),
        model_(probe.model_),
        offset_(probe.offset_),
        output_only_(probe.output_only_),
        base_(probe.base_),
        base_early_(probe.base_early_),
        entries_(probe.entries_) {}

  /// Residuals at each of `points` into outs[i] (residualCount() values each); ok[i] false where
  /// the model is not admitted there or a replay failed.
  void evaluate(const std::vector<std::vector<double>>& points, const std::vector<double*>& outs,
                std::vector<char>* ok) {
    ok->assign(points.size(), 0);
    struct Miss {
      std::size_t point;
      CellParams params;
      std::vector<CellEffectPtr> effects;
    };
    std::vector<Miss> misses;
    for (std::size_t i = 0; i < points.size(); ++i) {
      if (recall(points[i], outs[i], &(*ok)[i])) continue;
      try {
        const auto values = valuesOf(model_, points[i]);
        misses.push_back({i, modelParams(model_, values, fit_.params), buildEffects(model_, values)});
      } catch (const std::invalid_argument&) {
        remember(points[i], nullptr, false);  // outside what makeEffect() admits: Ceres shrinks its step
      }
    }
    const int runs = static_cast<int>(fit_.runs.size());
    std::vector<const std::vector<Replay>*> bases(misses.size(), nullptr);
    for (std::size_t k = 0; output_only_ && k < misses.size(); ++k)
      bases[k] = baseReplays(misses[k].params, readsHeightEarly(misses[k].effects));
    std::vector<char> run_ok(misses.size() * runs, 1);
    parallelFor(static_cast<int>(run_ok.size()), fit_.threads, [&](int task) {
      const Miss& m = misses[task / runs];
      const int r = task % runs;
      const Replay* base = bases[task / runs] ? &(*bases[task / runs])[r] : nullptr;
      run_ok[task] = runResiduals(fit_.runs[r], m.params, m.effects, outs[m.point] + offset_[r], base);
    });
    for (std::size_t k = 0; k < misses.size(); ++k) {
      const std::size_t i = misses[k].point;
      (*ok)[i] = std::all_of(run_ok.begin() + k * runs, run_ok.begin() + (k + 1) * runs, [](char c) { return c != 0; });
      remember(points[i], outs[i], (*ok)[i] != 0);
    }
    replays_ += static_cast<int>(misses.size());
  }

  bool evaluate(const std::vector<double>& u, double* out) {
    std::vector<char> ok;
    evaluate({u}, {out}, &ok);
    return ok[0] != 0;
  }

  /// `r` (residualCount() values; ok false: the point does not replay) is what `u` gives, kept
  /// among the last kRemembered points.
  void remember(const std::vector<double>& u, const double* r, bool ok) {
    std::lock_guard<std::mutex> lock(mutex_);
    Entry e;
    e.u = u;
    e.ok = ok;
    if (r && ok) e.r.assign(r, r + offset_.back());
    entries_.push_back(std::move(e));
    if (entries_.size() > kRemembered) entries_.pop_front();
  }

  /// Replays of the fit-run set made (remembered points not counted).
  int replays() const { return replays_; }

  const ModelSpec& model() const { return model_; }
  int residualCount() const { return offset_.back(); }

 private:
  /// Points remembered: the last few, enough for an accepted step and a solve's start.
  static constexpr std::size_t kRemembered = 8;
  struct Entry {
    std::vector<double> u, r;
    bool ok = false;
  };

  /// The fit runs replayed once without effects on `params` (the same at every point of a model
  /// without free calibrated parameters), for a model of output-side distortions only; with
  /// `early` the replays start as a height read early has them start (ReplayStart::kNotHeight).
  const std::vector<Replay>* baseReplays(const CellParams& params, bool early) {
    std::lock_guard<std::mutex> lock(base_mutex_);
    std::shared_ptr<const std::vector<Replay>>& base = early ? base_early_ : base_;
    if (base) return base.get();
    auto replays = std::make_shared<std::vector<Replay>>(fit_.runs.size());
    const ReplayStart start = early ? ReplayStart::kNotHeight : ReplayStart::kReadings;
    parallelFor(static_cast<int>(fit_.runs.size()), fit_.threads, [&](int r) {
      (*replays)[r] =
          replayRun(*fit_.runs[r].data, params, {}, fit_.runs[r].max_substeps, IntervalShape::kSpread, start);
    });
    base = replays;
    return base.get();
  }

  bool recall(const std::vector<double>& u, double* out, char* ok) const {
    std::lock_guard<std::mutex> lock(mutex_);
    for (const Entry& e : entries_)
      if (e.u == u) {
        if (e.ok) std::copy(e.r.begin(), e.r.end(), out);
        *ok = e.ok;
        return true;
      }
    return false;
  }

  const FitData& fit_;
  const ModelSpec& model_;
  std::vector<int> offset_;   ///< each run's first residual slot
  bool output_only_ = false;  ///< output-side channel distortions only: base_ transformed
  std::shared_ptr<const std::vector<Replay>> base_, base_early_;
  std::mutex base_mutex_;
  mutable std::mutex mutex_;
  std::deque<Entry> entries_;
  std::atomic<int> replays_{0};
};

/// All fit residuals as a function of the fit coordinates u; Jacobian by forward differences
/// of whole replays (a step of kJacobianStep, backwards at the upper bound), the columns
/// replayed together.
class ReplayCost : public ceres::CostFunction {
 public:
  explicit ReplayCost(ResidualEvaluator* evaluator) : evaluator_(evaluator) {
    set_num_residuals(evaluator->residualCount());
    mutable_parameter_block_sizes()->push_back(static_cast<int>(evaluator->model().axes.size()));
  }

  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override {
    const ModelSpec& model = evaluator_->model();
    const int k = static_cast<int>(model.axes.size()), n = num_residuals();
    const std::vector<double> u(parameters[0], parameters[0] + k);
    if (!(jacobians && jacobians[0])) return evaluator_->evaluate(u, residuals);
    // Forward, or backward at the upper bound; the other way where the replay fails there (a
    // failed column would stop the whole solve at its start).
    std::vector<double> step(k, 0.0), shifted(static_cast<std::size_t>(n) * k);
    std::vector<char> done(k, 0);
    for (int attempt = 0; attempt < 2; ++attempt) {
      std::vector<std::vector<double>> points;
      std::vector<double*> outs;
      std::vector<int> columns;
      if (attempt == 0) {
        points.push_back(u);
        outs.push_back(residuals);
      }
      for (int j = 0; j < k; ++j) {
        if (done[j]) continue;
        const double first = u[j] + kJacobianStep <= model.axes[j].u_max ? kJacobianStep : -kJacobianStep;
        const double s = attempt == 0 ? first : -first;
        std::vector<double> v = u;
        v[j] += s;
        if (v[j] < model.axes[j].u_min || v[j] > model.axes[j].u_max) continue;
        step[j] = s;
        points.push_back(v);
        outs.push_back(shifted.data() + static_cast<std::size_t>(j) * n);
        columns.push_back(j);
      }
      std::vector<char> ok;
      evaluator_->evaluate(points, outs, &ok);
      const std::size_t first_column = attempt == 0 ? 1 : 0;
      if (attempt == 0 && !ok[0]) return false;
      for (std::size_t c = 0; c < columns.size(); ++c) done[columns[c]] = ok[first_column + c];
    }
    for (int j = 0; j < k; ++j) {
      if (!done[j]) return false;
      const double* col = shifted.data() + static_cast<std::size_t>(j) * n;
      for (int i = 0; i < n; ++i) jacobians[0][i * k + j] = (col[i] - residuals[i]) / step[j];
    }
    return true;
  }

 private:
  ResidualEvaluator* evaluator_;
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

std::vector<std::vector<double>> fitStarts(const FitData& fit, const ModelSpec& m) {
  std::vector<std::vector<double>> starts = gridStarts(m);
  if (m.axes.size() != 1 || m.axes[0].calibration || m.axes[0].spec.name != "height_offset_m") return starts;
  double sum = 0.0;
  int count = 0;
  for (const auto& r : fit.runs) {
    const double h0 = r.has_height ? initialHeight(*r.data).h_m : NAN;
    if (std::isfinite(h0)) sum += h0, ++count;
  }
  if (count == 0) return starts;
  const FitAxis& a = m.axes[0];
  const double u = a.toU(sum / count);
  if ((u < 0.0 || u > 1.0) && u > a.u_min && u < a.u_max) starts.push_back({u});
  return starts;
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

namespace {

/// Stops a solve that, at its best pace over its last kPaceIterations steps taken (the largest
/// relative drop of the cost in one), could not get below `target_cost` within its iterations left.
class OvertakeCheck : public ceres::IterationCallback {
 public:
  OvertakeCheck(double target_cost, int max_iterations) : target_cost_(target_cost), max_(max_iterations) {}
  ceres::CallbackReturnType operator()(const ceres::IterationSummary& s) override {
    // The pace of the steps taken: a rejected one shrinks the trust region, not the solve's pace.
    if (!s.step_is_successful) return ceres::SOLVER_CONTINUE;
    costs_.push_back(s.cost);
    if (!std::isfinite(target_cost_) || costs_.size() <= kPaceIterations) return ceres::SOLVER_CONTINUE;
    double pace = 0.0;
    for (std::size_t i = costs_.size() - kPaceIterations; i < costs_.size(); ++i)
      pace = std::max(pace, 1.0 - costs_[i] / costs_[i - 1]);
    const double reachable = s.cost * std::pow(1.0 - std::min(pace, 1.0), std::max(0, max_ - s.iteration));
    if (!(reachable > target_cost_)) return ceres::SOLVER_CONTINUE;
    stopped_ = true;
    return ceres::SOLVER_TERMINATE_SUCCESSFULLY;
  }
  bool stopped() const { return stopped_; }

 private:
  static constexpr std::size_t kPaceIterations = 3;
  double target_cost_;
  int max_;
  std::vector<double> costs_;
  bool stopped_ = false;
};

/// The solves of one fit side by side, in step: after each iteration every solve still running
/// posts its point and cost, and a solve whose point lies within kSameBasinU (of every fit
/// coordinate's range) of a lower one's stops there: both descend to the same minimum, and the
/// one left goes on with the cores to itself. Decided on the same iteration of all, so the
/// outcome does not depend on the threads' timing.
class SolveMeeting {
 public:
  explicit SolveMeeting(std::size_t solves) : history_(solves), posted_(solves, -1) {}

  /// True: solve k stops at its point of iteration `iteration`.
  bool post(std::size_t k, int iteration, const std::vector<double>& u, double cost) {
    std::unique_lock<std::mutex> lock(mutex_);
    history_[k][iteration] = {u, cost};
    posted_[k] = iteration;
    changed_.notify_all();
    changed_.wait(lock,
                  [&] { return std::all_of(posted_.begin(), posted_.end(), [&](int p) { return p >= iteration; }); });
    for (std::size_t i = 0; i < history_.size(); ++i) {
      const auto other = history_[i].find(iteration);
      if (i == k || other == history_[i].end()) continue;
      const auto& [point, other_cost] = other->second;
      if (!(other_cost < cost || (other_cost == cost && i < k))) continue;
      double far = 0.0;
      for (std::size_t j = 0; j < u.size(); ++j) far = std::max(far, std::fabs(point[j] - u[j]));
      if (far < kSameBasinU) return true;
    }
    return false;
  }

  /// Solve k has ended (or stopped): the others no longer wait for it.
  void leave(std::size_t k) {
    std::lock_guard<std::mutex> lock(mutex_);
    posted_[k] = std::numeric_limits<int>::max();
    changed_.notify_all();
  }

 private:
  static constexpr double kSameBasinU = 0.01;
  std::mutex mutex_;
  std::condition_variable changed_;
  std::vector<std::map<int, std::pair<std::vector<double>, double>>> history_;  ///< per solve: iteration -> point, cost
  std::vector<int> posted_;  ///< per solve: its last iteration posted (max int once it has left)
};

/// Solve k's view of the meeting (a Ceres callback; the point is its parameter block).
class MeetingCallback : public ceres::IterationCallback {
 public:
  MeetingCallback(SolveMeeting* meeting, std::size_t k, const std::vector<double>* u)
      : meeting_(meeting), k_(k), u_(u) {}
  ceres::CallbackReturnType operator()(const ceres::IterationSummary& s) override {
    if (!meeting_->post(k_, s.iteration, *u_, s.cost)) return ceres::SOLVER_CONTINUE;
    meeting_->leave(k_);
    return ceres::SOLVER_TERMINATE_SUCCESSFULLY;
  }

 private:
  SolveMeeting* meeting_;
  std::size_t k_;
  const std::vector<double>* u_;
};

/// The lowest-cost point a solve has stood on. A step the line search accepted on its cost
/// alone can land where a Jacobian column does not replay either way; Ceres then ends the solve
/// as failed, and the point before it is still a fit.
class BestPoint : public ceres::IterationCallback {
 public:
  explicit BestPoint(const std::vector<double>* u) : u_(u) {}
  ceres::CallbackReturnType operator()(const ceres::IterationSummary& s) override {
    if (s.step_is_successful && std::isfinite(s.cost) && s.cost < cost_) {
      cost_ = s.cost;
      best_ = *u_;
    }
    return ceres::SOLVER_CONTINUE;
  }
  double cost() const { return cost_; }
  const std::vector<double>& point() const { return best_; }

 private:
  const std::vector<double>* u_;
  double cost_ = INFINITY;
  std::vector<double> best_;
};

/// The distinct starts, the `held` axes at their off value, probed in one batch: those that
/// replay, by chi2, the best `solves` of them remembered. A repeated start (the hold merges some;
/// a calibration that moved nothing starts its joint refits twice at nominal) would be solved
/// twice to the same end.
std::vector<std::pair<double, std::vector<double>>> rankStarts(ResidualEvaluator* evaluator, const FitData& fit,
                                                               const ModelSpec& model, const std::vector<int>& held,
                                                               const std::vector<std::vector<double>>& starts,
                                                               std::size_t solves) {
  std::vector<std::vector<double>> tried;
  for (auto s : starts) {
    for (int j : held) s[j] = model.axes[j].toU(model.axes[j].spec.off_value);
    if (std::find(tried.begin(), tried.end(), s) != tried.end()) continue;
    tried.push_back(s);
  }
  // Their residuals are needed for their sums only.
  const std::size_t n = static_cast<std::size_t>(fit.residualCount());
  std::vector<double> probe(tried.size() * n);
  std::vector<double*> outs;
  for (std::size_t i = 0; i < tried.size(); ++i) outs.push_back(probe.data() + i * n);
  std::vector<char> ok;
  evaluator->evaluate(tried, outs, &ok);
  std::vector<std::pair<double, std::size_t>> order;  // chi2, start
  for (std::size_t i = 0; i < tried.size(); ++i)
    if (ok[i]) order.emplace_back(sumSquares(std::vector<double>(outs[i], outs[i] + n)), i);
  std::sort(order.begin(), order.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  // The solves start at the best `solves`: their residuals are remembered last, whatever the
  // grid's size.
  for (std::size_t k = std::min(order.size(), solves); k-- > 0;)
    evaluator->remember(tried[order[k].second], outs[order[k].second], true);
  std::vector<std::pair<double, std::vector<double>>> ranked;
  for (const auto& [chi2, i] : order) ranked.emplace_back(chi2, tried[i]);
  return ranked;
}

/// One Levenberg-Marquardt solve of `model` from `u` (in place) within its axes' bounds, the
/// `held` axes constant; `callbacks` watch its iterations.
ceres::Solver::Summary solveFrom(ResidualEvaluator* evaluator, const ModelSpec& model, const std::vector<int>& held,
                                 int max_iterations, const std::vector<ceres::IterationCallback*>& callbacks,
                                 std::vector<double>* u) {
  ceres::Problem problem;
  problem.AddResidualBlock(new ReplayCost(evaluator), nullptr, u->data());
  for (std::size_t j = 0; j < model.axes.size(); ++j) {
    problem.SetParameterLowerBound(u->data(), static_cast<int>(j), model.axes[j].u_min);
    problem.SetParameterUpperBound(u->data(), static_cast<int>(j), model.axes[j].u_max);
  }
  if (held.size() == model.axes.size()) problem.SetParameterBlockConstant(u->data());
  else if (!held.empty()) problem.SetManifold(u->data(), new ceres::SubsetManifold(static_cast<int>(u->size()), held));
  ceres::Solver::Options options;
  options.linear_solver_type = ceres::DENSE_QR;
  options.max_num_iterations = max_iterations;
  options.function_tolerance = 1e-5;
  options.parameter_tolerance = 1e-4;
  options.num_threads = 1;
  options.logging_type = ceres::SILENT;
  // With bounds, Ceres searches along each step (Armijo) before judging it. One trial, the step
  // itself, leaves the judging to the trust region: a search that shrinks a poor step by
  // hundreds ends the solve on Ceres' step and cost tolerances far from the minimum. Quadratic
  // interpolation needs the trial's cost alone; the default cubic asks a whole Jacobian there.
  options.max_num_line_search_step_size_iterations = 1;
  options.line_search_interpolation_type = ceres::QUADRATIC;
  options.callbacks = callbacks;
  // The callbacks (SolveMeeting, BestPoint) read each iteration's point from `u`.
  options.update_state_every_iteration = true;
  ceres::Solver::Summary summary;
  ceres::Solve(options, &problem, &summary);
  return summary;
}

}  // namespace

FitOutcome fitModel(const FitData& fit, const ModelSpec& model, const std::vector<std::vector<double>>& starts,
                    int max_iterations, double overtake_chi2) {
  ResidualEvaluator evaluator(fit, model);
  const std::vector<int> held = heldAxes(fit, model);
  // With two or more parameters a valley can hold one solve: a second from the second-best start.
  const std::size_t solves = model.axes.size() >= 2 ? 2 : 1;
  const std::vector<std::pair<double, std::vector<double>>> ranked =
      rankStarts(&evaluator, fit, model, held, starts, solves);
  FitOutcome best;
  if (ranked.empty()) {
    best.evaluations = evaluator.replays();
    best.message = "the model failed at every starting point";
    return best;
  }
  const std::size_t refined = std::min(ranked.size(), solves);
  best.ok = true;
  best.u = ranked[0].second;
  best.chi2 = ranked[0].first;
  // The solves run side by side, each with its own memory; the best is then taken in start
  // order, as one after the other.
  std::vector<std::unique_ptr<ResidualEvaluator>> solvers;
  for (std::size_t k = 0; k < refined; ++k) solvers.push_back(std::make_unique<ResidualEvaluator>(evaluator));
  std::vector<std::vector<double>> solved(refined);
  std::vector<ceres::Solver::Summary> summaries(refined);
  std::vector<std::unique_ptr<OvertakeCheck>> checks;
  for (std::size_t k = 0; k < refined; ++k)
    checks.push_back(std::make_unique<OvertakeCheck>(0.5 * overtake_chi2, max_iterations));
  // One thread per solve whatever fit.threads (each solve's replays use those): the meeting
  // needs them in step.
  SolveMeeting meeting(refined);
  std::vector<std::unique_ptr<BestPoint>> stood;
  for (std::size_t k = 0; k < refined; ++k) stood.push_back(std::make_unique<BestPoint>(&solved[k]));
  parallelFor(static_cast<int>(refined), static_cast<int>(refined), [&](int k) {
    solved[k] = ranked[k].second;
    MeetingCallback meet(&meeting, k, &solved[k]);
    std::vector<ceres::IterationCallback*> callbacks{stood[k].get(), checks[k].get()};
    if (refined > 1) callbacks.push_back(&meet);
    summaries[k] = solveFrom(solvers[k].get(), model, held, max_iterations, callbacks, &solved[k]);
    meeting.leave(k);
  });
  best.stopped = std::all_of(checks.begin(), checks.end(), [](const auto& c) { return c->stopped(); });
  for (std::size_t k = 0; k < refined; ++k) {
    const ceres::Solver::Summary& summary = summaries[k];
    // A solve that failed at its start reports final_cost -1: never a result.
    const bool usable = summary.IsSolutionUsable() && summary.final_cost >= 0.0 && std::isfinite(summary.final_cost);
    const double chi2 = usable ? 2.0 * summary.final_cost : 2.0 * stood[k]->cost();
    if (chi2 <= best.chi2) {
      best.u = usable ? solved[k] : stood[k]->point();
      best.chi2 = chi2;
      best.message = summary.BriefReport();
    }
  }
  best.evaluations = evaluator.replays();
  for (const auto& solver : solvers) best.evaluations += solver->replays();
  for (const auto& summary : summaries) best.iterations += static_cast<int>(summary.iterations.size()) - 1;
  return best;
}

bool fitCovariance(const FitData& fit, const ModelSpec& model, const std::vector<double>& u, Eigen::MatrixXd* cov) {
  ResidualEvaluator evaluator(fit, model);
  const ReplayCost cost(&evaluator);
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
