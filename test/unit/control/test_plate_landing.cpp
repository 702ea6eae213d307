// The landing's force law (PlateLanding) and the plate's tracked speed (PlateTracker).
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "nursing_bed/core/control/plate_landing.h"
#include "nursing_bed/core/control/plate_tracker.h"

namespace nb = nursing_bed;

namespace {
const nb::PlateMechanics kPlate{15.6, 15.6 / 9.81, 20.0};
}

TEST(PlateLanding, AsksForTheForceOfACriticallyDampedApproach) {
  nb::PlateLanding landing;
  EXPECT_FALSE(landing.force(0.005, {0.09, 0.0}, 0.10, kPlate, 40.0)) << "not started";
  landing.start();
  // 10 mm below the aim at rest: load plus m r^2 e.
  const auto below = landing.force(0.005, {0.09, 0.0}, 0.10, kPlate, 40.0);
  ASSERT_TRUE(below);
  EXPECT_NEAR(*below, 15.6 + kPlate.mass_kg * 1600.0 * 0.01, 1e-9);
  // Rising at 0.3 m/s 10 mm below: faster than the approach allows, so it brakes.
  const auto rising = landing.force(0.005, {0.09, 0.3}, 0.10, kPlate, 40.0);
  ASSERT_TRUE(rising);
  EXPECT_LT(*rising, 15.6);
  // The gas cannot pull: never below a twentieth of the load.
  const auto fast = landing.force(0.005, {0.099, 3.0}, 0.10, kPlate, 40.0);
  ASSERT_TRUE(fast);
  EXPECT_DOUBLE_EQ(*fast, 0.05 * 15.6);
}

TEST(PlateLanding, EndsOnceLandedOrTimedOut) {
  nb::PlateLanding landing;
  landing.start();
  EXPECT_TRUE(landing.force(0.005, {0.0996, 0.02}, 0.10, kPlate, 40.0)) << "within 0.5 mm but still moving";
  EXPECT_FALSE(landing.force(0.005, {0.0996, 0.005}, 0.10, kPlate, 40.0));
  EXPECT_FALSE(landing.active());
  landing.start();
  int periods = 0;
  while (landing.force(0.005, {0.05, 0.0}, 0.10, kPlate, 40.0)) ++periods;
  EXPECT_NEAR(periods, landing.timeout_s / 0.005, 1.0);
}

TEST(PlateTracker, FollowsTheModelsAccelerationWithoutLag) {
  nb::PlateTracker tracker;
  tracker.reset(0.02);
  const double a = 3.0, dt = 0.005;
  for (int i = 1; i <= 40; ++i) {
    const double t = i * dt;
    tracker.update(dt, 0.02 + 0.5 * a * t * t, a);
  }
  EXPECT_NEAR(tracker.state().velocity_m_s, a * 40 * dt, 1e-9);
  EXPECT_NEAR(tracker.state().height_m, 0.02 + 0.5 * a * 0.04, 1e-9);
}

TEST(PlateTracker, ItsSpeedNoiseIsWhatItSaysAndFarBelowTwoReadingsDifference) {
  nb::PlateTracker tracker;
  const double dt = 0.005, sd = 5e-4;
  std::mt19937 rng(3);
  std::normal_distribution<double> noise(0.0, sd);
  tracker.reset(0.1);
  double sum_sq = 0.0;
  int n = 0;
  for (int i = 0; i < 40000; ++i) {
    tracker.update(dt, 0.1 + noise(rng), 0.0);
    if (i > 200) sum_sq += tracker.state().velocity_m_s * tracker.state().velocity_m_s, ++n;
  }
  const double measured = std::sqrt(sum_sq / n);
  EXPECT_NEAR(measured, tracker.speedSd(sd, dt), 0.1 * tracker.speedSd(sd, dt));
  EXPECT_LT(tracker.speedSd(sd, dt), 0.2 * std::sqrt(2.0) * sd / dt);
}

TEST(PlateTracker, StartsAgainFromAReadingAfterABadPeriod) {
  nb::PlateTracker tracker;
  tracker.reset(0.05);
  tracker.update(0.005, 0.05, NAN);  // an unknown acceleration counts as none
  EXPECT_TRUE(std::isfinite(tracker.state().velocity_m_s));
  tracker.update(0.0, 0.07, 0.0);  // no time step: restart at the reading
  EXPECT_DOUBLE_EQ(tracker.state().height_m, 0.07);
  EXPECT_DOUBLE_EQ(tracker.state().velocity_m_s, 0.0);
}
