// Height controller of one airbag cell (ROS-free). It sets the height through the gas, as the
// paper's section 5 proposes, but through a load-aware characteristic and with the loop
// closed on measured height and pressure.
#pragma once

#include <memory>
#include <optional>
#include <string>

#include "nursing_bed/core/control/commands_in_flight.h"
#include "nursing_bed/core/control/plate_landing.h"
#include "nursing_bed/core/control/plate_load_estimator.h"
#include "nursing_bed/core/control/plate_tracker.h"
#include "nursing_bed/core/control/shaped_move.h"
#include "nursing_bed/core/physics/cell_characteristic.h"
#include "nursing_bed/core/physics/valve_openings.h"

namespace nursing_bed {

struct HeightControllerParams {
  double min_height_m = 0.0;           ///< lowest setpoint accepted [m]
  double max_height_m = 0.150;         ///< highest setpoint accepted [m]
  double height_tolerance_m = 0.0004;  ///< deadband: no valve action within it [m]
  double approach_band_m = 0.004;      ///< predicted error over which a valve goes from shut to fully open [m]
  double max_pressure_pa = 32000.0;    ///< never fill above this gauge pressure (below the relief) [Pa]
  double load_filter_time_s = 0.3;     ///< time constant of the load estimate's filter (PlateLoadEstimator) [s]
  double settled_speed_m_s = 0.003;    ///< plate speed under which the cell counts as at rest [m/s]
  double integral_rate_per_s = 2.0;    ///< rate at which a resting height error is integrated out [1/s]
  double integral_limit_m = 0.02;      ///< bound of that correction [m]
  double move_threshold_m = 0.003;     ///< predicted error above which a move uses the shaped full-flow law [m]
  double damping_band_m = 0.01;  ///< plate swing about its rest height that opens a valve fully (active damping) [m]
  double hold_band_m =
      0.0004;  ///< once on target, the valves stay shut until the predicted or resting error leaves this [m]

  /// Empty when valid, else every problem found.
  std::string validate() const;
};

/**
 * Model-predictive valve law. From the measured pressure and height it computes the gas's
 * adiabatic invariant K = p V^gamma and, from the tabulated characteristic, the height h_rest at
 * which the plate would come to rest under the estimated load if the valves shut now.
 *  - Moves (|h* - h_rest| > move_threshold_m): the ideal flow-limited command is a
 *    full-flow pulse that ends when h_rest reaches the target. The loaded plate rings on its
 *    gas spring (half period T/2 from the characteristic), so the pulse is passed through a
 *    zero-vibration input shaper: half of it now, half T/2 later. In practice: half open for
 *    T/2, fully open until the gas in the cell plus half a flow for T/2 will carry the plate
 *    to the target, half open for the last T/2 (re-aimed every period on the prediction).
 *    A move too small for that is two half-open pulses T/2 apart. The ringing excited by
 *    the first half-step is cancelled by the second.
 *  - Landing: where the loop outruns the plate (landingRate), the tail is feedback instead
 *    (PlateLanding): the force of a critically damped approach, as the gas that exerts it at
 *    the present height, with the plate's speed tracked on its force balance (PlateTracker).
 *    A cell whose stiffness changes several-fold within the move lands without the swing a
 *    shaper timed on one period leaves.
 *  - Near the target the opening is proportional to h* - h_rest (full at approach_band_m)
 *    plus (h - h_rest) / damping_band_m: gas in while the plate swings above its rest
 *    height, out while below, makes the pressure lag the swing by a quarter period and so
 *    damps the lightly damped plate actively. Deadband height_tolerance_m.
 *  - Valves that act late (setDeadTime): the gas of the commands still in flight counts in
 *    h_rest (a Smith predictor), and where the dead time exceeds a sixteenth of the plate's
 *    period the swing term is dropped (a quarter period late it pumps the swing: a 36 N
 *    plate over Modbus limit-cycled at 5 Hz, a throughput the observer's flow model cannot
 *    follow; doc/real_bed.md).
 *  - Hold: once on target (predicted and measured errors within the deadband; where the
 *    swing is damped, the swing too) the valves stay shut while the predicted rest error
 *    stays within hold_band_m and, at rest, the measured error too. A swing after a load
 *    change rings out on the plate's own damping instead of spending gas on the readings'
 *    noise.
 * The feed-forward is the characteristic (h, load) -> p; the feedback is the measured height:
 * a resting error is integrated into the target the predictor aims at. The load is estimated
 * from the plate's force balance on the characteristic (PlateLoadEstimator) outside moves.
 */
/// Size: ~37 methods and 20 members are one valve law's state (target, integral, load, hold,
/// rest prediction); the move, its landing, the plate's tracked speed and the commands in
/// flight are their own classes.
class HeightController {
 public:
  HeightController(const HeightControllerParams& params, std::shared_ptr<const CellCharacteristic> characteristic);

