#include "nursing_bed/core/control/plate_tracker.h"

#include <algorithm>
#include <cmath>

namespace nursing_bed {

namespace {
/// The tracker's gains at period `dt_s`: alpha = 2 w dt, beta = (w dt)^2, alpha within (0, 1].
void gains(double bandwidth_per_s, double dt_s, double* alpha, double* beta) {
  const double wdt = std::min(bandwidth_per_s * dt_s, 0.5);
  *alpha = 2.0 * wdt;
  *beta = wdt * wdt;
}
}  // namespace

void PlateTracker::reset(double height_m) {
  state_ = {height_m, 0.0};
  started_ = true;
}

const PlateState& PlateTracker::update(double dt_s, double height_m, double acceleration_m_s2) {
  if (!started_ || !(dt_s > 0.0) || !std::isfinite(state_.height_m) || !std::isfinite(state_.velocity_m_s)) {
    reset(height_m);
    return state_;
  }
  double alpha = 0.0, beta = 0.0;
  gains(bandwidth_per_s_, dt_s, &alpha, &beta);
  const double a = std::isfinite(acceleration_m_s2) ? acceleration_m_s2 : 0.0;
  const double h = state_.height_m + state_.velocity_m_s * dt_s + 0.5 * a * dt_s * dt_s;
  const double v = state_.velocity_m_s + a * dt_s;
  const double residual = height_m - h;
  state_.height_m = h + alpha * residual;
  state_.velocity_m_s = v + beta / dt_s * residual;
  return state_;
}

double PlateTracker::speedSd(double height_sd_m, double dt_s) const {
  // The alpha-beta filter's steady speed variance: sd^2 2 beta^2 / (dt^2 alpha (4 - 2 alpha - beta)).
  double alpha = 0.0, beta = 0.0;
  gains(bandwidth_per_s_, dt_s, &alpha, &beta);
  return height_sd_m * std::sqrt(2.0 * beta * beta / (alpha * (4.0 - 2.0 * alpha - beta))) / dt_s;
}

}  // namespace nursing_bed
