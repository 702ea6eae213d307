// Load on a cell's plate from its force balance (ROS-free).
#pragma once

#include <array>

namespace nursing_bed {

/**
 * Estimates the load W a cell carries from the plate's force balance
 *   m a = F(h, p) - W - c v,   m = max(m_plate, W / g),
 * with F(h, p) the structure's plate force, p A_eff and the film's own (the characteristic's
 * loadAt), and the velocity from successive heights. Both sides pass through the same filter (two first-order
 * stages of tau/2): the filtered acceleration is then the derivative of the filtered velocity,
 * (v_1 - v_2) / (tau/2), so no second difference of a noisy height is taken, and for a
 * constant W the filtered balance holds exactly while the plate swings:
 *   W (1 + a_f / g) = F_f - c v_f   (load-dominated mass),   W = F_f - c v_f - m_plate a_f (light).
 * So the estimate learns while the plate moves, not only at rest: a cell whose plate chatters
 * after a load drop (stiff near the FE table's top) read its old load for minutes before.
 */
class PlateLoadEstimator {
 public:
  /// tau: filter time constant [s]; plate mass [kg] and guide damping [N s/m] of the cell model.
  PlateLoadEstimator(double filter_time_s, double plate_mass_kg, double plate_damping_n_s_m);

  /// Sets the estimate (a load cell, the nominal load); the filters restart from it.
  void seed(double load_n);
  /// One period: time step [s], measured height [m], the structure's plate force at (h, p) [N];
  /// `learn` false (plate on the bed, the valves in a move) keeps the estimate, not the filters.
  void update(double dt_s, double height_m, double structure_force_n, bool learn);
  double load() const { return load_n_; }
  /// Changes the filter time constant [s] (positive); the filters keep their state.
  void setFilterTime(double filter_time_s) { filter_time_s_ = filter_time_s; }

 private:
  double filter_time_s_, plate_mass_kg_, plate_damping_n_s_m_;
  double load_n_ = 0.6;
  bool primed_ = false;  // the filters hold a sample and a height to differentiate
  double last_height_m_ = 0.0;
  std::array<double, 2> force_f_n_{}, velocity_f_m_s_{};  // the two filter stages
};

}  // namespace nursing_bed
