// A whole-breath statistic for slow drifts on cyclic runs (a ventilated lung): the gas balance of
// every whole cycle, the metered gas less the change of what the calibrated cell holds between
// the cycle's two ends (each read at the same point of the cycle, the foot of the setpoint's
// rise), over the cycle's length. A constant error of the metered flow (a meter's offset) or a
// steady loss of gas leaves every cycle out of balance by the same rate, which the whitened
// likelihood (whose meter-noise term is itself a random walk of the volume) discounts. Mass
// conservation alone: no replay's form error enters it. ROS-free
// (doc/gap_real_recordings.md, "The meter's offset").
#pragma once

#include <cmath>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "nursing_bed/core/gap/diagnosis_stages.h"
#include "nursing_bed/core/gap/run_data.h"
#include "nursing_bed/core/physics/cell_structure.h"

namespace nursing_bed {
namespace gap {

/// The gas [kg] a cell holds at rest at a gauge pressure under a load: its chamber at the
/// structure's equilibrium and its airway's circuit, both at the ambient temperature.
class CellContent {
 public:
  CellContent(const CellParams& params, double load_n);
  /// NaN where no equilibrium holds the load at that pressure (the plate on the bed).
  double massKg(double gauge_pressure_pa) const;
  /// d massKg / dp by central differences [kg/Pa] (NaN where massKg() is).
  double slopeKgPa(double gauge_pressure_pa) const;

 private:
  CellParams params_;
  std::shared_ptr<const CellStructure> structure_;
  double load_n_;
};

/// One whole cycle's rate [kg/s] (metered gas, content change or their balance) over its length.
struct CycleRate {
  double t_s = 0.0;         ///< the cycle's end, from the run's first sample [s]
  double duration_s = 0.0;  ///< [s]
  double rate_kg_s = 0.0;
};

/// The median cycle length of the runs [s] (cycleStarts(), a start within `min_cycle_s` of the
/// one before dropped: a run cut on a cycle edge starts a sample before it); NaN when no run has
/// two cycle starts.
double medianCyclePeriod(const std::vector<const RunData*>& runs, double min_cycle_s);

/// Each whole cycle's change of content, (M(p_end) - M(p_start)) / length, with the pressures
/// `p_pa` (the run's readings or a replay's) at its two ends: the foot of each setpoint rise (the
/// last sample before it climbs), the run's first sample for its first cycle, its last sample for
/// its last when that cycle is `period_s` long within 10 % (NaN: the run's own median cycle). A
/// cycle with an end of no finite pressure or content is left out. Throws std::invalid_argument
/// when `p_pa` is not as long as the run.
std::vector<CycleRate> contentRates(const RunData& run, const std::vector<double>& p_pa, const CellContent& content,
                                    double period_s = NAN);

/// Each whole cycle's balance: the metered gas over it (trapezoids of mdot_in_kg_s) less the
/// change of content at the measured pressures, over its length (cycles as contentRates(); one
/// with a missing flow sample left out).
std::vector<CycleRate> cycleBalances(const RunData& run, const CellContent& content, double period_s = NAN);

/// The mean rate over the cycles of several runs and its standard error.
struct BalanceMean {
  double mean_kg_s = NAN;
  double se_kg_s = NAN;
  int points = 0;
  bool ok() const { return points >= 1 && std::isfinite(mean_kg_s) && std::isfinite(se_kg_s); }
  /// The mean stands out of its scatter by more than z standard errors (either sign).
  bool significant(double z) const { return ok() && std::fabs(mean_kg_s) > z * se_kg_s; }
};

/// The mean of every cycle's rate; its standard error from their scatter (n - 1 degrees of
/// freedom), or with a single cycle from `scatter_kg_s` (another set's scatter); floored at
/// `floor_kg_s` (the sensors' noise over one cycle) so identical cycles prove nothing. Not ok()
/// without a cycle, or with one and no scatter given.
BalanceMean meanBalance(const std::vector<std::vector<CycleRate>>& runs, double floor_kg_s, double scatter_kg_s = NAN);
/// The cycles' scatter (standard deviation) behind `mean` (NaN with fewer than 2 cycles).
double cycleScatter(const std::vector<std::vector<CycleRate>>& runs);

/// What the whole-breath rule decided (nameDriftAboveFloor()).
struct DriftNaming {
  int winner = -1;                       ///< index into the scored candidates; -1: none
  double period_s = NAN;                 ///< the runs' median cycle (NaN: not cyclic)
  std::map<std::string, double> params;  ///< the winner's parameters, its drift parameter rescaled
  std::vector<std::string> reasons;
  BalanceMean fit_before, fit_after;    ///< the calibrated model's and the named model's, fit runs
  BalanceMean held_before, held_after;  ///< the same on the withheld runs
};

/// The whole-breath rule for a recording above its model-form floor on cyclic runs: where the
/// calibrated cell's cycles are out of balance on the fit runs (z = 3), the first single
/// candidate in BIC order (lowering it) with one parameter away from off that moves the balance
/// towards zero is rescaled, its parameter moved from off in proportion, so that the balance
/// vanishes (it is linear in a small flow error; a candidate's share is the change of content of
/// its replay against the calibrated model's, cycle by cycle). It is named when the rescaled
/// model is plausible, leaves the fit runs' balance within 2 standard errors and under a quarter
/// of the calibrated one's, and removes `options.floor_removed` of the withheld runs' balance,
/// which must stand out in the same direction (one-sided, z = 1.645: it confirms the fit runs'
/// finding). `baseline` is the calibration the candidates were compared with.
DriftNaming nameDriftAboveFloor(const PreparedRuns& prepared, const CellParams& params,
                                const std::map<std::string, double>& baseline,
                                const std::vector<ScoredCandidate>& scored, const DiagnosisOptions& options);

}  // namespace gap
}  // namespace nursing_bed
