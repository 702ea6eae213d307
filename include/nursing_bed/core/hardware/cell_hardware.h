// The cell hardware boundary: what the control side (controller, safety, observer) reads from
// and writes to one airbag cell. The simulation is one implementation (the cell model and its
// sensors), a Modbus TCP valve terminal another; an EtherCAT or CAN driver is one more
// (doc/real_bed.md, "Writing a driver"). ROS-free: the ROS layer loads implementations with
// pluginlib (nursing_bed_hardware_plugins.xml), the way ros_control loads RobotHW plugins, and
// the core and its tests use them directly.
// SI units: Pa (gauge), m, kg/s, K, s. Stamps are on the caller's clock (seconds since start).
#pragma once

#include <cstdint>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "nursing_bed/core/physics/cell_model.h"
#include "nursing_bed/core/physics/readings.h"
#include "nursing_bed/core/physics/valve_openings.h"

namespace nursing_bed {

/// One reading with the time it was taken; NaN value and stamp when the hardware has none.
struct StampedReading {
  double value = std::numeric_limits<double>::quiet_NaN();
  double stamp_s = std::numeric_limits<double>::quiet_NaN();
  bool present() const { return value == value; }
};

/// Communication state of the cell's link (bus, terminal).
enum class LinkState : std::uint8_t { kOk = 0, kDown = 1 };

/// One bus cycle's reading of a cell's pressure, with the mean openings its valves were driven
/// at over the interval before it (from the previous sample, or the previous read). A driver
/// that samples faster than the cell's period hands these out, so that a period that came late
/// (a starved thread) can still count its gas at the pressures it passed through.
struct BusSample {
  double stamp_s = 0.0;            ///< when the pressure was read, on the caller's clock [s]
  double span_s = 0.0;             ///< the interval the openings are a mean over, ending at stamp_s [s]
  double gauge_pressure_pa = 0.0;  ///< cell gauge pressure [Pa]
  double inlet = 0.0, vent = 0.0;  ///< the valves' mean driven openings over span_s, [0, 1]
};

/// Everything the hardware reports for one cell. A reading the hardware lacks stays NaN;
/// pressure is always there while the link is up.
struct CellReadings {
  StampedReading gauge_pressure_pa;   ///< cell gauge pressure [Pa]
  StampedReading height_m;            ///< plate height [m], where a height sensor is fitted
  StampedReading inflow_kg_s;         ///< inlet mass flow [kg/s], where a flow meter is fitted
  StampedReading gas_temperature_k;   ///< gas temperature [K], where measured
  StampedReading supply_pressure_pa;  ///< supply (regulator outlet) gauge pressure [Pa], where measured
  /// The valve openings the driver applied since the previous read(), time-averaged (an on/off
  /// valve: the fraction of the interval its output was on), where it knows them; the interval
  /// is the caller's (read()'s now_s less the previous one's), so that the caller, integrating
  /// them over its periods, counts every pulse once. The command
  /// is a duty over the control period; the pulses that realise it are what passes the gas, at
  /// the pressure during each pulse, so an observer integrates these. While the link is down
  /// a driver may still know them: a terminal holds its outputs as last written until its own
  /// watchdog shuts them, so the gas kept flowing for that long (absent: taken as shut).
  StampedReading inlet_driven, vent_driven;
  /// The bus cycles since the previous read(), oldest first, where the driver samples between
  /// reads (empty otherwise). Their spans tile the interval from the previous read to the last
  /// sample; the caller's own interval is what inlet_driven / vent_driven are a mean over.
  std::vector<BusSample> bus_samples;
  LinkState link = LinkState::kOk;
  std::string link_error;  ///< why the link is down (empty while up)
  /// The device failed and was reset since the last read(): the cell is in its reset state
  /// (the simulated plant: its solve failed or left an invalid state and it was reset flat at
  /// rest, valves shut). A real driver may set it too (a terminal that rebooted, a cell found
  /// emptied). The control side answers with a fault (kFaultModel) and mode SAFE.
  bool device_reset = false;
};

/// The values of a driver's report, stamps and link state dropped: NaN where it has none.
inline Readings readingsOf(const CellReadings& r) {
  Readings out;
  out.gauge_pressure_pa = r.gauge_pressure_pa.value;
  out.height_m = r.height_m.value;
  out.inflow_kg_s = r.inflow_kg_s.value;
  out.gas_temperature_k = r.gas_temperature_k.value;
  return out;
}

/// Which readings the hardware has (fixed for its lifetime).
struct HardwareCapabilities {
  bool height = false;
  bool inflow = false;
  bool gas_temperature = false;
  bool supply_pressure = false;
  /// The vent line can be switched to a vacuum source (CPR). Without one, venting is to the
  /// atmosphere whatever ValveOpenings::vent_to_vacuum says, and the observer must model it so.
  bool vent_vacuum = false;
};

/// Everything an implementation may need to configure itself; each takes what it uses.
struct HardwareConfig {
  std::uint32_t cell_id = 0;        ///< row * cols + col
  double control_period_s = 0.005;  ///< the control side's period [s]
  // The simulated plant (simulated hardware, and the rig emulator's cells).
  CellParams cell;
  std::vector<CellEffectPtr> effects;  ///< hidden in the simulated plant
  double load_n = 0.6;                 ///< initial load on the plate [N]
  double initial_height_m = 0.0;       ///< start at rest at this height [m]
  double cpr_vacuum_pa = -5000.0;      ///< gauge pressure at the vent while vent_to_vacuum [Pa]
  double pressure_noise_pa = 0.0;      ///< sd of the simulated pressure sensor [Pa]
  double height_noise_m = 0.0;         ///< sd of the simulated height sensor [m]
  std::uint32_t noise_seed = 1;
  // Real hardware.
  std::string register_map_path;  ///< modbus_tcp: the register map YAML
  std::uint32_t bed_cells = 0;    ///< cells in the bed: the map must serve each (0: not checked)
};

class CellHardware {
 public:
  virtual ~CellHardware() = default;
  /// Sets the hardware up for one cell; throws std::runtime_error naming what is wrong. Called
  /// once, before any read() or write() (pluginlib needs a default constructor).
  virtual void configure(const HardwareConfig& config) = 0;
  virtual HardwareCapabilities capabilities() const = 0;
  /// The latest readings at `now_s` (a simulation advances its plant to `now_s` first). Real
  /// hardware is read at `now_s` = the time of the call: its driven openings are averaged over
  /// the interval since the previous call, which the caller integrates over its own period.
  virtual CellReadings read(double now_s) = 0;
  /// Commands the valves from `now_s` on (until the next write()).
  virtual void write(const ValveOpenings& valves, double now_s) = 0;
  /// Short description for logs ("simulated", "modbus_tcp 127.0.0.1:15020 unit 1, coils 3/63").
  virtual std::string describe() const = 0;
  /// A condition the hardware works under that degrades it, for the node to log once (empty:
  /// none), e.g. a bus thread refused its real-time priority.
  virtual std::string warning() const { return {}; }
};

using CellHardwarePtr = std::shared_ptr<CellHardware>;

}  // namespace nursing_bed
