// What the bed supervisor sends its cells (ROS-free): a plan's targets passed through the rate
// limiter, as a height setpoint per cell, or a vent to every cell while the plan vents. A
// command goes out when its value changes, and again every `resend_s` so that a restarted cell
// gets its target back and the cells' command watchdog is fed. Times are seconds on the
// caller's clock.
#pragma once

#include <cstdint>
#include <vector>

#include "nursing_bed/core/bed/cell_health.h"
#include "nursing_bed/core/bed/posture_plans.h"
#include "nursing_bed/core/control/rate_limiter.h"

namespace nursing_bed {

/// One command to one cell.
struct CellCommand {
  std::uint32_t id = 0;
  bool vent = false;                      ///< open the vent (CPR) instead of a setpoint
  double height_m = CellSnapshot::kNone;  ///< the height setpoint [m] (NaN with vent)
};

class CellCommander {
 public:
  /// `cells` by id; `limits` for that many cells (throws std::invalid_argument when invalid).
  CellCommander(std::vector<BedCell> cells, RateLimits limits, double resend_s);

  /// The commands for `targets` at `now_s`, `dt_s` after the previous call. Heights pass the
  /// rate limiter; where nothing was sent yet the ramp starts at the cell's `measured_m` (by
  /// cell id, NaN: unknown), within its range. Venting clears the ramp.
  std::vector<CellCommand> command(const PlanTargets& targets, const std::vector<double>& measured_m, double dt_s,
                                   double now_s);
  /// The next command() sends every target at once (a new plan).
  void resendAll();
  /// The last setpoint sent to the cell (NaN: none, or vented since) [m].
  double sentHeight(std::uint32_t id) const { return sent_height_m_.at(id); }
  /// The last setpoint sent to each cell, by cell id (NaN: none, or vented since) [m].
  const std::vector<double>& sentHeights() const { return sent_height_m_; }

 private:
  std::vector<double> limit(const std::vector<double>& wanted, const std::vector<double>& measured_m, double dt_s);
  /// `targets` as limited; `wanted_m` the plan's own targets by cell id.
  std::vector<CellCommand> send(const PlanTargets& targets, const std::vector<double>& wanted_m, double now_s);

  std::vector<BedCell> cells_;
  RateLimiter limiter_;
  std::vector<double> limited_m_;      ///< rate-limited targets, by cell id (NaN: none)
  std::vector<double> sent_height_m_;  ///< last setpoint sent, by cell id (NaN: none)
  std::vector<double> sent_at_s_;      ///< when a command last went to the cell (NaN: never, or due)
  double resend_s_;
};

}  // namespace nursing_bed
