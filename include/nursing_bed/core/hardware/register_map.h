// The register map of a bed's Modbus TCP valve terminals: per terminal its address and timing,
// per cell its valve outputs (coils for on/off solenoid valves, holding registers for
// proportional ones) and analogue inputs (pressure always; height, inflow where fitted).
// Parsed from YAML (config/real_bed_register_map.yaml, every key commented) and validated: a
// bad map is refused at start with a message naming the entry.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "nursing_bed/core/io/status.h"

namespace nursing_bed {

/// One valve output. A coil is an on/off valve (pulse-width modulated over the control
/// period); a holding register a proportional valve (opening * full_scale).
struct ValveOutput {
  enum Kind { kNone, kCoil, kHoldingRegister };
  Kind kind = kNone;
  int address = -1;
  double full_scale = 1000.0;  ///< holding-register value of a fully open valve [-]
};

/// One analogue input register (16-bit unsigned count): value = count * scale + offset.
struct AnalogInput {
  int address = -1;     ///< input register; -1: not fitted
  double scale = 1.0;   ///< SI units per count
  double offset = 0.0;  ///< SI value at count 0
  bool present() const { return address >= 0; }
  double toValue(std::uint16_t count) const { return count * scale + offset; }
  /// The count that encodes `value` (rounded, clamped to 0..65535).
  std::uint16_t toCount(double value) const;
};

struct CellRegisters {
  std::uint32_t cell_id = 0;
  ValveOutput inlet, vent;
  AnalogInput pressure_pa, height_m, inflow_kg_s;
};

struct TerminalMap {
  std::string name;  ///< label in messages
  std::string host = "127.0.0.1";
  int port = 502;
  int unit_id = 1;
  double response_timeout_s = 0.05;  ///< a request unanswered this long fails (and is retried next cycle)
  /// The link goes down when no bus cycle has completed for this long (a closed connection:
  /// at once). Must exceed response_timeout_s + cycle_s, so that one unanswered request
  /// alone never takes the link down, and with them stay within 0.5 s, the time in which the
  /// cells of a silent terminal report a communication fault.
  double link_loss_after_s = 0.2;
  double reconnect_interval_s = 0.25;  ///< time between reconnection attempts
  /// The terminal's output watchdog: with no request for this long it shuts every output. Until
  /// then, over a lost link, the outputs hold their last written state (and pass gas).
  double watchdog_s = 0.1;
  double cycle_s = 0.005;      ///< bus cycle: one batched read and write of every cell
  double stale_after_s = 0.2;  ///< a reading older than this is a sensor fault
  /// SCHED_FIFO priority (1-99) of the bus thread serving this terminal, and of the rig
  /// emulator's server standing in for it (a terminal answers in deterministic time); 0: the
  /// normal scheduler. Refused by the system (no CAP_SYS_NICE), the thread runs normally and
  /// the cells' hardware says so (CellHardware::warning).
  int realtime_priority = 0;
  AnalogInput supply_pressure_pa;  ///< optional supply pressure input
  std::vector<CellRegisters> cells;
  std::string endpoint() const { return host + ":" + std::to_string(port) + " unit " + std::to_string(unit_id); }
};

struct RegisterMap {
  std::vector<TerminalMap> terminals;
  /// The terminal and slot serving `cell_id`; false when no terminal does.
  bool find(std::uint32_t cell_id, std::size_t* terminal, std::size_t* slot) const;
};

/// Success when the map serves cells 0..expected_cells-1 exactly once (expected_cells 0: any
/// set) with sane values and no address used twice, else every problem, naming the entry.
Status validateRegisterMap(const RegisterMap& map, std::uint32_t expected_cells);

/// Parses and validates; throws std::runtime_error naming `source` and the entry at fault.
RegisterMap parseRegisterMap(const std::string& yaml_text, const std::string& source, std::uint32_t expected_cells);
RegisterMap loadRegisterMap(const std::string& path, std::uint32_t expected_cells);

}  // namespace nursing_bed
