#include "nursing_bed/core/gap/noise_model.h"

#include "nursing_bed/core/gap/calibration.h"

#include <Eigen/Cholesky>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace nursing_bed {
namespace gap {
namespace {

/// Replay accuracy in the noise floor: this share of the signal's measured range (the replay of
/// noise-free nominal data comes back within about 2e-3 of the range).
constexpr double kModelAccuracyShare = 5.0e-4;
/// Largest number of samples of one run in the fits.
constexpr std::size_t kMaxFitSamples = 600;
/// The timing spread's ringing is its envelope over this many samples either side, its trend
/// the running median over kTrendSamples either side (timingSpread).
constexpr std::size_t kTimingEnvelopeSamples = 2;
constexpr std::size_t kTrendSamples = 5;

}  // namespace

/// The readings' response to a change of the run's inputs: (replay of `changed` - `nominal`) /
/// `unit` per sample (0 where either is not finite); false (and zeros) when the replay fails.
bool replayResponse(const RunData& changed, const CellParams& params, const Replay& nominal, double unit,
                    std::vector<double>* dp, std::vector<double>* dh, IntervalShape shape) {
  dp->assign(nominal.p_gauge_pa.size(), 0.0);
  dh->assign(nominal.h_m.size(), 0.0);
  const Replay rep = replayRun(changed, params, {}, 0, shape);
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
    if (std::isfinite(q0) && std::isfinite(q1))
      injected += 0.5 * std::max(0.0, q0 + q1) * (run.t_s[i] - run.t_s[i - 1]);
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
/// (initialHeight), whose noise stays in the replay's gas for the whole run. The mode is the
/// readings' response to the start height (from a replay started one noise floor higher) with the
/// start height's variance (empty for a run that starts flat).
ErrorMode startMode(const RunData& run, const CellParams& params, const Replay& nominal, double noise_h_m) {
  ErrorMode mode;
  const InitialHeight h0 = initialHeight(run);
  if (h0.samples == 0 || !(h0.h_m > kLandedHeightM) || !(noise_h_m > 0.0)) return mode;
  RunData lifted = run;
  for (std::size_t i = 0; i < run.size() && run.t_s[i] <= run.t_s[0] + kInitialRestS; ++i) lifted.h_m[i] += noise_h_m;
  if (!replayResponse(lifted, params, nominal, noise_h_m, &mode.p, &mode.h)) return ErrorMode{};
  mode.variance = noise_h_m * noise_h_m / h0.samples;
  return mode;
}

RunNoise runNoise(const RunData& run) { return {estimateNoise(run.p_gauge_pa), estimateNoise(run.h_m)}; }

/// Running median of `r` over kTrendSamples samples either side.
std::vector<double> runningMedian(const std::vector<double>& r) {
  std::vector<double> out(r.size());
  std::vector<double> window;
  for (std::size_t i = 0; i < r.size(); ++i) {
    const std::size_t lo = i >= kTrendSamples ? i - kTrendSamples : 0, hi = std::min(r.size() - 1, i + kTrendSamples);
    window.assign(r.begin() + lo, r.begin() + hi + 1);
    std::nth_element(window.begin(), window.begin() + window.size() / 2, window.end());
    out[i] = window[window.size() / 2];
  }
  return out;
}

/// Largest |ring[j]| within kTimingEnvelopeSamples samples of each sample, squared.
std::vector<double> squaredEnvelope(const std::vector<double>& ring) {
  std::vector<double> out(ring.size(), 0.0);
  for (std::size_t i = 0; i < ring.size(); ++i) {
    const std::size_t lo = i >= kTimingEnvelopeSamples ? i - kTimingEnvelopeSamples : 0;
    const std::size_t hi = std::min(ring.size() - 1, i + kTimingEnvelopeSamples);
    for (std::size_t j = lo; j <= hi; ++j) out[i] = std::max(out[i], ring[j] * ring[j]);
  }
  return out;
}

/// Interval means say how much gas came in over an interval, not when or how within it: the
/// bed's on/off valves open for a few ms at a time, at the interval's start or its end. The
/// readings are uncertain by the replay's response to that: replays with every interval's gas
/// (and vent opening) as a pulse at the interval's start and at its end (IntervalShape); a
/// placement uniform in between has about a third of such a response's variance (a sixth per
/// extreme). Each response has two parts, treated differently:
/// - its trend (running median): gas the pulse timing moved for good. The adiabatic gas keeps
///   the work done on it, so a lift-off timed differently leaves an offset for the rest of the
///   run, one error shared by all later samples: an ErrorMode, correlated, not white.
/// - what rings around the trend: the plate rings on its gas spring after every pulse (the
///   lift-off, a slow controlled rise), faster than the samples, so the pulse timing changes the
///   aliased ringing's phase at each sample and one replay's difference may pass through zero
///   where the ringing is large. Its envelope is a white variance per sample.
/// Empty (zero variances, no modes) for instantaneous readings.
TimingSpread timingSpread(const RunData& run, const CellParams& params, const Replay& nominal) {
  const std::size_t n = run.size();
  TimingSpread spread;
  spread.var_p.assign(n, 0.0);
  spread.var_h.assign(n, 0.0);
  if (!run.flow_interval_means || n < 3) return spread;
  for (IntervalShape shape : {IntervalShape::kPulseAtStart, IntervalShape::kPulseAtEnd}) {
    ErrorMode response;
    if (!replayResponse(run, params, nominal, 1.0, &response.p, &response.h, shape)) continue;
    ErrorMode trend{runningMedian(response.p), runningMedian(response.h), 1.0 / 6.0};
    std::vector<double> ring_p(n), ring_h(n);
    for (std::size_t i = 0; i < n; ++i) {
      ring_p[i] = response.p[i] - trend.p[i];
      ring_h[i] = response.h[i] - trend.h[i];
    }
    const std::vector<double> env_p = squaredEnvelope(ring_p), env_h = squaredEnvelope(ring_h);
    for (std::size_t i = 0; i < n; ++i) {
      spread.var_p[i] += env_p[i] / 6.0;
      spread.var_h[i] += env_h[i] / 6.0;
    }
    spread.modes.push_back(std::move(trend));
  }
  return spread;
}

/// Cholesky factor of the covariance of the floor-scaled residuals [p0, h0, p1, h1, ...] of the
/// run's used samples: white noise on the diagonal, the mass walk,
/// Cov(e_a(t_j), e_b(t_l)) = g_a(t_j) g_b(t_l) Var_m(min(t_j, t_l)), and each shared error mode's
/// s_a(t_j) s_b(t_l) Var. Throws std::invalid_argument if it is not positive definite.
Eigen::MatrixXd correlationCholesky(const FitData::Run& r, const std::vector<double>& walk,
                                    const std::vector<double>& white_p, const std::vector<double>& white_h,
                                    const std::vector<double>& gain_p, const std::vector<double>& gain_h,
                                    const std::vector<ErrorMode>& modes) {
  const int m = static_cast<int>(r.index.size());
  // Per mode, its scaled sensitivities at the used samples, [p0, h0, p1, h1, ...].
  std::vector<Eigen::VectorXd> scaled;
  for (const ErrorMode& mode : modes) {
    if (mode.variance <= 0.0) continue;
    Eigen::VectorXd v(2 * m);
    for (int j = 0; j < m; ++j) {
      v[2 * j] = mode.p[r.index[j]] / r.sigma_p_pa[j] * std::sqrt(mode.variance);
      v[2 * j + 1] = r.has_height ? mode.h[r.index[j]] / r.sigma_h_m[j] * std::sqrt(mode.variance) : 0.0;
    }
    scaled.push_back(std::move(v));
  }
  Eigen::MatrixXd cov = Eigen::MatrixXd::Zero(2 * m, 2 * m);
  for (int j = 0; j < m; ++j)
    for (int l = 0; l <= j; ++l) {
      const double v = walk[l];  // l <= j: the earlier sample's walk variance
      const double gj[2] = {gain_p[j] / r.sigma_p_pa[j], gain_h[j] / r.sigma_h_m[j]};
      const double gl[2] = {gain_p[l] / r.sigma_p_pa[l], gain_h[l] / r.sigma_h_m[l]};
      for (int a = 0; a < 2; ++a)
        for (int b = 0; b < 2; ++b) {
          double c = gj[a] * gl[b] * v;
          if (j == l && a == b)
            c += (a == 0 ? white_p[j] / std::pow(r.sigma_p_pa[j], 2) : white_h[j] / std::pow(r.sigma_h_m[j], 2));
          cov(2 * j + a, 2 * l + b) = c;
          cov(2 * l + b, 2 * j + a) = c;
        }
    }
  for (const Eigen::VectorXd& v : scaled) cov.noalias() += v * v.transpose();
  Eigen::LLT<Eigen::MatrixXd> llt(cov);
  if (llt.info() != Eigen::Success)
    throw std::invalid_argument(r.data->name + ": the noise model is not positive definite");
  return llt.matrixL();
}

/// Noise floor of each used sample: sensor noise, the replay's accuracy, the flow meter's noise
/// integrated by the replay (a random walk of the gas mass, seen through the model's
/// sensitivity), the timing spread and the shared error modes.
FitData::Run prepareFitRun(const RunData& run, const std::vector<double>& measured_flow, const RunNoise& noise,
                           const CellParams& params, double sample_hz) {
  FitData::Run r;
  r.data = &run;
  r.has_height = !runHasNoHeight(run);
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
  // Errors shared by many samples: the start height and the timing's lasting offsets.
  const TimingSpread timing = timingSpread(run, params, nominal);
  std::vector<ErrorMode> modes = timing.modes;
  modes.push_back(startMode(run, params, nominal, noise.h_m));
  const std::vector<double> flow_noise = meterNoise(run, measured_flow, 25);
  double walk_var = 0.0;
  std::vector<double> walk, white_p, white_h, gain_p, gain_h;
  for (std::size_t i = 0; i < run.size(); ++i) {
    // Flow set to 0 where the inlet is closed (zeroClosedInletFlow) integrates no noise.
    if (i > 0 && run.mdot_in_kg_s[i] != 0.0)
      walk_var += std::pow(std::max(flow_noise[i], 0.0) * (run.t_s[i] - run.t_s[i - 1]), 2);
    if (i % stride != 0 || nominal.phases[i] == RunPhase::kLanded) continue;
    if (!std::isfinite(run.p_gauge_pa[i]) || (r.has_height && !std::isfinite(run.h_m[i]))) continue;
    r.index.push_back(i);
    walk.push_back(walk_var);
    white_p.push_back(std::pow(noise.p_pa, 2) + std::pow(kModelAccuracyShare * range.range_p_pa, 2) + timing.var_p[i]);
    // No height sensor: its slots are uncorrelated unit noise whose residual is 0.
    white_h.push_back(r.has_height ? std::pow(noise.h_m, 2) + std::pow(kModelAccuracyShare * range.range_h_m, 2) +
                                         timing.var_h[i]
                                   : 1.0);
    gain_p.push_back(dp_dm[i]);
    gain_h.push_back(r.has_height ? dh_dm[i] : 0.0);
    double input_p = dp_dm[i] * dp_dm[i] * walk_var, input_h = gain_h.back() * gain_h.back() * walk_var;
    for (const ErrorMode& mode : modes) {
      if (mode.variance <= 0.0) continue;
      input_p += mode.p[i] * mode.p[i] * mode.variance;
      if (r.has_height) input_h += mode.h[i] * mode.h[i] * mode.variance;
    }
    r.sigma_p_pa.push_back(std::sqrt(white_p.back() + input_p));
    r.sigma_h_m.push_back(std::sqrt(white_h.back() + input_h));
    r.var_data_p.push_back(std::pow(noise.p_pa, 2));
    r.var_num_p.push_back(white_p.back() - r.var_data_p.back());
    r.var_input_p.push_back(input_p);
    r.var_data_h.push_back(r.has_height ? std::pow(noise.h_m, 2) : 0.0);
    r.var_num_h.push_back(r.has_height ? white_h.back() - r.var_data_h.back() : 0.0);
    r.var_input_h.push_back(input_h);
  }
  r.correlation_cholesky = correlationCholesky(r, walk, white_p, white_h, gain_p, gain_h, modes);
  return r;
}

}  // namespace gap
}  // namespace nursing_bed
