// The last bus cycles of one cell as its driver read them (ROS-free): each cycle's pressure and
// the valves' total on-time up to it, handed to a read as BusSamples (cell_hardware.h) so that
// a cell whose period came late counts its gas at the pressures it passed through.
#pragma once

#include <chrono>
#include <cstddef>
#include <deque>
#include <vector>

#include "nursing_bed/core/hardware/cell_hardware.h"

namespace nursing_bed {

class BusSampleRing {
 public:
  using Clock = std::chrono::steady_clock;

  /// Keeps the last `capacity` cycles (at least one).
  explicit BusSampleRing(std::size_t capacity);

  /// The cycle read `gauge_pressure_pa` [Pa] at `t`; the valves' total on-time up to then was
  /// `inlet_on_s` and `vent_on_s` [s] (totals never decrease).
  void push(Clock::time_point t, double gauge_pressure_pa, double inlet_on_s, double vent_on_s);

  /// The cycles after `from` up to `to`, oldest first, each with the mean openings over the
  /// interval since the one before (the first: since `from`, when the totals were
  /// `inlet_from_s` and `vent_from_s`), stamped on the caller's clock, on which `to` is
  /// `to_caller_s`. Cycles no longer kept are missing: the first kept one's span then reaches
  /// back to `from` (its openings still exact as a mean).
  std::vector<BusSample> between(Clock::time_point from, double inlet_from_s, double vent_from_s, Clock::time_point to,
                                 double to_caller_s) const;

 private:
  struct Cycle {
    Clock::time_point t;
    double gauge_pressure_pa;
    double on_s[2];  ///< total inlet, vent on-time up to t [s]
  };
  std::size_t capacity_;
  std::deque<Cycle> cycles_;
};

}  // namespace nursing_bed
