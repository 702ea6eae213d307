#include "nursing_bed/core/observer/valve_delay_line.h"

#include <algorithm>

namespace nursing_bed {

void ValveDelayLine::reset() {
  pending_.clear();
  pending_s_ = 0.0;
}

ObserverInputs ValveDelayLine::delayed(const ObserverInputs& in, double dt) {
  const double dead = dead_time_s_;
  if (dead <= 0.0) return in;
  pending_.push_back({in, dt});
  pending_s_ += dt;
  // The queue covers [now - pending_s_, now]; the period acting now is [now - dead - dt, now - dead].
  while (!pending_.empty() && pending_s_ - pending_.front().held_s >= dead + dt) {
    pending_s_ -= pending_.front().held_s;
    pending_.pop_front();
  }
  ObserverInputs out = in;
  out.valves.inlet = out.valves.vent = 0.0;    // before the first command: shut
  const double from = pending_s_ - dead - dt;  // the acting span's start, from the queue's start
  double start = 0.0;
  for (const Held& h : pending_) {
    const double overlap = std::min(start + h.held_s, from + dt) - std::max(start, from);
    if (overlap > 0.0) {
      out.valves.inlet += h.inputs.valves.inlet * overlap / dt;
      out.valves.vent += h.inputs.valves.vent * overlap / dt;
      out.vent_back_pressure_pa = h.inputs.vent_back_pressure_pa;
    }
    start += h.held_s;
    if (start >= from + dt) break;
  }
  return out;
}

}  // namespace nursing_bed
