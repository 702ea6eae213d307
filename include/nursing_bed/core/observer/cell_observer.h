// Height from pressure: an extended Kalman filter on the cell model (ROS-free). A real array bed
// has a pressure sensor per cell and rarely a height sensor; the paper (sections 2.1 and 5) sets
// the height through the pressure and the mass of air filled in. This observer does that with the
// whole control-volume model: it integrates the valve flows (commands and supply pressure in),
// corrects with the measured pressure (and height or inflow where the hardware has them), and
// estimates gas mass, plate height and velocity, and the load, with their uncertainty.
// SI units throughout: kg, m, s, N, Pa (gauge unless named absolute), K.
#pragma once

#include <Eigen/Dense>
#include <deque>
#include <limits>
#include <string>
#include <vector>

#include "nursing_bed/core/physics/cell_model.h"

namespace nursing_bed {

/// Tuning of the observer. Defaults fit the nominal cell at a 5 ms period with a 12-bit pressure
/// input (doc/real_bed.md, "Observer").
struct CellObserverParams {
  double period_s = 0.005;                 ///< one predict/correct step [s]
  /// sd of the pressure reading [Pa]: sensor noise and quantisation, and what the model misses
  /// of the fast plate and film dynamics (50-100 Pa tracks best; the sensor alone is ~10 Pa).
  double pressure_noise_pa = 70.0;
  double height_noise_m = 0.0005;          ///< sd of a height reading, where there is one [m]
  double inflow_noise_kg_s = 2.0e-6;       ///< sd of an inflow reading, where there is one [kg/s]
  double flow_uncertainty = 0.02;          ///< relative sd of the modelled valve and leak flows over 1 s [-]
  double mass_walk_kg_sqrt_s = 2.0e-8;     ///< random walk of the gas mass (unmodelled leaks) [kg/sqrt(s)]
  double heat_walk_w_sqrt_s = 0.02;        ///< random walk of the gas energy (unmodelled heat) [J/sqrt(s)]
  double force_noise_n = 0.5;              ///< unmodelled force on the plate, white [N sqrt(s)]
  double load_walk_n_sqrt_s = 3.0;         ///< random walk of the load (the patient moves) [N/sqrt(s)]
  double initial_load_sd_n = 10.0;         ///< sd of the load guess at reset [N]
  double valve_dead_time_s = 0.0;          ///< a valve command acts this late (bus and valve) [s]
  /// sd of a reading's time against the model's (bus cycle, PWM phase, valve timing) [s]
  double reading_time_sd_s = 0.0;
  double reanchor_pressure_pa = 60.0;      ///< |gauge pressure| under which a venting cell is flat [Pa]
  double reanchor_time_s = 0.5;            ///< vented and that flat for this long: re-anchor [s]
  /// Above this estimated height the gas mass is not corrected from the pressure, only
  /// integrated from the valve flows: a lifted plate's pressure follows the load, and cannot
  /// tell a mass error from a load change (the two drift together otherwise) [m].
  double mass_lock_height_m = 0.005;
  int jacobian_refresh_steps = 2;          ///< steps between linearisations [-]

