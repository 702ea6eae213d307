#include "nursing_bed/core/gap/noise_model.h"

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

}  // namespace

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

}  // namespace gap
}  // namespace nursing_bed
