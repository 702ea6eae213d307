// What the observer takes each period (ROS-free): the inputs acting on the gas. The readings at
// the period's end are a Readings (NaN where the hardware has none or it failed).
// SI units: Pa (gauge), m, kg/s.
#pragma once

#include <limits>

#include "nursing_bed/core/physics/readings.h"
#include "nursing_bed/core/physics/valve_openings.h"

namespace nursing_bed {

/// Inputs over one period (what was commanded, not what was measured).
struct ObserverInputs {
  /// Inlet and vent openings 0..1, means over the period (vent_to_vacuum is not read: the vent
  /// outlet is vent_back_pressure_pa).
  ValveOpenings valves;
  double vent_back_pressure_pa = 0.0;  ///< gauge pressure at the vent outlet (CPR vacuum < 0)
  /// Regulator setting, gauge; NaN: the cell parameters' setting.
  double supply_pressure_pa = std::numeric_limits<double>::quiet_NaN();
  /// The regulator outlet's gauge pressure where the hardware measures it (NaN: not measured;
  /// the observer's regulator then follows the setting, from the setting at reset).
  double measured_supply_pa = std::numeric_limits<double>::quiet_NaN();
};

}  // namespace nursing_bed
