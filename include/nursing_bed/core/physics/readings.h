// What a cell's sensors report at one instant (ROS-free), in SI units: the model's simulated
// sensors, the hardware's readings handed to the observer, what the control side publishes.
#pragma once

#include <limits>

namespace nursing_bed {

/// One reading per signal; NaN where the reading is absent (no such sensor, a failed one).
struct Readings {
  double gauge_pressure_pa = std::numeric_limits<double>::quiet_NaN();  ///< cell pressure above ambient
  double height_m = std::numeric_limits<double>::quiet_NaN();           ///< plate height
  double inflow_kg_s = std::numeric_limits<double>::quiet_NaN();        ///< flow meter at the inlet
  double gas_temperature_k = std::numeric_limits<double>::quiet_NaN();  ///< gas temperature
};

}  // namespace nursing_bed
