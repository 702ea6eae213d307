#include "nursing_bed/core/control/commands_in_flight.h"

#include <stdexcept>

namespace nursing_bed {

void CommandsInFlight::setDeadTime(double dead_time_s) {
  if (!(dead_time_s >= 0.0 && dead_time_s <= 1.0))
    throw std::invalid_argument("height controller: the valves' dead time must lie in [0, 1] s");
  dead_time_s_ = dead_time_s;
  commands_.clear();
}

void CommandsInFlight::note(const ValveOpenings& cmd, double dt_s) {
  if (dead_time_s_ <= 0.0 || !(dt_s > 0.0)) return;
  commands_.push_back({cmd, dt_s});
  double held_s = 0.0;
  for (const Held& c : commands_) held_s += c.held_s;
  // The oldest commands have begun to act: only the last dead time's are still in flight.
  while (!commands_.empty() && held_s - commands_.front().held_s >= dead_time_s_) {
    held_s -= commands_.front().held_s;
    commands_.pop_front();
  }
  if (!commands_.empty() && held_s > dead_time_s_) commands_.front().held_s -= held_s - dead_time_s_;
}

void CommandsInFlight::openSeconds(double* inlet_s, double* vent_s) const {
  *inlet_s = *vent_s = 0.0;
  for (const Held& c : commands_) {
    *inlet_s += c.valves.inlet * c.held_s;
    *vent_s += c.valves.vent * c.held_s;
  }
}

}  // namespace nursing_bed
