// The observer's valve dead time (ROS-free): a delay line in time, not in periods, over the
// inputs the control side reports each period.
#pragma once

#include <deque>

#include "nursing_bed/core/observer/observer_inputs.h"

namespace nursing_bed {

/**
 * Each input is kept with the time it was held, and the openings acting over a period are the
 * mean of those held over the same span dead_time_s earlier. Shifted by a count of periods
 * instead, a late tick's long span would be charged with the opening of a short one (or the
 * reverse): on a loaded machine, with valves chattering, that drifts the gas inventory.
 */
class ValveDelayLine {
 public:
  explicit ValveDelayLine(double dead_time_s = 0.0) : dead_time_s_(dead_time_s) {}
  double deadTime() const { return dead_time_s_; }
  /// Forgets the inputs held: the valves were shut before the next one.
  void reset();
  /// `in` held for the next `dt_s`; returns the inputs acting over it (`in` with the openings
  /// of dead_time_s earlier; shut before the first input).
  ObserverInputs delayed(const ObserverInputs& in, double dt_s);

 private:
  struct Held {
    ObserverInputs inputs;
    double held_s;
  };
  double dead_time_s_;
  std::deque<Held> pending_;  ///< inputs with the time they were held, oldest first
  double pending_s_ = 0.0;    ///< time the queue covers [s]
};

}  // namespace nursing_bed
