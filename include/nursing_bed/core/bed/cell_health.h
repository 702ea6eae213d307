// Health of the bed's cells as the bed supervisor sees them (ROS-free): each cell's last state,
// which cells are dead (silent past a timeout, judged only once the start-up is over) or faulty
// (a sensor or model fault), and each cell's condition for diagnostics. Times
// are seconds on the caller's clock, simulated or wall.
#pragma once

#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "nursing_bed/core/control/airbag_cell.h"

namespace nursing_bed {

/// One cell of the bed as the supervisor knows it (from the bed's description).
struct BedCell {
  std::uint32_t id = 0;       ///< row * cols + col; cells are kept by id (cells[id].id == id)
  std::string name;           ///< e.g. "airbag_3_4", for messages
  std::string link_name;      ///< the cell's top-plate link, for messages
  double min_height_m = 0.0;  ///< lowest height the cell takes [m]
  double max_height_m = 0.0;  ///< highest height the cell takes [m]
};

/// What the supervisor keeps of one cell's last state.
struct CellSnapshot {
  static constexpr double kNone = std::numeric_limits<double>::quiet_NaN();
  std::uint32_t id = 0;
  double height_m = kNone;            ///< reported height [m]
  double height_sd_m = kNone;         ///< its standard deviation [m]
  std::uint32_t faults = kFaultNone;  ///< AirbagFault bits
  double gauge_pressure_pa = kNone;   ///< for messages [Pa]
  double external_load_n = kNone;     ///< for messages [N]
  double seen_s = kNone;              ///< when the state arrived [s]; NaN: never
  bool unverified = false;            ///< its estimated height is not proven
};

/// How serious a condition is (a cell's or the bed's, on diagnostics; an event's in the log).
enum class Severity { kOk, kWarn, kError };

/// One cell on diagnostics: error when not reporting, warn with its fault names, else ok.
struct CellReport {
  Severity severity = Severity::kOk;
  std::string message;  ///< "ok", "faults: sensor ...", "no state for 0.8 s", "no state received"
};

class CellHealthWatcher {
 public:
  /// `cells` by id; a cell is dead when silent for more than `timeout_s`. No cell is judged
  /// until the start-up is over: 2 s after every cell first reports at once (cells still being
  /// loaded stall the ones loaded before them, and the last ones stall a moment after their
  /// first state), or `startup_grace_s` after `started_s`, whichever is first; silences count
  /// from then.
  CellHealthWatcher(std::vector<BedCell> cells, double timeout_s, double startup_grace_s, double started_s);

  /// Keeps a cell's state (and the longest wait between two of its states); false, and nothing
  /// changes, for an id that is not a cell.
  bool record(const CellSnapshot& state);
  /// Updates the dead and faulty flags at `now_s`; describes each cell that newly failed.
  std::vector<std::string> watch(double now_s);

  const std::vector<BedCell>& cells() const { return cells_; }
  const CellSnapshot& state(std::uint32_t id) const { return states_.at(id); }
  /// A state of the cell has arrived.
  bool reported(std::uint32_t id) const;
  /// Its last state is no older than the timeout at `now_s`.
  bool reporting(std::uint32_t id, double now_s) const;
  bool dead(std::uint32_t id) const { return dead_.at(id); }
  bool faulty(std::uint32_t id) const { return faulty_.at(id); }
  std::vector<std::uint32_t> deadCells() const;
  std::vector<std::uint32_t> faultyCells() const;
  /// Reporting cells whose estimated height is not proven (CellSnapshot::unverified).
  std::vector<std::uint32_t> unverifiedCells() const;
  /// The reported heights by cell id (NaN where none arrived) [m].
  std::vector<double> heights() const;
  /// Mean over the cells neither dead nor faulty of the height each is held at: `held_m[id]`
  /// where finite (the target it was sent), else its reported height; nullopt when there is
  /// none [m].
  std::optional<double> healthyMeanHeight(const std::vector<double>& held_m) const;
  /// The cell's condition at `now_s` for diagnostics.
  CellReport report(std::uint32_t id, double now_s) const;
  /// The longest wait between two states of one cell since resetLargestGap() [s].
  double largestGapS() const { return largest_gap_s_; }
  void resetLargestGap() { largest_gap_s_ = 0.0; }
  /// A new silence after which a cell is dead (> 0, checked by the caller) [s]; the next
  /// watch() applies it.
  void setTimeout(double timeout_s) { timeout_s_ = timeout_s; }
  /// The start-up is over: cells are judged (see the constructor).
  bool judging() const { return std::isfinite(judged_from_s_); }

 private:
  std::vector<BedCell> cells_;
  std::vector<CellSnapshot> states_;
  std::vector<bool> dead_, faulty_;
  double timeout_s_, startup_grace_s_, started_s_;
  double judged_from_s_ = std::numeric_limits<double>::quiet_NaN();  ///< when the start-up ended
  double largest_gap_s_ = 0.0;
};

/// The fault bits that make a cell faulty for the bed (it is levelled around it). A lost
/// hardware link is not one: the cell holds its gas and resumes the plan when the link returns,
/// while the bed raises an alarm (BedSupervisor).
constexpr std::uint32_t kFaultsThatFailACell = kFaultSensor | kFaultModel | kFaultInconsistent;

/// The names of the fault bits set in `faults`, each after a space (" sensor overpressure").
std::string faultNames(std::uint32_t faults);

}  // namespace nursing_bed
