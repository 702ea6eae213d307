// The low-pressure / leak alarm of the bed's cells (ROS-free): a reporting cell held more than
// an error below the target it was sent, for longer than a duration, raises an alarm until it
// comes back within the error. Times are seconds on the caller's clock.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "nursing_bed/core/bed/cell_health.h"

namespace nursing_bed {

class LeakWatch {
 public:
  /// `cells` cells, the alarm after `duration_s` [s] more than `error_m` [m] below the target.
  LeakWatch(std::size_t cells, double error_m, double duration_s);

  /// Watches `cell` at `now_s`: its reported `height_m` against the `target_m` it was sent (NaN:
  /// none). A `silent` cell (dead or never reported) is not watched. Returns the alarm text
  /// while the alarm stands, else "".
  std::string update(const BedCell& cell, bool silent, double height_m, double target_m, double now_s);
  /// New thresholds (both > 0, checked by the caller); a cell already below its target keeps
  /// the time it went below.
  void setThresholds(double error_m, double duration_s) {
    error_m_ = error_m;
    duration_s_ = duration_s;
  }

 private:
  std::vector<double> below_since_s_;  ///< by cell id; NaN: not below
  double error_m_, duration_s_;
};

}  // namespace nursing_bed
