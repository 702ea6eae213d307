// A period that came late, replayed from the driver's bus samples (ROS-free): the valves acted
// all through it, so its gas is counted at the pressures of the cycles it spanned, as the
// periods the loop missed would have counted it, instead of at its end's reading.
#pragma once

#include <vector>

#include "nursing_bed/core/hardware/cell_hardware.h"

namespace nursing_bed {

/// One step of a replayed period: the readings as a period ending at `end_s` would have had them.
struct ReplayStep {
  CellReadings readings;
  double end_s = 0.0;  ///< on the caller's clock [s]
  double dt_s = 0.0;   ///< the step's length [s]
};

/// The steps of the period from `from_s` to `now_s` that `r.bus_samples` cover: samples merged
/// into steps of at least `step_s` [s], each with its last sample's pressure and the mean driven
/// openings over it, then the rest of the period with the read's own readings; each valve's
/// openings scaled so that their on-time is the read's mean over the period. Empty (replay nothing) when there are no samples, when the samples
/// leave a gap longer than `max_gap_s` [s] (the bus missed cycles), or where a height sensor
/// or flow meter measures what the count would be needed for.
std::vector<ReplayStep> busSampleSteps(const CellReadings& r, double from_s, double now_s, double step_s,
                                       double max_gap_s);

}  // namespace nursing_bed
