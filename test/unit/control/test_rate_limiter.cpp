// The rate limiter every cell target passes through: per-position rate, slope-angle rate, shape
// kept, NaN handling, bad limits refused.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "nursing_bed/core/control/rate_limiter.h"

namespace nb = nursing_bed;

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

TEST(RateLimiter, EveryPositionMovesAtMostItsRateAndTheShapeIsKept) {
  nb::RateLimits limits;
  limits.max_rate_per_s = 0.02;
  const nb::RateLimiter limiter(limits, 3);
  const std::vector<double> from{0.10, 0.10, 0.10}, to{0.00, 0.15, 0.10};
  const std::vector<double> out = limiter.step(from, to, 0.1);
  // The largest change (0.1 m) is cut to 2 mm; the others by the same factor (0.02).
  EXPECT_NEAR(out[0], 0.098, 1e-12);
  EXPECT_NEAR(out[1], 0.101, 1e-12);
  EXPECT_NEAR(out[2], 0.10, 1e-12);
  // A small change is not slowed.
  const std::vector<double> near = limiter.step(from, {0.101, 0.099, 0.10}, 0.1);
  EXPECT_NEAR(near[0], 0.101, 1e-12);
  EXPECT_NEAR(near[1], 0.099, 1e-12);
}

TEST(RateLimiter, RepeatedStepsReachTheTargetAtTheRate) {
  nb::RateLimits limits;
  limits.max_rate_per_s = 0.02;
  const nb::RateLimiter limiter(limits, 2);
  std::vector<double> x{0.0, 0.05}, target{0.10, 0.10};
  int steps = 0;
  while (x != target && steps < 1000) {
    x = limiter.step(x, target, 0.1);
    ++steps;
  }
  EXPECT_EQ(steps, 50);  // 0.1 m at 2 mm per step
}

// Slope of two positions 0.8 m apart: s = (x1 - x0) / 0.8.
nb::RateLimits slopeLimits(double deg_per_s) {
  nb::RateLimits limits;
  limits.max_rate_per_s = 10.0;  // not the binding limit here
  limits.slope_weights = {-1.0 / 0.8, 1.0 / 0.8};
  limits.max_angle_rate_rad_s = deg_per_s * M_PI / 180.0;
  return limits;
}

TEST(RateLimiter, TheSlopeAngleChangesAtMostItsRate) {
  const nb::RateLimiter limiter(slopeLimits(1.0), 2);
  // From a 20 deg tilt to flat in one go: the angle may change by 0.1 deg in 0.1 s.
  const double t20 = std::tan(20.0 * M_PI / 180.0) * 0.8;
  std::vector<double> x{0.10 - 0.5 * t20, 0.10 + 0.5 * t20};
  const std::vector<double> flat{0.10, 0.10};
  const double a0 = limiter.angle(x) * 180.0 / M_PI;
  EXPECT_NEAR(a0, 20.0, 1e-9);
  std::vector<double> next = limiter.step(x, flat, 0.1);
  EXPECT_NEAR(limiter.angle(next) * 180.0 / M_PI, 19.9, 1e-9);
  // To the other side: the same rate, through zero, 400 steps of 0.1 s.
  int steps = 0;
  const std::vector<double> other{x[1], x[0]};
  double worst = 0.0;
  while (x != other && steps < 1000) {
    next = limiter.step(x, other, 0.1);
    worst = std::max(worst, std::fabs(limiter.angle(next) - limiter.angle(x)) * 180.0 / M_PI / 0.1);
    x = next;
    ++steps;
  }
  EXPECT_LE(worst, 1.0 + 1e-9);
  EXPECT_EQ(steps, 400);
}

TEST(RateLimiter, NaNMeansNoTargetOrNothingToLimitAgainst) {
  const nb::RateLimiter limiter(slopeLimits(1.0), 2);
  const std::vector<double> out = limiter.step({kNaN, 0.10}, {0.05, kNaN}, 0.1);
  EXPECT_EQ(out[0], 0.05);          // nothing known before: the target
  EXPECT_TRUE(std::isnan(out[1]));  // no target
  EXPECT_EQ(limiter.allowedFraction({0.1, 0.1}, {0.1, 0.1}, 0.1), 1.0);
  EXPECT_EQ(limiter.allowedFraction({0.1, 0.1}, {0.2, 0.1}, 0.0), 0.0);  // no time, no motion
}

TEST(RateLimiter, BadLimitsAreRefusedByName) {
  nb::RateLimits limits;
  limits.max_rate_per_s = 0.0;
  EXPECT_THROW(nb::RateLimiter(limits, 1), std::invalid_argument);
  limits = nb::RateLimits{};
  limits.slope_weights = {1.0};
  try {
    nb::RateLimiter limiter(limits, 3);
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("1 slope weights for 3 positions"), std::string::npos) << e.what();
  }
  limits.slope_weights = {kNaN, 0.0, 0.0};
  EXPECT_THROW(nb::RateLimiter(limits, 3), std::invalid_argument);
  const nb::RateLimiter ok(nb::RateLimits{}, 2);
  EXPECT_THROW(ok.step({0.0}, {0.0}, 0.1), std::invalid_argument);
}

TEST(RateLimiter, ScalarLimit) {
  EXPECT_NEAR(nb::limitRate(0.0, 0.1, 0.02, 0.5), 0.01, 1e-12);
  EXPECT_NEAR(nb::limitRate(0.1, 0.0, 0.02, 0.5), 0.09, 1e-12);
  EXPECT_NEAR(nb::limitRate(0.1, 0.105, 0.02, 0.5), 0.105, 1e-12);
  EXPECT_EQ(nb::limitRate(kNaN, 0.07, 0.02, 0.5), 0.07);
  EXPECT_TRUE(std::isnan(nb::limitRate(0.07, kNaN, 0.02, 0.5)));
}

}  // namespace
