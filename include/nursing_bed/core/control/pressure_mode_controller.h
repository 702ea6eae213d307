// Pressure setpoint mode of one cell (ROS-free): how therapy mattresses are run. A proportional
// valve law on the measured gauge pressure with a deadband.
#pragma once

#include <limits>
#include <string>

#include "nursing_bed/core/io/status.h"
#include "nursing_bed/core/physics/valve_openings.h"

namespace nursing_bed {

struct PressureModeParams {
  double band_pa = 1000.0;     ///< pressure error at which a valve opens fully [Pa]
  double tolerance_pa = 50.0;  ///< deadband: both valves shut within it [Pa]
  /// Success when valid, else an error with every problem found, separated by "; ".
  Status validate() const;
};

class PressureModeController {
 public:
  /// Throws std::invalid_argument naming what is wrong in `params`.
  explicit PressureModeController(const PressureModeParams& params = PressureModeParams{});
  const PressureModeParams& params() const { return params_; }

  /// Holds `gauge_pressure_pa` from now on (the caller checks its range).
  void setSetpoint(double gauge_pressure_pa) { setpoint_pa_ = gauge_pressure_pa; }
  void clear() { setpoint_pa_ = std::numeric_limits<double>::quiet_NaN(); }
  bool active() const { return setpoint_pa_ == setpoint_pa_; }
  /// Gauge pressure setpoint [Pa] (NaN when none).
  double setpoint() const { return setpoint_pa_; }
  /// The valves for the measured `gauge_pressure_pa`: the inlet below the setpoint, the vent
  /// above, in proportion to the error beyond the deadband (full at band_pa).
  ValveOpenings update(double gauge_pressure_pa) const;

 private:
  PressureModeParams params_;
  double setpoint_pa_ = std::numeric_limits<double>::quiet_NaN();
};

}  // namespace nursing_bed
