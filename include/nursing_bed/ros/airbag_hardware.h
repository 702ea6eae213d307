// The airbag node's hardware and observer parameters, and loading its cell hardware with
// pluginlib (plugins: hardware_plugins.xml; interface: core/hardware/cell_hardware.h). Read from
// the node's private namespace over the defaults namespace (hardware/..., observer/...), so a
// launch file sets them once for every cell. Keys: doc/real_bed.md.
#pragma once

#include <ros/node_handle.h>

#include <string>

#include "nursing_bed/core/control/airbag_cell.h"
#include "nursing_bed/core/io/status.h"

namespace nursing_bed {

struct AirbagHardwareParams {
  /// hardware/plugin: pluginlib name of the CellHardware; default the simulated cell.
  std::string plugin = "nursing_bed/SimulatedHardware";
  std::string register_map;     ///< hardware/register_map: YAML path (modbus_tcp)
  CellObserverParams observer;  ///< observer/<key>: tuning (observerParamFields)
  /// observer/resume_vent_s, observer/reanchor_below_m: the cell's checks of the observer's gas
  /// (gasVerifierParamFields).
  GasVerifierParams gas_check;
  /// observer/monitor_<key>: the consistency monitor's thresholds (consistencyMonitorParamFields).
  ConsistencyMonitorParams monitor;
  /// observer/cell_params: YAML of the observer's cell model (a calibrated set, e.g. from
  /// `gap calibrate`); empty: the cell's own parameters.
  std::string observer_cell_params;
  /// observer/effects: effects the observer's model carries (a `gap diagnose` verdict, in the
  /// ~effects syntax); empty: the nominal model.
  std::string observer_effects;
  bool observer_force = false;  ///< observer/force: use the estimate even with a height sensor

  bool simulated() const { return plugin == "nursing_bed/SimulatedHardware"; }
  /// Success, or every problem found.
  Status validate() const;
  static AirbagHardwareParams load(const ros::NodeHandle& private_nh, const std::string& defaults_ns);
};

/// Creates the plugin and configures it; throws std::runtime_error naming the plugin and what
/// is wrong (unknown plugin, bad register map, ...).
CellHardwarePtr loadCellHardware(const AirbagHardwareParams& params, const HardwareConfig& config);

/// The observer setup: its tuning, its model (observer_cell_params or `cell`) and effects.
AirbagObserverSetup observerSetup(const AirbagHardwareParams& params, const CellParams& cell, std::uint32_t seed);

}  // namespace nursing_bed
