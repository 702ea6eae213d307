// What the observer takes each period (ROS-free): the inputs acting on the gas and the readings
// at the period's end. SI units: Pa (gauge), m, kg/s.
#pragma once

#include <limits>

namespace nursing_bed {

/// Inputs over one period (what was commanded, not what was measured).
struct ObserverInputs {
  double inlet_opening = 0.0;              ///< inlet valve opening 0..1 (mean over the period)
  double vent_opening = 0.0;               ///< vent valve opening 0..1
  double vent_back_pressure_pa = 0.0;      ///< gauge pressure at the vent outlet (CPR vacuum < 0)
  /// Regulator setting, gauge; NaN: the cell parameters' setting.
  double supply_pressure_pa = std::numeric_limits<double>::quiet_NaN();
  /// The regulator outlet's gauge pressure where the hardware measures it (NaN: not measured;
  /// the observer's regulator then follows the setting, from the setting at reset).
  double measured_supply_pa = std::numeric_limits<double>::quiet_NaN();
};

/// Readings at the end of the period; NaN where the hardware has none (or it failed).
struct ObserverReadings {
  double gauge_pressure_pa = std::numeric_limits<double>::quiet_NaN();
  double height_m = std::numeric_limits<double>::quiet_NaN();
  double inflow_kg_s = std::numeric_limits<double>::quiet_NaN();
};

}  // namespace nursing_bed
