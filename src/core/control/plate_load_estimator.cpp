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
    force_f_n_ = structure_force_n;
    velocity_f_m_s_ = 0.0;
    return;
  }
  const double velocity = (height_m - last_height_m_) / dt_s;
  last_height_m_ = height_m;
  const double a = std::min(1.0, dt_s / filter_time_s_);
  const double velocity_before = velocity_f_m_s_;
  force_f_n_ += a * (structure_force_n - force_f_n_);
  velocity_f_m_s_ += a * (velocity - velocity_f_m_s_);
  if (!learn) return;
  // d/dt of the filtered velocity = the filtered acceleration.
  const double accel_f = (velocity - velocity_before) / std::max(filter_time_s_, dt_s);
  const double supported = force_f_n_ - plate_damping_n_s_m_ * velocity_f_m_s_;
  // A plate in free fall (a_f near -g) carries nothing it could be weighed by: bounded.
  const double heavy = supported / std::max(0.2, 1.0 + accel_f / kGravity);
  const double load = heavy >= plate_mass_kg_ * kGravity ? heavy : supported - plate_mass_kg_ * accel_f;
  load_n_ = std::max(0.0, load);
}

}  // namespace nursing_bed
