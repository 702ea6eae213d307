// The bus cycles a driver keeps for a read that comes late.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>

#include "nursing_bed/core/hardware/bus_sample_ring.h"

namespace nb = nursing_bed;
using Clock = nb::BusSampleRing::Clock;

namespace {
Clock::time_point at(double s) {
  return Clock::time_point{} + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(s));
}
}  // namespace

TEST(BusSampleRing, HandsOutTheCyclesOfARequestedIntervalWithTheOpeningsOverEach) {
  nb::BusSampleRing ring(100);
  // Every 5 ms from 10.000 s; the inlet open from 10.010 to 10.020 s.
  for (int k = 0; k <= 8; ++k) {
    const double t = 10.0 + 0.005 * k;
    ring.push(at(t), 100.0 * k, std::clamp(t - 10.01, 0.0, 0.01), 0.0);
  }
  // A read at 10.041 s (caller's clock 3.041 s) after one at 10.002 s, when 0 s of on-time had passed.
  const auto s = ring.between(at(10.002), 0.0, 0.0, at(10.041), 3.041);
  ASSERT_EQ(s.size(), 8u) << "the cycles of 10.005 to 10.040 s";
  EXPECT_NEAR(s.front().stamp_s, 3.005, 1e-9);
  EXPECT_NEAR(s.front().span_s, 0.003, 1e-9) << "from the previous read";
  EXPECT_NEAR(s.back().stamp_s, 3.040, 1e-9);
  EXPECT_DOUBLE_EQ(s[3].gauge_pressure_pa, 400.0);
  double inlet_s = 0.0;
  for (const nb::BusSample& c : s) inlet_s += c.inlet * c.span_s;
  EXPECT_NEAR(inlet_s, 0.01, 1e-9);
  EXPECT_NEAR(s[2].inlet, 1.0, 1e-9) << "10.010-10.015 s: open";
  EXPECT_NEAR(s[5].inlet, 0.0, 1e-9) << "10.025-10.030 s: shut";
}

TEST(BusSampleRing, CyclesNoLongerKeptWidenTheFirstSpanAndKeepItsOnTime) {
  nb::BusSampleRing ring(3);
  for (int k = 0; k <= 8; ++k) ring.push(at(0.005 * k), 0.0, 0.0025 * k, 0.0);
  const auto s = ring.between(at(0.0), 0.0, 0.0, at(0.04), 0.04);
  ASSERT_EQ(s.size(), 3u);
  EXPECT_NEAR(s.front().span_s, 0.03, 1e-9) << "back to the interval's start";
  EXPECT_NEAR(s.front().inlet, 0.5, 1e-9);
}
