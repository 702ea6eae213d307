// Faults the rig emulator injects into its own cells and terminals (ROS-free; test and bench
// use only, never a real bed): a restart with the cells emptied or kept, dropped or delayed
// Modbus replies, a stuck valve, a frozen or offset pressure sensor, a sudden leak. Each is
// selected per cell and reproducible by the emulator's fault seed.
#pragma once

#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include "nursing_bed/core/io/status.h"
#include "nursing_bed/core/physics/valve_openings.h"

namespace nursing_bed {

enum class RigFaultKind : std::uint8_t {
  kClear,         ///< every fault of the cells (and their terminals' replies) removed
  kStuckOpen,     ///< `valve` passes fully whatever is commanded
  kStuckClosed,   ///< `valve` passes nothing whatever is commanded
  kFrozenSensor,  ///< the pressure register keeps its last value
  kSensorOffset,  ///< the pressure reads `value` Pa more than the cell's
  kLeak,          ///< a hole of `value` m^2 (effective area) to ambient
  kDropReplies,   ///< the cells' terminals leave each request unanswered with probability `value`
  kDelayReplies,  ///< ... answer it `delay_s` late with probability `value`
  kRestart,       ///< the terminals fall silent for `value` s; the cells emptied unless keep_gas
};

/// One request, from the emulator's parameters or its service.
struct RigFaultRequest {
  std::string fault;                    ///< a name of rigFaultNames()
  std::vector<std::uint32_t> cell_ids;  ///< the cells; empty: random_cells of them, or every cell
  int random_cells = 0;                 ///< with no cell_ids: this many cells drawn by the fault seed
  std::string valve;                    ///< stuck_open, stuck_closed: "inlet" or "vent"
  double value = 0.0;                   ///< offset [Pa], leak area [m^2], probability [-], silence [s]
  double delay_s = 0.0;                 ///< delay_replies: how late [s]
  bool keep_gas = false;                ///< restart: the cells keep their gas (else emptied flat)
};

/// The faults acting on one emulated cell.
struct CellFaults {
  int stuck_inlet = -1;  ///< -1 none, 0 stuck closed, 1 stuck open
  int stuck_vent = -1;
  bool frozen = false;
  double offset_pa = 0.0;
  double leak_area_m2 = 0.0;

  /// The valve openings the cell's valves pass for the commanded ones; a leak is an extra vent
  /// opening of its area over the vent's (`vent_area_m2`).
  ValveOpenings apply(const ValveOpenings& commanded, double vent_area_m2) const;
};

/// "clear, stuck_open, ..." for messages.
std::string rigFaultNames();
/// Checks `request` against the cells served (`served_ids`) and the vent's area: success with
/// its kind in `*kind`, else an error naming each problem.
Status checkRigFault(const RigFaultRequest& request, const std::vector<std::uint32_t>& served_ids, double vent_area_m2,
                     RigFaultKind* kind);
/// The cells a checked request applies to (random_cells drawn from `rng`).
std::vector<std::uint32_t> rigFaultCells(const RigFaultRequest& request, const std::vector<std::uint32_t>& served_ids,
                                         std::mt19937* rng);
/// Sets (or for kClear removes) the per-cell part of a checked request of `kind` on `faults`.
void applyCellFault(RigFaultKind kind, const RigFaultRequest& request, CellFaults* faults);

}  // namespace nursing_bed
