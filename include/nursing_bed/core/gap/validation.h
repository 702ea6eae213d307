// The validation statement of the gap diagnosis, in the manner of ASME V&V 20: per signal,
// phase and load, the comparison error E = S - D of the nominal model and its validation
// uncertainty u_val from the data (sensor noise), the replay's numerics and the inputs.
// ROS-free (doc/gap_diagnosis.md, "Where it lies").
#pragma once

#include <string>
#include <vector>

#include "nursing_bed/core/gap/diagnosis_stages.h"

namespace nursing_bed {
namespace gap {

/// The rows for `replays` (one per run of `prepared`, e.g. the nominal model's) with the noise
/// model's floor at each used sample; by signal, then phase (deploy, pressurize, hold, vent),
/// then load.
std::vector<ValidationRow> validationTable(const PreparedRuns& prepared, const NoiseModel& noise,
                                           const std::vector<Replay>& replays);

/// "within" (|E| RMS at most u_val), or how many u_val the comparison error is.
std::string validationWords(const ValidationRow& row);

}  // namespace gap
}  // namespace nursing_bed
