// The observer's flat-cell test (ROS-free): a cell with its inlet shut whose mean pressure stays
// that low for reanchor_time_s is flat, and its gas can be re-anchored.
#pragma once

#include "nursing_bed/core/observer/observer_inputs.h"

namespace nursing_bed {

/**
 * A plate cannot rest lifted below the plate alone's pressure, so a mean below half of it for
 * reanchor_time_s with the inlet shut is a flat cell, vented or sealed. Not while the inlet
 * passes gas (a fill from flat starts below that pressure), nor while venting into a vacuum.
 * The pressure is averaged over a third of the re-anchor time: a lightly loaded plate's vent
 * holds a few tens of Pa, as large as the reading's noise and ADC step. A vent that opens or
 * shuts rings a light plate, whose pressure dips to flat and below while it stands lifted: the
 * test starts afresh once the plate has settled after each vent edge. A bus slower than the
 * observer's step leaves periods without a new sample: they pause the test, and each sample
 * counts for the time since the last one up to kSampleCreditPeriods periods (one sample
 * repeated by a lossy link is one reading, not a flat cell).
 */
class ReanchorDetector {
 public:
  /// Most periods one sample stands for (here and in the cell's consistency monitor): a bus at
  /// a third of the step's rate still feeds the tests at their pace; a longer silence counts
  /// as this many.
  static constexpr double kSampleCreditPeriods = 3.0;

  /// `flat_pressure_pa`: |mean gauge pressure| under which the cell is flat; `period_s`: the
  /// observer's step.
  ReanchorDetector(double reanchor_time_s, double period_s, double flat_pressure_pa);
  double flatPressure() const { return flat_pressure_pa_; }
  /// Forgets the test under way and any expectFlat.
  void reset();
  /// A period without a reading (the link lost, a sensor fault): the test starts again. A
  /// period without a new sample is not passed to update() at all.
  void interrupt() { flat_for_s_ = -1.0; }
  /// Until `until_s` a mean below ambient counts as flat too (the cell has vented and keeps
  /// its valves shut to be tested).
  void expectFlatUntil(double until_s) { sub_ambient_flat_until_s_ = until_s; }
  /// One reading at `now_s` under the inputs acting: true when the cell is found flat, with the
  /// mean pressure to anchor it at.
  bool update(double now_s, const ObserverInputs& applied, double gauge_pressure_pa, double* mean_pa);

 private:
  double reanchor_time_s_, period_s_, flat_pressure_pa_;
  double flat_for_s_ = -1.0;                ///< time the test has run on samples (-1: none under way) [s]
  double last_sample_s_ = -1.0;             ///< the last sample's time [s]
  double mean_pa_ = 0.0;                    ///< the measured pressure averaged while it runs
  double sub_ambient_flat_until_s_ = -1.0;  ///< see expectFlatUntil
  bool venting_ = false;                    ///< the vent acting at the last reading was open
  double settled_from_s_ = -1.0;            ///< the plate has settled after the last vent edge from then
};

}  // namespace nursing_bed
