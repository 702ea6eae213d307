// The airbag cell's safety layer (ROS-free): sensor range, command watchdog and pressure relief,
// whatever the mode. It judges; AirbagCell sets its faults and mode from the verdicts.
#pragma once

#include <string>

namespace nursing_bed {

struct AirbagSafetyParams {
  double relief_pressure_pa = 35000.0;       ///< gauge pressure never exceeded: inlet shut, vent open [Pa]
  double relief_margin_pa = 500.0;           ///< act this far below it, ahead of the next period's rise [Pa]
  double command_timeout_s = 0.0;            ///< hold and flag when no command/heartbeat for this long; 0 = off [s]
  double sensor_pressure_min_pa = -50000.0;  ///< readings outside [min, max] are a sensor fault [Pa]
  double sensor_pressure_max_pa = 150000.0;
  double sensor_height_min_m = -0.02;  ///< [m]
  double sensor_height_max_m = 0.40;   ///< [m]
  /// Consecutive control periods a reading must stay out of range to be a sensor fault [-]
  /// (meanwhile the valves hold the gas).
  int sensor_fault_periods = 10;
  /// Largest external load a cell accepts [N]; larger, negative or non-finite loads are refused
  /// (a 100 mm face at the relief pressure carries about 300 N; default 1000 N).
  double max_load_n = 1000.0;
  /// Fastest change of a cell's height target outside CPR: the bed manager limits every target
  /// it sends with it, the airbag node ramps direct set_height calls with it [m/s] (the core
  /// cell takes targets as given).
  double max_height_rate_m_s = 0.02;
  /// Empty when valid, else every problem found, separated by "; " (a string, not a Status, while
  /// AirbagCellParams::validate() gathers it with other string checks).
  std::string validate() const;
};

/// What the sensor range check makes of one period's readings.
enum class SensorVerdict {
  kOk,     ///< in range
  kHold,   ///< out of range: hold the gas (valves shut), not yet a fault
  kFault,  ///< out of range for sensor_fault_periods: a sensor fault
};

/// What the relief makes of one period's pressure.
enum class ReliefVerdict {
  kVent,   ///< at the relief pressure (or about to be): inlet shut, vent open, overpressure flagged
  kClear,  ///< well below it: an overpressure flag clears
  kKeep,   ///< in between: the flag stays as it is
};

class SafetyLayer {
 public:
  /// Throws std::invalid_argument naming what is wrong in `params`.
  explicit SafetyLayer(const AirbagSafetyParams& params);
  const AirbagSafetyParams& params() const { return params_; }
  /// Replaces the thresholds (e.g. from dynamic reconfigure) when valid and returns ""; else
  /// returns why not and changes nothing. The counters and the last pressure are kept.
  std::string setParams(const AirbagSafetyParams& params);

  /// The relief's rise is measured from this pressure next period [Pa].
  void setLastPressure(double gauge_pressure_pa) { last_pressure_pa_ = gauge_pressure_pa; }

  /// Sensor range: one period's readings (NaN counts as out of range). A reading out of range
  /// holds the gas at once; it is a fault once it persists for sensor_fault_periods (a single
  /// out-of-range sample is what a plate lifting off a flat cell gives for a few ms).
  SensorVerdict checkReadings(double gauge_pressure_pa, double height_m);

  /// Command watchdog: a command or heartbeat at `now_s`.
  void noteCommand(double now_s) { last_command_s_ = now_s; }
  /// No command or heartbeat for longer than command_timeout_s (never when it is 0).
  bool commandTimedOut(double now_s) const;

  /// Relief, whatever the mode: act before the next period's rise could cross the relief
  /// pressure. Remembers `gauge_pressure_pa` for the next period's rise.
  ReliefVerdict relief(double gauge_pressure_pa);

  /// Empty when `load_n` is a load the cell accepts (finite, 0..max_load_n), else why not.
  std::string checkLoad(double load_n) const;

 private:
  AirbagSafetyParams params_;
  int bad_readings_ = 0;           ///< consecutive periods with an out-of-range reading
  double last_command_s_ = 0.0;    ///< the last command or heartbeat [s]
  double last_pressure_pa_ = 0.0;  ///< the last period's pressure [Pa]
};

}  // namespace nursing_bed
