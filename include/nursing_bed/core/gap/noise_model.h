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

/// The readings' response to a change of the run's inputs: (replay of `changed` - `nominal`) /
/// `unit` per sample (0 where either is not finite); false (and zeros) when the replay fails.
bool replayResponse(const RunData& changed, const CellParams& params, const Replay& nominal, double unit,
                    std::vector<double>* dp, std::vector<double>* dh);

/// The model's sensitivity of the readings to a mass error made at the start: replays the run
/// with a little more gas injected in its first sample interval.
void massSensitivity(const RunData& run, const CellParams& params, const Replay& nominal, std::vector<double>* dp_dm,
                     std::vector<double>* dh_dm);

/// The start height's variance (0 for a run that starts flat) and the readings' sensitivity to it.
double startSensitivity(const RunData& run, const CellParams& params, const Replay& nominal, double noise_h_m,
                        std::vector<double>* dp_dh0, std::vector<double>* dh_dh0);

/// Variance per sample from not knowing when within an interval an interval-mean flow came.
void timingSpread(const RunData& run, const CellParams& params, const Replay& nominal, std::vector<double>* var_p,
                  std::vector<double>* var_h);

/// One run prepared for the fits: its samples at about `sample_hz`, their noise floor and the
/// Cholesky factor of their correlation. Throws std::invalid_argument if the nominal replay fails.
FitData::Run prepareFitRun(const RunData& run, const std::vector<double>& measured_flow, const RunNoise& noise,
                           const CellParams& params, double sample_hz);

}  // namespace gap
}  // namespace nursing_bed
