// Height from pressure: an extended Kalman filter on the cell model (ROS-free). A real array bed
// has a pressure sensor per cell and rarely a height sensor; the paper (sections 2.1 and 5) sets
// the height through the pressure and the mass of air filled in. This observer does that with the
// whole control-volume model: it integrates the valve flows (commands and supply pressure in),
// corrects with the measured pressure (and height or inflow where the hardware has them), and
// estimates gas mass, plate height and velocity, and the load, with their uncertainty.
// SI units throughout: kg, m, s, N, Pa (gauge unless named absolute), K.
#pragma once

#include <Eigen/Dense>
#include <limits>
#include <string>
#include <vector>

#include "nursing_bed/core/io/status.h"
#include "nursing_bed/core/observer/observer_inputs.h"
#include "nursing_bed/core/observer/reading_noise.h"
#include "nursing_bed/core/observer/reanchor_detector.h"
#include "nursing_bed/core/observer/resting_plate_pulse.h"
#include "nursing_bed/core/observer/valve_delay_line.h"
#include "nursing_bed/core/observer/weight_bound.h"
#include "nursing_bed/core/physics/cell_model.h"

namespace nursing_bed {

/// Tuning of the observer. Defaults fit the nominal cell at a 5 ms period with a 12-bit pressure
/// input (doc/real_bed.md, "Observer").
struct CellObserverParams {
  double period_s = 0.005;              ///< one step [s]
  double pressure_noise_pa = 15.0;      ///< sd of a pressure reading until the still gas's readings measured it [Pa]
  double height_noise_m = 0.0005;       ///< sd of a height reading, where there is one [m]
  double flow_uncertainty = 0.02;       ///< relative sd of the modelled valve and leak flows over 1 s [-]
  double mass_walk_kg_sqrt_s = 2.0e-8;  ///< random walk of the gas mass (unmodelled leaks) [kg/sqrt(s)]
  double heat_walk_w_sqrt_s = 0.02;     ///< random walk of the gas energy (unmodelled heat) [J/sqrt(s)]
  double load_filter_time_s = 0.3;      ///< time constant of the load estimate (p A_eff) [s]
  double initial_load_sd_n = 10.0;      ///< sd of the load guess at reset [N]
  double valve_dead_time_s = 0.0;       ///< a valve command acts this late (bus and valve) [s]
  /// |mean gauge pressure| under which a venting cell is flat [Pa]; at most half the pressure
  /// at which the plate alone rests lifted (the model's, found at construction).
  double reanchor_pressure_pa = 60.0;
  double reanchor_time_s = 0.5;  ///< inlet shut and that flat (mean pressure) this long: re-anchor [s]
  /// Both valves shut this long (the plate settled, then its mean pressure over as long again)
  /// bounds the height from above by where the plate alone rests at that pressure; 0: off [s].
  double weight_bound_window_s = 0.5;
  /// The same bound while the plate is lifted (inlet open, vent shut, the plate not falling:
  /// it needs at least its weight then too): after this long, readings averaged as long
  /// again; 0: off [s].
  double weight_bound_lift_window_s = 0.05;
  /// Share of the vent gas counted while the plate may ring (within 30 ms of a valve edge; the
  /// gauge pressure within the flows' curved bands, 300 Pa by default; beyond, this share times
  /// that pressure over the cell's) that the count may be off: flows at readings 5 ms apart
  /// miss the plate's 40-100 Hz swing, and a few ms' error in the valves' timing moves them
  /// onto another part of it. Summed since the cell was last found flat
  /// (CellEstimate::count_doubt_m) [-].
  double vent_count_doubt = 0.1;

