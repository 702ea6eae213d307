// A rate limiter for many positions at once (ROS-free), in the spirit of ros_controllers'
// speed_limiter: every change of a cell's height target passes through it, so no plan, plan
// switch, direct call or fault response moves a cell, or tilts the patient, faster than allowed.
#pragma once

#include <limits>
#include <string>
#include <vector>

#include "nursing_bed/core/io/status.h"

namespace nursing_bed {

struct RateLimits {
  /// Fastest change of any one position [unit/s] (cell heights: [m/s]).
  double max_rate_per_s = 0.02;
  /// Weights w of a linear functional s = sum w_i x_i whose angle atan(s) is limited too (the
  /// lateral slope of the cells under the body: the patient's roll). Empty: no such limit.
  std::vector<double> slope_weights;
  /// Fastest change of atan(s) [rad/s]; infinity: no limit.
  double max_angle_rate_rad_s = std::numeric_limits<double>::infinity();

  /// Success when valid for `size` positions, else an error naming what is wrong.
  Status validate(std::size_t size) const;
};

/**
 * Moves a vector of positions towards its targets along the straight line between them, as far
 * as the limits allow in `dt_s`: the step is the whole change scaled by the largest factor in
 * [0, 1] that keeps every position's rate and the slope angle's rate within their limits, so a
 * change keeps its shape while it is slowed (a tilted plane stays a plane).
 *
 * NaN handling: a NaN target means "no target" (the output is NaN there); a NaN previous value
 * with a finite target starts at the target (nothing is known to limit against). Such elements
 * take no part in the slope limit.
 */
class RateLimiter {
 public:
  /// Throws std::invalid_argument when limits.validate(size) fails.
  RateLimiter(RateLimits limits, std::size_t size);

  /// The positions after `dt_s` [s] from `previous` towards `target` (both of size()).
  std::vector<double> step(const std::vector<double>& previous, const std::vector<double>& target, double dt_s) const;
  /// The largest factor in [0, 1] of the change `target - previous` allowed in `dt_s`.
  double allowedFraction(const std::vector<double>& previous, const std::vector<double>& target, double dt_s) const;
  /// atan(sum w_i x_i) over the finite elements [rad] (0 without weights).
  double angle(const std::vector<double>& x) const;

  std::size_t size() const { return size_; }
  const RateLimits& limits() const { return limits_; }

 private:
  RateLimits limits_;
  std::size_t size_;
};

/// The scalar case: `previous` moved towards `target` by at most max_rate_per_s * dt_s.
double limitRate(double previous, double target, double max_rate_per_s, double dt_s);

}  // namespace nursing_bed
