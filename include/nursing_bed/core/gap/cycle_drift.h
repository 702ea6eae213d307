// A whole-breath statistic for slow drifts on cyclic runs (a ventilated lung): the residual
// (measured less modelled pressure) at the end of every cycle, where the flow is near rest and
// the setpoint edges' ringing has died out, and its linear trend through the runs. A constant
// error of the metered flow (a meter's offset) or a steady loss of gas integrates into a volume
// error that grows by the same amount every cycle: a linear trend of the end-of-cycle residual,
// which the whitened likelihood (whose meter-noise term is itself a random walk of the volume)
// discounts. ROS-free (doc/gap_real_recordings.md, "The meter's offset").
#pragma once

#include <cmath>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "nursing_bed/core/gap/diagnosis_stages.h"
#include "nursing_bed/core/gap/run_data.h"

namespace nursing_bed {
namespace gap {

/// One end-of-cycle point: the time since the run's start [s] and the mean residual [Pa].
struct CyclePoint {
  double t_s = 0.0;
  double residual_pa = 0.0;
};

/// The median cycle length of the runs [s] (cycleStarts(), a start within `min_cycle_s` of the
/// one before dropped: a run cut on a cycle edge starts a sample before it); NaN when no run has
/// two cycle starts.
double medianCyclePeriod(const std::vector<const RunData*>& runs, double min_cycle_s);

/// The mean of measured less modelled pressure over the last `window_s` before each cycle's end:
/// every cycle start after the run's first (cycleStarts(), a start within `window_s` of the one
/// before dropped), and the run's end when its
/// last cycle is `period_s` long within 10 % (a run cut at cycle boundaries ends where the next
/// cycle starts; NaN: the run's own median cycle). Times from the run's first sample. Throws
/// std::invalid_argument when `modelled_p_pa` is not as long as the run or `window_s` is not
/// positive.
std::vector<CyclePoint> endOfCycleResiduals(const RunData& run, const std::vector<double>& modelled_p_pa,
                                            double window_s, double period_s = NAN);

/// The linear trend of end-of-cycle residuals through several runs.
struct CycleDrift {
  double slope_pa_s = NAN;    ///< pooled trend [Pa/s]
  double se_pa_s = NAN;       ///< its standard error (from the points' scatter about the line)
  double intercept_pa = NAN;  ///< the residual a cycle's end starts from (the model's form there)
  int points = 0;
  bool ok() const { return points >= 3 && std::isfinite(slope_pa_s) && std::isfinite(se_pa_s); }
  /// The trend stands out of its scatter by more than z standard errors.
  bool significant(double z) const { return ok() && std::fabs(slope_pa_s) > z * se_pa_s; }
};

/// Least squares r = a + b t over the runs' points with one intercept a for all of them: every
/// replay starts at the measured state, so a run's end-of-cycle residual is the model's error at
/// that point of the cycle (alike in every cycle) plus the drift since the run's start. The
/// standard error of b from the scatter about the line (n - 2 degrees of freedom; the scatter
/// floored at `floor_pa`, the pressure sensor's noise over a window, so exactly collinear points
/// do not make any slope significant). Not ok() with fewer than 3 points or no spread in time.
CycleDrift fitCycleDrift(const std::vector<std::vector<CyclePoint>>& runs, double floor_pa);

/// What the whole-breath rule decided (nameDriftAboveFloor()).
struct DriftNaming {
  int winner = -1;                       ///< index into the scored candidates; -1: none
  double period_s = NAN;                 ///< the runs' median cycle (NaN: not cyclic)
  std::map<std::string, double> params;  ///< the winner's parameters, its drift parameter rescaled
  std::vector<std::string> reasons;
  CycleDrift fit_before, fit_after;    ///< the baseline's and the named model's, fit runs
  CycleDrift held_before, held_after;  ///< the same on the withheld runs
};

/// The whole-breath rule for a recording above its model-form floor on cyclic runs: where the
/// calibrated model's end-of-cycle residual drifts significantly on the fit runs (z = 3), the
/// first single candidate in BIC order (lowering it) with one parameter away from off that
/// moves the drift towards zero is rescaled, its parameter moved from off in proportion, so that
/// the drift vanishes (the drift is linear in a small flow error). It is named when the rescaled
/// model is plausible, leaves the fit runs' drift within 2 standard errors and under a quarter of
/// the baseline's, and removes `options.floor_removed` of the withheld runs' drift, which must be
/// significant too (z = 2). `baseline` is the calibration the candidates were compared with.
DriftNaming nameDriftAboveFloor(const PreparedRuns& prepared, const CellParams& params,
                                const std::map<std::string, double>& baseline,
                                const std::vector<ScoredCandidate>& scored, const DiagnosisOptions& options);

}  // namespace gap
}  // namespace nursing_bed