  /// Success when valid, else an error with every problem found, separated by "; ".
  Status validate() const;
};

/// What one step found, for the control side to act on (the counts in CellEstimate are for
/// diagnostics).
struct ObserverEvents {
  bool reanchored = false;      ///< the gas was re-anchored on a flat cell
  bool weight_bounded = false;  ///< the plate's weight bounded the height from above
};

/// The estimate with its standard deviations.
struct CellEstimate {
  double height_m = 0.0, height_sd_m = 0.0;
  double velocity_m_s = 0.0;
  double mass_kg = 0.0, mass_sd_kg = 0.0;
  double load_n = 0.0, load_sd_n = 0.0;
  double gauge_pressure_pa = 0.0;  ///< model pressure at the estimate
  double temperature_k = 0.0;
  double volume_m3 = 0.0;
  int reanchors = 0;               ///< how often the mass was re-anchored on a flat cell
  int weight_bounds = 0;           ///< how often the plate's weight bounded the height
  double pressure_noise_pa = 0.0;  ///< the readings' sd as measured (ReadingNoise) [Pa]
  /// The height the gas counted since the cell was last found flat may be off by: the vent
  /// edges' doubt (CellObserverParams::vent_count_doubt), the readings' noise near ambient and
  /// what doubtCount() added (an unsure link, a late period); 0 on a flat cell or with a
  /// height sensor [m].
  double count_doubt_m = 0.0;
};

/**
 * A Kalman filter on the gas inventory, the height from the gas and the measured pressure.
 * The paper's control idea (sections 2.1 and 5): the height is set through the mass of air
 * filled in and the pressure. The gas in the cell, mass m and internal energy U, changes only
 * by what flows through the valves (commands delayed by the dead time, supply pressure, the
 * measured cell pressure), the leaks, the heat exchanged and the work on the plate; the given
 * effects (a diagnosed leak, heat exchange, ...) join these flows exactly as in the simulation.
 * Its volume then follows from the pressure read: V = (gamma - 1) U / p, and the height from
 * the structure's V(h, film relaxed to p). The work p dV of each step is taken along the
 * isentrope between the two readings, so the plate's own dynamics (a heavy plate bouncing on its
 * gas spring) and the unknown load do not enter: no model of them is needed to follow them.
 *  - Gas covariance (m, U): the flows' relative uncertainty (correlated over 1 s) and random
 *    walks; the height's sd follows from U's through V.
 *  - Plate down (the volume from the pressure is at most the flat cell's): U is read from the
 *    pressure (p V_flat = (gamma - 1) U), a measurement of the gas with the pressure's noise.
 *  - A height reading, where fitted, measures U the same way at its height.
 *  - An inflow reading, where fitted, replaces the modelled inlet flow.
 *  - A valve opening on a resting plate: its first period's flows are the model's plate's,
 *    swung from rest at the pressure read before (RestingPlatePulse), not the readings'.
 *  - Re-anchor: a cell with its inlet shut (vented or sealed) whose |mean pressure| stays for
 *    reanchor_time_s below half the plate alone's lifted pressure (and reanchor_pressure_pa;
 *    while expectFlat, anything below) is flat: mass and energy are the flat cell's (the rest
 *    volume's air at the mean pressure), which ends the drift of a mass that is otherwise only
 *    integrated.
 *  - Load: p A_eff(h) less the guide's damping while the plate is lifted, filtered; while it
 *    is down, at least the flat cell's plate force at the pressure read (the load holds the
 *    plate down against the gas), filtered the same way.
 *  - Reading noise: measured from the readings while both valves are shut and the plate has
 *    settled (ReadingNoise), the configured pressure_noise_pa until then; it sets the flows'
 *    noise bias near ambient, the measurements' variances and the weight bound's error.
 *  - Count doubt: vent gas counted within 30 ms of a valve edge, near ambient (a swing the
 *    readings do not resolve), is summed as the count's doubt, reported as the height it spans
 *    (count_doubt_m) and cleared where the gas is measured (flat, a height reading); the control
 *    side re-anchors a light cell on it (GasVerifier).
 *  - Weight bound: no load is less than the plate's own weight and the plate alone rests
 *    higher the more pressure holds it, so a settled plate's mean pressure bounds its height
 *    from above (p A_eff(h) >= m_plate g). An inventory drifted past it is measured back to it.
 */
/// Size: the filter's state, covariance and steps (propagation, isentropic work, volume
/// inversion, measurements, load) are one computation; the delay line, the flat test and the
/// weight bound and an isolated pulse's swing are their own classes.
class CellObserver {
 public:
  using Vector = CellModel::StateVector;
  using Matrix2 = Eigen::Matrix2d;

  /// Throws std::invalid_argument naming what is wrong in either parameter set.
  CellObserver(const CellParams& model, const CellObserverParams& params,
               const std::vector<CellEffectPtr>& effects = {});