  /// Empty when valid, else every problem found, separated by "; ".
  std::string validate() const;
};

/// Inputs over one period (what was commanded, not what was measured).
struct ObserverInputs {
  double inlet_opening = 0.0;              ///< inlet valve opening 0..1 (mean over the period)
  double vent_opening = 0.0;               ///< vent valve opening 0..1
  double vent_back_pressure_pa = 0.0;      ///< gauge pressure at the vent outlet (CPR vacuum < 0)
  /// Regulator setting or measured supply pressure, gauge; NaN: the cell parameters' setting.
  double supply_pressure_pa = std::numeric_limits<double>::quiet_NaN();
};

/// Readings at the end of the period; NaN where the hardware has none (or it failed).
struct ObserverReadings {
  double gauge_pressure_pa = std::numeric_limits<double>::quiet_NaN();
  double height_m = std::numeric_limits<double>::quiet_NaN();
  double inflow_kg_s = std::numeric_limits<double>::quiet_NaN();
};

/// The estimate with its standard deviations.
struct CellEstimate {
  double height_m = 0.0, height_sd_m = 0.0;
  double velocity_m_s = 0.0;
  double mass_kg = 0.0, mass_sd_kg = 0.0;
  double load_n = 0.0, load_sd_n = 0.0;
  double gauge_pressure_pa = 0.0;          ///< model pressure at the estimate
  double temperature_k = 0.0;
  double volume_m3 = 0.0;
  int reanchors = 0;                       ///< how often the mass was re-anchored on a flat cell
};

/**
 * EKF on x = [cell model state (gas mass, internal energy, plate height and velocity, regulator
 * outlet, film shape, states of the effects given), load]. The load is a random walk. Effects
 * (a diagnosed leak, heat exchange, ...) join the model exactly as in the simulation.
 *  - Predict: the mean by the cell model's own integrator (error-controlled ROS2 sub-steps:
 *    the plate on its gas spring, its lift-off and the film are stiff); the covariance by a
 *    finite-difference Jacobian J and the linearly implicit map F = I + dt (I - g dt J)^-1 J.
 *    Valve-flow noise enters mass and energy together (gas carries its enthalpy).
 *  - Correct: sequential scalar updates with each reading present; the gas mass only while
 *    the plate is down (mass_lock_height_m).
 *  - Re-anchor: a cell whose vent has been open with |p| < reanchor_pressure_pa for
 *    reanchor_time_s is flat: gas mass and energy are reset to the flat cell's (ambient air in
 *    the rest volume), which ends the drift of a mass that is otherwise only integrated.
 */
class CellObserver {
 public:
  using Vector = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, CellModel::kMaxStates + 1, 1>;
  using Matrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, CellModel::kMaxStates + 1,
                               CellModel::kMaxStates + 1>;

  /// Throws std::invalid_argument naming what is wrong in either parameter set.
  CellObserver(const CellParams& model, const CellObserverParams& params, const std::vector<CellEffectPtr>& effects = {});

  /// Flat cell at ambient, load guess `load_n` with sd initial_load_sd_n.
  void reset(double load_n);
  /// Plate at rest at `height_m` under `load_n` (both known well).
  void resetToHeight(double height_m, double load_n);

  /// One period: predict with `inputs`, then correct with `readings`. `dt_s` > 0: the time
  /// since the last step when it differs from period_s (a real-time loop's jitter).
  void step(const ObserverInputs& inputs, const ObserverReadings& readings, double dt_s = 0.0);
  void predict(const ObserverInputs& inputs, double dt_s = 0.0);
  void correct(const ObserverReadings& readings);

  CellEstimate estimate() const;
  const CellVariables& variables() const { return vars_; }
  double time() const { return time_; }
  const Vector& state() const { return x_; }
  const Matrix& covariance() const { return p_; }
  const CellObserverParams& params() const { return params_; }
  const CellModel& model() const { return model_; }

 private:
  int loadIndex() const { return static_cast<int>(x_.size()) - 1; }
  CellInputs modelInputs(const ObserverInputs& in, double load_n) const;
  CellModel::StateVector rate(const Vector& x, const CellInputs& in, CellVariables* vars = nullptr) const;
  void linearise(const CellInputs& in);
  void integrateMean(const CellInputs& in, double dt_s);
  void propagateCovariance(double dt_s);
  void scalarUpdate(const Vector& h_row, double innovation, double variance);
  void correctPressure(double gauge_pressure_pa);
  void correctInflow(double inflow_kg_s);
  void keepPhysical();
  void checkReanchor(const ObserverReadings& readings);
  void anchorFlat();
  void refresh();
  ObserverInputs delayed(const ObserverInputs& in);

  CellObserverParams params_;
  CellModel model_;          ///< integrates the mean from the estimate; resets
  double time_ = 0.0;
  double pressure_rate_pa_s_ = 0.0;  ///< the model's gauge pressure rate over the last period
  Vector x_;
  Matrix p_;
  Matrix jacobian_;          ///< d rate / d x at the last linearisation (load column included)
  int steps_since_jacobian_ = 1 << 30;
  CellVariables vars_;       ///< variables at the current estimate
  Vector scale_;             ///< typical magnitudes (finite-difference increments)
  std::deque<ObserverInputs> pending_;  ///< commands not yet acting (valve dead time)
  ObserverInputs applied_;   ///< the inputs acting over the last period
  double flat_since_s_ = -1.0;
  int reanchors_ = 0;
};

/// Height errors (true minus estimated) accumulated over a run: RMS and worst.
struct ObserverErrorStats {
  double sum_sq_m2 = 0.0;
  double max_abs_m = 0.0;    ///< largest |true - estimated| height [m]
  long samples = 0;
  void add(double error_m);
  double rmsM() const;       ///< RMS error [m] (0 without samples)
};

}  // namespace nursing_bed
