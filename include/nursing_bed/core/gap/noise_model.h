// The noise floor of the gap diagnosis (doc/gap_diagnosis.md, "Noise model"): what a run's
// residuals may be, given its sensors' noise, the replay's accuracy, the flow meter's noise that
// the replay integrates into a random walk of the gas mass, the start height's noise and the
// timing of interval-mean flows.
#pragma once

#include <vector>

#include "nursing_bed/core/gap/fit_model.h"

namespace nursing_bed {
namespace gap {

/// A run's sensor noise as measured (estimateNoise of each signal).
struct RunNoise {
  double p_pa = 0.0, h_m = 0.0;
};

RunNoise runNoise(const RunData& run);

/// The readings' response to a change of the run's inputs (or of how its interval means are
/// shaped): (replay of `changed` - `nominal`) / `unit` per sample (0 where either is not
/// finite); false (and zeros) when the replay fails.
bool replayResponse(const RunData& changed, const CellParams& params, const Replay& nominal, double unit,
                    std::vector<double>* dp, std::vector<double>* dh, IntervalShape shape = IntervalShape::kSpread);

/// The model's sensitivity of the readings to a mass error made at the start: replays the run
/// with a little more gas injected in its first sample interval.
void massSensitivity(const RunData& run, const CellParams& params, const Replay& nominal, std::vector<double>* dp_dm,
                     std::vector<double>* dh_dm);

/// An error shared by a run's samples, seen through the model: the readings move by (p[i], h[i])
/// times one random number of variance `variance` (0: no such error).
struct ErrorMode {
  std::vector<double> p, h;
  double variance = 0.0;
};

/// The start height's error (no mode for a run that starts flat).
ErrorMode startMode(const RunData& run, const CellParams& params, const Replay& nominal, double noise_h_m);

/// What not knowing when and how within an interval an interval-mean flow came does to the
/// readings: white variances per sample (the aliased ringing after valve pulses) and the lasting
/// offsets it leaves (modes, one per pulse placement).
struct TimingSpread {
  std::vector<double> var_p, var_h;
  std::vector<ErrorMode> modes;
};
TimingSpread timingSpread(const RunData& run, const CellParams& params, const Replay& nominal);

/// One run prepared for the fits: its samples at about `sample_hz`, their noise floor and the
/// Cholesky factor of their correlation. Throws std::invalid_argument if the nominal replay fails.
FitData::Run prepareFitRun(const RunData& run, const std::vector<double>& measured_flow, const RunNoise& noise,
                           const CellParams& params, double sample_hz);

}  // namespace gap
}  // namespace nursing_bed