  /// Empty when `height_m` is an acceptable setpoint, else why not.
  std::string checkSetpoint(double height_m) const;
  /// Sets the target (must pass checkSetpoint); resets the integral correction.
  void setTarget(double height_m);
  void clearTarget();
  bool hasTarget() const { return has_target_; }
  double target() const { return target_m_; }
  /// The integral correction added to the target the predictor aims at [m].
  double integralCorrection() const { return integral_m_; }

  /// One control period: measured gauge pressure [Pa], height [m], their time step [s].
  ValveOpenings update(double dt_s, double gauge_pressure_pa, double height_m);

  /// The valves act this late after a command (bus, terminal, valve) [s]; default 0. The gas
  /// of the commands still in flight counts in the predicted rest height (a Smith predictor):
  /// without it every correction of a heavy plate overshoots by the dead time's worth of
  /// full flow (36 N at 91 mm: ~0.1 m/s of rest height) and the hold limit-cycles.
  void setDeadTime(double dead_time_s);
  /// The valves written for the next `dt_s` (what the cell sent after its modes and safety,
  /// not what update() wanted): kept for the last dead time as the gas in flight.
  void noteWritten(const ValveOpenings& cmd, double dt_s);
  /// The height readings' noise, independent from period to period (sd) [m]; default 0. It
  /// bounds how fast a landing may act on the speed the readings give (landingRate).
  void setHeightNoise(double sd_m) { height_noise_m_ = sd_m; }
  /// Pressure of the supply behind the inlet valve, gauge [Pa] (default: the cell's setting).
  void setSupplyPressure(double pressure_pa) { supply_pressure_pa_ = pressure_pa; }
  /// Seeds the load estimate (e.g. from a load cell or the nominal load) [N].
  void setLoadEstimate(double load_n) { load_.seed(load_n); }
  double loadEstimate() const { return load_.load(); }
  /// Half period of the loaded plate ringing on the closed cell at the target [s].
  double halfPeriod() const;
  /// Where the plate would rest if the valves shut now [m].
  double restingHeight() const { return resting_height_m_; }
  /// Feed-forward: gauge pressure that holds the target under the estimated load [Pa].
  double targetPressure() const;
  /// True when the target needs more pressure than max_pressure_pa allows for this load.
  bool targetOutOfReach() const;
  const HeightControllerParams& params() const { return params_; }
  /// Replaces the gains, bands and limits (e.g. from dynamic reconfigure) when `params` is
  /// valid and returns ""; else returns why not and changes nothing. Refused too: a new
  /// load_filter_time_s (the load estimate is filtered with the old one). Target, load
  /// estimate and a move under way are kept; the integral correction is bounded by the new
  /// integral_limit_m.
  std::string setParams(const HeightControllerParams& params);
  /// The phase of the shaped move under way (kNone outside moves).
  MovePhase movePhase() const { return landing_.active() ? MovePhase::kLanding : move_.phase(); }
  /// The poles of a landing at the target [1/s]: twice the plate's own frequency there, within
  /// what the loop's delay (one period of `dt_s` and the valves' dead time) keeps stable and
  /// what the readings' noise lets the speed's feedback ask of the gas; 0 where that is slower
  /// than the plate itself (the open-loop tail then ends the move).
  double landingRate(double dt_s) const;

