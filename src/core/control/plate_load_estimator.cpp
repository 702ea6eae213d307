#include "nursing_bed/core/control/plate_load_estimator.h"

#include <algorithm>

#include "nursing_bed/core/physics/units.h"

namespace nursing_bed {

PlateLoadEstimator::PlateLoadEstimator(double filter_time_s, double plate_mass_kg, double plate_damping_n_s_m)
    : filter_time_s_(filter_time_s), plate_mass_kg_(plate_mass_kg), plate_damping_n_s_m_(plate_damping_n_s_m) {}

void PlateLoadEstimator::seed(double load_n) {
  load_n_ = load_n;
  primed_ = false;
}

void PlateLoadEstimator::update(double dt_s, double height_m, double structure_force_n, bool learn) {
  if (!primed_ || !(dt_s > 0.0)) {
    primed_ = true;
    last_height_m_ = height_m;
    force_f_n_ = {structure_force_n, structure_force_n};
    velocity_f_m_s_ = {0.0, 0.0};
    return;
  }
  const double velocity = (height_m - last_height_m_) / dt_s;
  last_height_m_ = height_m;
  // Two first-order stages of tau/2 each: the same lag as one of tau, and the acceleration below
  // differentiates the once-filtered velocity, not the raw one (whose noise is sigma_h / dt).
  const double stage_s = 0.5 * filter_time_s_;
  const double a = std::min(1.0, dt_s / stage_s);
  force_f_n_[0] += a * (structure_force_n - force_f_n_[0]);
  force_f_n_[1] += a * (force_f_n_[0] - force_f_n_[1]);
  velocity_f_m_s_[0] += a * (velocity - velocity_f_m_s_[0]);
  const double velocity_before = velocity_f_m_s_[1];
  velocity_f_m_s_[1] += a * (velocity_f_m_s_[0] - velocity_f_m_s_[1]);
  if (!learn) return;
  // d/dt of the twice-filtered velocity = the twice-filtered acceleration.
  const double accel_f = (velocity_f_m_s_[0] - velocity_before) / std::max(stage_s, dt_s);
  const double supported = force_f_n_[1] - plate_damping_n_s_m_ * velocity_f_m_s_[1];
  // A plate in free fall (a_f near -g) carries nothing it could be weighed by: bounded.
  const double heavy = supported / std::max(0.2, 1.0 + accel_f / kGravity);
  load_n_ = std::max(0.0, heavy >= plate_mass_kg_ * kGravity ? heavy : supported - plate_mass_kg_ * accel_f);
}

}  // namespace nursing_bed
