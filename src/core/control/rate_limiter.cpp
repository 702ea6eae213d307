#include "nursing_bed/core/control/rate_limiter.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include "nursing_bed/core/io/errors.h"

namespace nursing_bed {
namespace {

bool moving(double previous, double target) { return std::isfinite(previous) && std::isfinite(target); }

// Slope sum w_i (previous_i + f (target_i - previous_i)) over the elements that move: s0 + f ds.
void slopeParts(const std::vector<double>& w, const std::vector<double>& previous, const std::vector<double>& target,
                double* s0, double* ds) {
  *s0 = 0.0;
  *ds = 0.0;
  for (std::size_t i = 0; i < w.size(); ++i) {
    if (!moving(previous[i], target[i])) continue;
    *s0 += w[i] * previous[i];
    *ds += w[i] * (target[i] - previous[i]);
  }
}

}  // namespace

Status RateLimits::validate(std::size_t size) const {
  ErrorList errors;
  errors.addIf(!(max_rate_per_s > 0.0), "max_rate_per_s must be positive (got ", max_rate_per_s, ")");
  errors.addIf(!(max_angle_rate_rad_s > 0.0), "max_angle_rate_rad_s must be positive (got ", max_angle_rate_rad_s, ")");
  errors.addIf(!slope_weights.empty() && slope_weights.size() != size, slope_weights.size(), " slope weights for ",
               size, " positions");
  for (double w : slope_weights)
    if (!std::isfinite(w)) {
      errors.add("slope weights must be finite");
      break;
    }
  return errors.status();
}

RateLimiter::RateLimiter(RateLimits limits, std::size_t size) : limits_(std::move(limits)), size_(size) {
  const Status valid = limits_.validate(size);
  if (!valid.ok()) throw std::invalid_argument("rate limiter: " + valid.message());
}

double RateLimiter::angle(const std::vector<double>& x) const {
  double s = 0.0;
  for (std::size_t i = 0; i < limits_.slope_weights.size() && i < x.size(); ++i)
    if (std::isfinite(x[i])) s += limits_.slope_weights[i] * x[i];
  return std::atan(s);
}

double RateLimiter::allowedFraction(const std::vector<double>& previous, const std::vector<double>& target,
                                    double dt_s) const {
  if (previous.size() != size_ || target.size() != size_)
    throw std::invalid_argument("rate limiter: expected " + std::to_string(size_) + " positions");
  if (!(dt_s > 0.0)) return 0.0;
  double fraction = 1.0;
  const double max_step = limits_.max_rate_per_s * dt_s;
  for (std::size_t i = 0; i < size_; ++i) {
    if (!moving(previous[i], target[i])) continue;
    const double change = std::fabs(target[i] - previous[i]);
    if (change > max_step) fraction = std::min(fraction, max_step / change);
  }
  if (limits_.slope_weights.empty() || !std::isfinite(limits_.max_angle_rate_rad_s)) return fraction;
  double s0 = 0.0, ds = 0.0;
  slopeParts(limits_.slope_weights, previous, target, &s0, &ds);
  if (ds == 0.0) return fraction;
  // atan is monotone: the slope may reach tan(atan(s0) +- max angle step), within +-90 deg.
  const double a0 = std::atan(s0);
  const double max_angle = limits_.max_angle_rate_rad_s * dt_s;
  const double bound = ds > 0.0 ? std::tan(std::min(a0 + max_angle, 1.5)) : std::tan(std::max(a0 - max_angle, -1.5));
  const double reachable = (bound - s0) / ds;
  return std::clamp(std::min(fraction, reachable), 0.0, 1.0);
}

std::vector<double> RateLimiter::step(const std::vector<double>& previous, const std::vector<double>& target,
                                      double dt_s) const {
  const double f = allowedFraction(previous, target, dt_s);
  std::vector<double> out(size_);
  for (std::size_t i = 0; i < size_; ++i) {
    if (!std::isfinite(target[i])) out[i] = std::numeric_limits<double>::quiet_NaN();
    else if (!std::isfinite(previous[i])) out[i] = target[i];
    else out[i] = f >= 1.0 ? target[i] : previous[i] + f * (target[i] - previous[i]);
  }
  return out;
}

double limitRate(double previous, double target, double max_rate_per_s, double dt_s) {
  if (!std::isfinite(target)) return std::numeric_limits<double>::quiet_NaN();
  if (!std::isfinite(previous)) return target;
  const double max_step = std::max(0.0, max_rate_per_s * dt_s);
  return previous + std::clamp(target - previous, -max_step, max_step);
}

}  // namespace nursing_bed