 private:
  /// One period's readings and what follows from them, passed between update()'s parts.
  struct Period {
    double dt_s = 0.0, gauge_pressure_pa = 0.0, height_m = 0.0;
    bool resting = false;            ///< the plate's speed is under settled_speed_m_s
    PlateState plate;                ///< the plate's height and speed, tracked (PlateTracker)
    double volume_m3 = 0.0;          ///< gas volume, film relaxed to the pressure
    double invariant = 0.0;          ///< K = p V^gamma of the present gas
    double error_m = 0.0;            ///< target - measured height
    double predicted_error_m = 0.0;  ///< predictedError() after the integral's update
    bool lowest = false;             ///< the target is the lowest setpoint: vent fully
  };
  /// The plate's speed, the load estimate, the rest height and the commands in flight's shift
  /// of it, from the period's readings.
  void predictRest(Period* s);
  /// The valve of `direction` (+1 inlet, -1 vent) at `opening`, within max_pressure_pa; the
  /// lowest setpoint vents fully.
  ValveOpenings command(const Period& s, int direction, double opening) const;
  /// The plate's load, mass and damping as the controller knows them.
  PlateMechanics mechanics() const;
  /// The plate's acceleration [m/s^2] under the structure's force at the readings.
  double plateAcceleration(double structure_force_n, double velocity_m_s) const;
  /// A move or its landing under way: the load estimate and the integral wait.
  bool moving() const { return move_.active() || landing_.active(); }
  /// The change of the gas's invariant K that makes it exert `force_n` on the plate at the
  /// present height; nothing where the height is out of that load's reach.
  std::optional<double> landingGas(const Period& s, double force_n) const;
  /// Full flow hands the move to the landing once the landing asks for less than full flow:
  /// the gas in the cell already carries the plate to the aim (a fold that opens on the way
  /// up runs the plate ahead of the gas's predicted rest).
  bool landingTakesOver(const Period& s, int direction) const;
  /// The landing's valve: its gas within one period; nothing once it has landed (or cannot).
  std::optional<ValveOpenings> land(const Period& s);
  /// Whether a snap of the fold is under way (and not yet overdue); counts its time.
  bool snapping(const Period& s);
  /// During a snap: nothing, or a short pulse that pushes a stalled fold on to its new side.
  ValveOpenings snapNudge(const Period& s);
  /// Outside moves: the proportional approach with active damping, or the hold on target.
  ValveOpenings fineCorrection(const Period& s);
  /// The change of the rest height the commands in flight will still make [m].
  double inFlightRestShift(double gauge_pressure_pa, double volume_m3, double invariant) const;
  /// Target + integral - where the gas rests the plate once the commands in flight have acted.
  double predictedError() const { return target_m_ + integral_m_ - resting_height_m_ - in_flight_shift_m_; }
  /// Holding: whether an error has left hold_band_m (the measured one only counts at rest).
  bool leavesHold(double predicted_error_m, double error_m, bool resting) const;
  /// Rate at which the gas's invariant K changes with the valve of `direction` fully open
  /// [Pa m^(3 gamma)/s], magnitude.
  double fullFlowInvariantRate(int direction, double gauge_pressure_pa, double volume_m3) const;
  /// Rate at which h_rest moves with the valve of `direction` fully open [m/s].
  double fullFlowRestRate(int direction, double gauge_pressure_pa, double volume_m3, double invariant) const;
  /// A move's distance still to go and its full-flow rate, both in the invariant K: a choked
  /// valve changes K at a nearly steady rate, where the rest height's rate follows the cell's
  /// stiffness along the way (an FE cell's p(h) steepens several-fold within one move).
  struct MoveGauge {
    double remaining = 0.0;  ///< K of the aimed rest - K of the predicted one, in the move's direction
    double rate = 0.0;       ///< |dK/dt| at full flow
  };
  MoveGauge moveGauge(int direction, const Period& s) const;

  HeightControllerParams params_;
  std::shared_ptr<const CellCharacteristic> characteristic_;
  bool has_target_ = false;
  double target_m_ = 0.0;
  int settled_branch_ = 0;       ///< the fold's side where the plate last rested on its gas
  double snap_time_s_ = 0.0;     ///< how long the present snap has run [s]
  double snap_from_m_ = 0.0;     ///< plate height where it began [m]
  int snap_direction_ = 0;       ///< +1 the snap lifts the plate, -1 drops it
  double snap_stalled_s_ = 0.0;  ///< how long its plate has stood still [s]
  double integral_m_ = 0.0;
  PlateLoadEstimator load_;
  double resting_height_m_ = 0.0;
  double last_height_m_ = 0.0;
  bool has_last_ = false;
  bool holding_ = false;            ///< on target: valves shut until an error leaves hold_band_m
  CommandsInFlight in_flight_;      ///< commands of the last dead time, not yet acting
  double in_flight_shift_m_ = 0.0;  ///< rest height they still add (this period's)
  /// The film's relaxed shape, carried between periods: a bistable fold keeps its side
  /// (the branch the rest is predicted on) until the pressure leaves its hysteresis band.
  CellCharacteristic::Shape shape_{};
  int branch_ = 0;
  ShapedMove move_;       ///< the shaped full-flow move under way, if any
  PlateLanding landing_;  ///< the move's tail under feedback, if under way
  PlateTracker tracker_;  ///< the plate's speed for the landing
  double supply_pressure_pa_ = 0.0;
  double height_noise_m_ = 0.0;  ///< sd of the height readings' noise [m]
  /// Half period kept for the target and branch while the load estimate stays within 5 % (the
  /// shaper's timing does not follow the estimate's wander within a move).
  struct HalfPeriodCache {
    double half_period_s = -1.0, target_m = -1.0, load_n = -1.0;
    int branch = -1;
  };
  mutable HalfPeriodCache half_period_;
};

/**
 * The physical bound on a height move: the inlet (or, going down, the vent) fully open from
 * the start, with the plate at rest at `from_m`, until the gas volume reaches the volume of the
 * rest state at `to_m` under the same load [s]. No controller can do it faster with these
 * valves and this supply. NaN if the volume is never reached within 30 s.
 */
double flowLimitedMinimumTime(const CellParams& params, double load_n, double from_m, double to_m);

}  // namespace nursing_bed
