#include "nursing_bed/core/hardware/bus_sample_ring.h"

#include <algorithm>

namespace nursing_bed {

BusSampleRing::BusSampleRing(std::size_t capacity) : capacity_(std::max<std::size_t>(1, capacity)) {}

void BusSampleRing::push(Clock::time_point t, double gauge_pressure_pa, double inlet_on_s, double vent_on_s) {
  if (cycles_.size() == capacity_) cycles_.pop_front();
  cycles_.push_back(Cycle{t, gauge_pressure_pa, {inlet_on_s, vent_on_s}});
}

std::vector<BusSample> BusSampleRing::between(Clock::time_point from, double inlet_from_s, double vent_from_s,
                                              Clock::time_point to, double to_caller_s) const {
  std::vector<BusSample> out;
  Clock::time_point last = from;
  double on_s[2] = {inlet_from_s, vent_from_s};
  // The cycles are in time order: start at the first after `from` (a read comes every period,
  // the ring holds a second of cycles).
  const auto first = std::upper_bound(cycles_.begin(), cycles_.end(), from,
                                      [](Clock::time_point t, const Cycle& c) { return t < c.t; });
  for (auto it = first; it != cycles_.end() && it->t <= to; ++it) {
    const Cycle& c = *it;
    const double span_s = std::chrono::duration<double>(c.t - last).count();
    if (!(span_s > 0.0)) continue;  // the same instant as the one before: nothing to average
    BusSample s;
    s.stamp_s = to_caller_s - std::chrono::duration<double>(to - c.t).count();
    s.span_s = span_s;
    s.gauge_pressure_pa = c.gauge_pressure_pa;
    s.inlet = std::clamp((c.on_s[0] - on_s[0]) / span_s, 0.0, 1.0);
    s.vent = std::clamp((c.on_s[1] - on_s[1]) / span_s, 0.0, 1.0);
    out.push_back(s);
    last = c.t;
    on_s[0] = c.on_s[0];
    on_s[1] = c.on_s[1];
  }
  return out;
}

}  // namespace nursing_bed
