// The valve commands written over the last dead time, not yet acting (ROS-free): the gas in
// flight that a Smith predictor counts.
#pragma once

#include <deque>

#include "nursing_bed/core/physics/valve_openings.h"

namespace nursing_bed {

class CommandsInFlight {
 public:
  /// The valves act this late after a command [s]; throws std::invalid_argument outside
  /// [0, 1] s. Forgets the commands kept.
  void setDeadTime(double dead_time_s);
  double deadTime() const { return dead_time_s_; }
  /// `cmd` written for the next `dt_s`: kept while it is within the last dead time.
  void note(const ValveOpenings& cmd, double dt_s);
  bool empty() const { return commands_.empty(); }
  /// Full-opening seconds of each valve still to act [s].
  void openSeconds(double* inlet_s, double* vent_s) const;

 private:
  struct Held {
    ValveOpenings valves;
    double held_s;
  };
  double dead_time_s_ = 0.0;
  std::deque<Held> commands_;  ///< oldest first, covering at most the dead time
};

}  // namespace nursing_bed
