// The end of a height move under feedback (ROS-free): the force the cell should put on the
// plate so that it lands on the aim without a swing; HeightController turns that force into gas.
#pragma once

#include <optional>

namespace nursing_bed {

/// The plate as the landing sees it in one period.
struct PlateState {
  double height_m = 0.0;
  double velocity_m_s = 0.0;  ///< upwards positive
};

/// The plate's mechanics the landing plans with.
struct PlateMechanics {
  double load_n = 0.0;         ///< what presses the plate down (its weight included) [N]
  double mass_kg = 0.0;        ///< what moves with it [kg]
  double damping_n_s_m = 0.0;  ///< viscous damping of its guide [N s/m]
};

/**
 * A shaped move's open-loop tail assumes a linear gas spring of one period; a cell whose
 * stiffness changes several-fold within the move (the FE fold-table cell) leaves the plate
 * swinging. The landing instead asks, every period, for the force that gives the plate a
 * critically damped approach to the aim (both poles at -rate):
 *   m a = -2 rate m v - rate^2 m (h - aim),  F = load + c v + m a   (feedback linearisation),
 * and the controller makes the gas that exerts F at the present height. The approach is as
 * fast as the loop allows: `rate` is bounded by its delay (HeightController::landingRate).
 */
class PlateLanding {
 public:
  void start();
  void stop() { active_ = false; }
  bool active() const { return active_; }

  /// The force [N] the cell should exert on the plate over the next period, or nothing once
  /// the plate has landed (within `landed_m` of the aim, slower than `landed_speed_m_s`) or
  /// `timeout_s` has passed (the landing has then stopped). The force is at least a twentieth
  /// of the load: the gas cannot pull.
  std::optional<double> force(double dt_s, const PlateState& plate, double aim_m, const PlateMechanics& mechanics,
                              double rate_per_s);
  /// That force alone, without the landing's bookkeeping (what a landing begun now would ask).
  static double approachForce(const PlateState& plate, double aim_m, const PlateMechanics& mechanics,
                              double rate_per_s);

  double landed_m = 0.0005;        ///< height error that counts as landed [m]
  double landed_speed_m_s = 0.01;  ///< plate speed under which it counts as landed [m/s]
  double timeout_s = 1.0;          ///< a landing lasts at most this long [s]

 private:
  bool active_ = false;
  double time_s_ = 0.0;
};

}  // namespace nursing_bed