  /// Flat cell at ambient, load guess `load_n` with sd initial_load_sd_n; the supply line at
  /// its setting (a bed's supply runs before its cells are controlled).
  void reset(double load_n);
  /// Plate at rest at `height_m` under `load_n` (both known well).
  void resetToHeight(double height_m, double load_n);

  /// One period: the gas over the period with `inputs`, then the readings at its end. `dt_s`
  /// > 0: the time since the last step when it differs from period_s (a real-time loop's
  /// jitter).
  /// Returns what the step found (a re-anchor, a weight bound).
  ObserverEvents step(const ObserverInputs& inputs, const Readings& readings, double dt_s = 0.0);
  /// A period without readings (a lost link): the gas integrated, the plate held; the flat
  /// test starts again.
  void predict(const ObserverInputs& inputs, double dt_s = 0.0);
  /// A period without a new sample (the bus slower than the step, a reply missed): as
  /// predict(), the flat test paused rather than restarted.
  void coast(const ObserverInputs& inputs, double dt_s = 0.0);

  CellEstimate estimate() const;
  /// Adds `gas_kg` to the count's doubt in full: gas counted while the valves' record or the
  /// readings were unsure (a communication or sensor fault), cleared as the rest of the doubt is.
  void doubtCount(double gas_kg);
  const CellVariables& variables() const { return vars_; }
  double time() const { return time_; }
  /// The cell model state at the estimate (m, U, h, v, regulator, film, effect states).
  const Vector& state() const { return x_; }
  /// Covariance of (gas mass, internal energy).
  const Matrix2& covariance() const { return p_; }
  const CellObserverParams& params() const { return params_; }
  const CellModel& model() const { return model_; }
  /// The valve openings acting over the last period (the commands after the dead time).
  const ObserverInputs& appliedInputs() const { return applied_; }
  /// Mean pressure under which a cell with its inlet shut counts as flat [Pa].
  double flatPressure() const { return reanchor_.flatPressure(); }
  /// The cell has vented and keeps its valves shut for `for_s` to test for a flat cell (the
  /// control side's gas check): meanwhile a mean pressure below ambient counts as flat too.
  void expectFlat(double for_s);

 private:
  CellInputs modelInputs(const ObserverInputs& in, double flow_gauge_pressure_pa) const;
  /// Gas flows (mass, enthalpy and heat, no work) and the other states' rates at the estimate,
  /// the gas's scaled by `pulse_factor` (RestingPlatePulse).
  void integrateFlows(const CellInputs& in, double dt_s, double pulse_factor);
  /// The gas's (dm/dt, dU/dt less the work) from a model rate and its variables.
  static Eigen::Vector2d gasRates(const Vector& dx, const CellVariables& v);
  /// What the readings' noise does to the gas's rates near ambient: adds on average through
  /// the flows' curvature in pressure (`bias`, to take off the rates at the readings), and
  /// scatters them by the slope times the noise of the period's reading mean (`sd`).
  struct FlowNoise {
    Eigen::Vector2d bias = Eigen::Vector2d::Zero();
    Eigen::Vector2d sd = Eigen::Vector2d::Zero();
  };
  FlowNoise flowNoise(const CellInputs& in, const Eigen::Vector2d& at_reading);
  /// The gas the count may be off by since it was last measured: the vent doubts summed and
  /// two sds of the readings' noise on the flows (a random walk) [kg].
  double countDoubtKg() const;
  /// The gas is measured (found flat, a height read): the count's doubt starts again.
  void clearCountDoubt();
  void propagateCovariance(double dt_s);
  /// The cell pressure the flows of the period see: the readings' mean; away from ambient
  /// smoothed within the noise (see flowNoise for near ambient).
  double flowPressure(double old_pressure_pa, double new_pressure_pa, double dt_s);
  /// The energy after the volume change at the new pressure, along the isentrope (trapezoid),
  /// from the gas's volume `v0_m3` at the old one.
  void isentropicWork(double old_pressure_pa, double new_pressure_pa, double v0_m3);
  /// The bag's top at the pressure: the structure's height limit with the film relaxed to it.
  double topHeight(double gauge_pressure_pa) const;
  /// Height and film from the volume at the pressure read; returns false when the plate is down.
  bool invertVolume(double gauge_pressure_pa, double dt_s);
  /// Scalar measurement of U (plate down, or a height reading): value and its variance.
  void measureEnergy(double energy_j, double variance_j2);
  /// A height reading and the gas's height, weighed by their variances.
  void fuseHeight(double height_m);
  void updateLoad(double gauge_pressure_pa, bool lifted, double dt_s);
  void keepPhysical();
  /// True when the cell was found flat and its gas re-anchored.
  bool checkReanchor(const Readings& readings);
  /// Whether the count lets a flat test found under an open vent anchor the cell now.
  bool countAllowsFlat();
  /// The flat cell's gas at `gauge_pressure_pa` (the mean read).
  void anchorFlat(double gauge_pressure_pa);
  void refresh(const CellInputs& in);
  /// The weight bound: the readings averaged over quiet windows (both valves shut, settled);
  /// true when it moved the estimate.
  bool boundByPlateWeight(double gauge_pressure_pa, bool lifted, double dt_s);
  /// Scalar measurement of U: the plate at rest at `height_m` (sd `sd_m`) under the pressure.
  void measureSettledHeight(double height_m, double sd_m, double gauge_pressure_pa);
  /// Measurement of U on the flat cell at the reading, while its plate rests there.
  void measureFlat(double gauge_pressure_pa);
  /// Adds the period's vent gas `vent_kg` counted at the flows' pressure to the count's doubt.
  void doubtVentCount(double vent_kg, double flow_gauge_pressure_pa);
  /// Feeds the readings taken while the gas is still (both valves shut a settling time) to
  /// reading_noise_.
  void trackReadingNoise(double gauge_pressure_pa, double dt_s);
  double pressureNoise() const { return reading_noise_.sd(); }
  /// Both valves shut over the last period (the inputs acting, after the dead time).
  bool valvesShut() const { return applied_.valves.inlet == 0.0 && applied_.valves.vent == 0.0; }
  /// The period's inputs: the valves acting (delayed), the supply line where it is measured.
  void takeInputs(const ObserverInputs& inputs, double dt);

