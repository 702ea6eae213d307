// New controller tuning and safety thresholds for a running cell (dynamic reconfigure), through
// the cell's setters (AirbagCell::setControllerParams, setSafetyParams): taken whole or refused
// whole.
#pragma once

#include <string>

#include "nursing_bed/core/control/airbag_cell.h"

namespace nursing_bed {

/// Gives `cell` `controller` and `safety` and returns "", or returns why not and changes
/// nothing. The command timeout keeps the cell's current setting (its watchdog is armed by the
/// node, setCommandTimeout). The setters check each part against the other's running values
/// (max_pressure_pa below the relief pressure): the part that loosens that bound goes first, so
/// a pair valid together is never refused half-way; the first part is put back when the second
/// is refused.
std::string applyTuning(AirbagCell& cell, const HeightControllerParams& controller, AirbagSafetyParams safety);

}  // namespace nursing_bed
