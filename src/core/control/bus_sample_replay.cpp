#include "nursing_bed/core/control/bus_sample_replay.h"

#include <algorithm>

namespace nursing_bed {

namespace {

/// Whether the samples tile the period without a gap longer than `max_gap_s`.
bool covers(const std::vector<BusSample>& samples, double from_s, double now_s, double max_gap_s) {
  double last_s = from_s;
  for (const BusSample& s : samples) {
    if (s.stamp_s - last_s > max_gap_s) return false;
    last_s = std::max(last_s, s.stamp_s);
  }
  return now_s - last_s <= max_gap_s;
}

/// A step ending at the last of `samples` [first, last], from `start_s`.
ReplayStep stepOf(const CellReadings& r, const BusSample* first, const BusSample* last, double start_s) {
  double span_s = 0.0, inlet_s = 0.0, vent_s = 0.0;
  for (const BusSample* s = first; s <= last; ++s) {
    span_s += s->span_s;
    inlet_s += s->inlet * s->span_s;
    vent_s += s->vent * s->span_s;
  }
  ReplayStep step;
  step.end_s = last->stamp_s;
  step.dt_s = last->stamp_s - start_s;
  step.readings.gauge_pressure_pa = {last->gauge_pressure_pa, last->stamp_s};
  step.readings.supply_pressure_pa = r.supply_pressure_pa;
  step.readings.gas_temperature_k = r.gas_temperature_k;
  step.readings.inlet_driven = {span_s > 0.0 ? inlet_s / span_s : 0.0, last->stamp_s};
  step.readings.vent_driven = {span_s > 0.0 ? vent_s / span_s : 0.0, last->stamp_s};
  return step;
}

/// Scales one valve's openings over `steps` so that their on-time is the read's, `total_s`:
/// the cycles say when in the period the valve was open, the read's mean how long (the
/// driver's account, which carries what a caller's period shorter than the real one cannot
/// hold to the next read, so that each pulse is counted once). What a full opening cannot
/// take goes to the steps with room, in proportion to it.
void handOut(std::vector<ReplayStep>* steps, StampedReading CellReadings::*valve, double total_s) {
  double shape_s = 0.0, span_s = 0.0;
  for (const ReplayStep& s : *steps) {
    shape_s += (s.readings.*valve).value * s.dt_s;
    span_s += s.dt_s;
  }
  double counted_s = 0.0, room_s = 0.0;
  for (ReplayStep& s : *steps) {
    double& opening = (s.readings.*valve).value;
    opening = std::clamp(shape_s > 0.0 ? opening * total_s / shape_s : total_s / span_s, 0.0, 1.0);
    counted_s += opening * s.dt_s;
    room_s += (1.0 - opening) * s.dt_s;
  }
  const double share = room_s > 0.0 ? std::clamp((total_s - counted_s) / room_s, 0.0, 1.0) : 0.0;
  for (ReplayStep& s : *steps) (s.readings.*valve).value += share * (1.0 - (s.readings.*valve).value);
}

}  // namespace

std::vector<ReplayStep> busSampleSteps(const CellReadings& r, double from_s, double now_s, double step_s,
                                       double max_gap_s) {
  const std::vector<BusSample>& samples = r.bus_samples;
  if (samples.empty() || r.height_m.present() || r.inflow_kg_s.present() || !r.inlet_driven.present() ||
      !r.vent_driven.present() || !covers(samples, from_s, now_s, max_gap_s))
    return {};
  std::vector<ReplayStep> steps;
  double start_s = from_s;
  std::size_t first = 0;
  for (std::size_t i = 0; i < samples.size(); ++i) {
    if (samples[i].stamp_s - start_s < step_s - 1e-9 && i + 1 < samples.size()) continue;  // ns: clock rounding
    if (!(samples[i].stamp_s > start_s)) continue;
    steps.push_back(stepOf(r, &samples[first], &samples[i], start_s));
    start_s = samples[i].stamp_s;
    first = i + 1;
  }
  // The rest, to the read: its own readings (the last sample again), the valves as they were.
  if (now_s - start_s > 1e-6) {
    ReplayStep rest{r, now_s, now_s - start_s};
    rest.readings.bus_samples.clear();
    rest.readings.inlet_driven.value = samples.back().inlet;
    rest.readings.vent_driven.value = samples.back().vent;
    steps.push_back(rest);
  }
  const double period_s = now_s - from_s;
  handOut(&steps, &CellReadings::inlet_driven, r.inlet_driven.value * period_s);
  handOut(&steps, &CellReadings::vent_driven, r.vent_driven.value * period_s);
  return steps;
}

}  // namespace nursing_bed