  CellObserverParams params_;
  CellModel model_;  ///< the cell's physics (flows, effects, structure); resets
  double gamma_;
  double time_ = 0.0;
  Vector x_;   ///< model state at the estimate
  Matrix2 p_;  ///< covariance of (m, U)
  double load_n_ = 0.6, load_var_n2_ = 0.0;
  double height_sd_m_ = 0.0;
  double volume_slope_m2_ = 0.01;  ///< dV/dh with the film relaxed, at the estimate
  CellVariables vars_;             ///< variables at the current estimate
  ValveDelayLine delay_;           ///< the commands until they act (valve_dead_time_s)
  RestingPlatePulse pulse_;        ///< an isolated valve pulse's gas through the plate's swing
  ObserverInputs applied_;         ///< the inputs acting over the last period
  double last_pressure_pa_ = std::numeric_limits<double>::quiet_NaN();  ///< the last reading
  double flow_pressure_pa_ = std::numeric_limits<double>::quiet_NaN();  ///< see flowPressure
  ReanchorDetector reanchor_;                                           ///< the flat-cell test
  int reanchors_ = 0;
  double unstretched_top_m_ = 0.0;  ///< the structure's height limit with the film at rest
  WeightBound weight_bound_;        ///< the plate alone's rests and the quiet windows
  int weight_bounds_ = 0;
  ReadingNoise reading_noise_;    ///< kept over resets: the sensor's, not the gas's
  double still_s_ = 0.0;          ///< both valves shut this long, for the noise [s]
  double count_doubt_kg_ = 0.0;   ///< gas the vent count may be off by since found flat [kg]
  double count_noise_kg2_ = 0.0;  ///< the readings' noise's variance on the count since then [kg^2]
  double since_edge_s_ = 0.0;     ///< since the valves' openings last changed [s]
  double flat_claimed_s_ = -1.0;  ///< when the flat test first held under this vent (-1: not yet) [s]
};

/// Height errors (true minus estimated) accumulated over a run: RMS and worst.
struct ObserverErrorStats {
  double sum_sq_m2 = 0.0;
  double max_abs_m = 0.0;  ///< largest |true - estimated| height [m]
  long samples = 0;
  void add(double error_m);
  double rmsM() const;  ///< RMS error [m] (0 without samples)
};

}  // namespace nursing_bed
