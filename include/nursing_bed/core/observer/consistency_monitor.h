// A cell's consistency monitor (ROS-free): tests over time whether the readings agree with what
// the observer believes, and says when they persistently do not, whatever the cause (a device
// that restarted empty, a stuck valve, a leak the model lacks, a frozen or drifting sensor).
#pragma once

#include <array>
#include <string>

#include "nursing_bed/core/io/status.h"

namespace nursing_bed {

struct ConsistencyMonitorParams {
  /// The same raw reading this long is a frozen sensor (a live sensor's noise and ADC step
  /// change it every few readings); 0: off [s].
  double frozen_s = 1.0;
  /// Both valves shut this long before the pressure is held to its hold's mean (a plate rings
  /// on its gas spring after a valve edge) [s].
  double settle_s = 0.5;
  /// Time constant of the hold's reference pressure, the innovation's prediction [s].
  double reference_time_s = 2.0;
  /// The fastest a body's moves change a held cell's pressure: beyond the noise the reference
  /// follows the readings at up to this rate. A load that steps (a leg lifted, an arm dropped)
  /// moves the plate along the gas's isentrope within a quarter of its gas-spring period, a
  /// few kPa in 10-20 ms, so only a larger step than a body makes outruns it; 0: the hold's
  /// mean alone (constant loads: a rig, a test) [Pa/s].
  double load_rate_pa_s = 300000.0;
  /// A period of one valve whose counted gas moves the pressure at fixed volume by less than
  /// this (a hold's small corrections, gamma p dm / m) does not end the hold; 0: any does [Pa].
  double hold_correction_pa = 50.0;
  /// Innovation within this many reading sds (and at least min_drift_pa) is noise [-].
  double drift_sds = 6.0;
  double min_drift_pa = 150.0;  ///< least innovation the CUSUM counts [Pa]
  /// The CUSUM of the innovation beyond the drift that is a persistent inconsistency [Pa s].
  double cusum_threshold_pa_s = 60.0;
  /// A settled plate's pressure moving this much between two readings and staying there on
  /// the next is a sensor (an offset, a terminal serving another image): the gas spring and the
  /// plate's inertia spread a load's step over several readings, and on a stiff cell under a
  /// light plate (an FE table's near its top) a step's first reading can move this much, but
  /// the next moves on [Pa].
  double jump_pa = 1200.0;
  /// A weight bound that moves the estimate more than this showed it wrong [m].
  double surprise_m = 0.006;
  /// A valve pulse whose counted gas would move the pressure at least this much at fixed
  /// volume (gamma p dm / m) is checked for a response: the pressure must move its way
  /// before the plate can take the gas up. Smaller pulses (a hold's corrections) are not
  /// judged; 0: off [Pa].
  double response_min_pa = 200.0;
  /// The response asked of such a pulse: the mean of the last few readings moves this many
  /// reading sds from the mean before it, in the pulse's direction [-].
  double response_sds = 3.0;
  /// Under a rigid load a working valve's pulse shows nearly always, the larger the surer: one
  /// valve's judged pulses in a row without a response, at least response_silent_pulses of
  /// them and counted worth this in all, are a valve stuck shut (a slow ramp's pulses are a few
  /// hundred pascals each; 1000 suits a rig). Under a body the part resting on the plate moves
  /// with it and healthy pulses can show nothing three times in a row; 0: off [Pa].
  double response_silent_sum_pa = 0.0;
  int response_silent_pulses = 3;  ///< that many at least [-]
  /// One silent pulse this large is a valve stuck shut on its own [Pa].
  double response_single_pa = 3000.0;
  /// Readings this steady before a pulse (their range over response_steady_s within
  /// response_steady_sds reading sds) show a plate at rest under a load that is not changing:
  /// a valve's gas must then move the pressure at fixed volume before the plate, with the mass
  /// or stiffness on it, takes it up, and no load change can hide it. A body's part shifting,
  /// a neighbour moving or a ring left by an earlier pulse moves the readings by hundreds of
  /// pascals; 0: off [s].
  double response_steady_s = 0.3;
  double response_steady_sds = 6.0;  ///< that range, in reading sds [-]
  /// One silent pulse from steady readings counted this much within a quarter of the plate's
  /// swing (faster than the plate can take it up) is a valve stuck shut on its own [Pa].
  double response_steady_single_pa = 1000.0;
  /// After the pulse's counted flow ends, the response is awaited this long [s].
  double response_window_s = 0.1;
  /// Pulses are judged only where the plate swings on its gas spring at least this slowly:
  /// a light plate follows the gas within a reading or two and its pressure hardly moves,
  /// working valve or not; 0: every plate [s].
  double response_min_period_s = 0.03;
  /// No load on a cell is larger: the observer's load estimate above it (a pressure its
  /// counted gas cannot hold at any height the structure has, e.g. a valve passing gas
  /// while shut) shows the count wrong; 0: off [N].
  double max_load_n = 200.0;
  /// A cell whose readings say flat for landed_time_s (their mean below the observer's flat
  /// pressure: at most half what the plate alone needs to be lifted) while the gas counted
  /// has the plate above landed_height_m lost gas uncounted (a vent stuck open, a
  /// leak, a terminal that restarted empty): the plate landed under the estimate. Above the
  /// few millimetres a re-anchor corrects after a healthy move; 0: off [m].
  double landed_height_m = 0.015;
  double landed_time_s = 0.2;  ///< that long (the readings' mean over a quarter of it) [s]
  /// Failure to reach target, a doubt rather than an inconsistency: once the gas counted through
  /// the inlet over its pulses (a slow ramp's small ones included) would lift the plate this
  /// much at fixed pressure (V dm / (m dV/dh)), 0.1 s later the pressure must have risen by
  /// progress_rel of where it was: the plate climbs the structure, whose pressure under a
  /// steady load rises about 1.3 % per millimetre, while a valve stuck shut leaves it. Under a
  /// body a load that changes meanwhile can hold the pressure just as well, so the gas counted
  /// over the sum becomes the count's doubt and the cell is reported unverified until its gas
  /// is found again; 0: off (the default; 5 mm suits the model) [m].
  double progress_inlet_m = 0.0;
  /// The same for the vent (the pressure must fall): an estimate that followed a count down
  /// while the plate stayed is flagged before it is 6 mm off; 0: off [m].
  double progress_vent_m = 0.004;
  /// The least relative rise (fall) asked of that much counted gas: about 40 % of what 4 mm
  /// along the structure gives, room for a body load still settling from a step [-].
  double progress_rel = 0.02;
  /// Judged only where progress_rel of the pressure is at least this (a light plate's pressure
  /// hardly moves along the structure) [Pa].
  double progress_min_pa = 15.0;
  /// The valve's gas is summed over at most this long (a body's slow load changes move the
  /// pressure over longer spans) [s].
  double progress_window_s = 60.0;

  /// Success when valid, else an error with every problem found, separated by "; ".
  Status validate() const;
};

/// What one reading told the monitor.
struct ConsistencySample {
  double gauge_pressure_pa = 0.0;  ///< the raw reading [Pa]
  double noise_sd_pa = 10.0;       ///< the readings' sd as the observer has it [Pa]
  bool valves_shut = false;        ///< both valves shut over the period (the inputs acting)
  /// How far a correction of the observer's that does not prove the gas (a weight bound)
  /// moved the height in this period [m]; 0 without one.
  double correction_m = 0.0;
  /// The fixed-volume pressure change of the gas the observer counted through the valves in
  /// this period (gamma p dm / m: + inlet, - vent; 0 with both valves shut) [Pa].
  double counted_step_pa = 0.0;
  double load_n = 0.0;  ///< the observer's load estimate [N]
  /// Period of the plate (with its load) on its gas spring, 2 pi sqrt(M / k) with
  /// k = gamma p_abs A^2 / V, A the structure's dV/dh, at the observer's estimate; 0: unknown
  /// (plate on the bed) [s].
  double plate_period_s = 0.0;
  double inlet_opening = 0.0, vent_opening = 0.0;  ///< the valves acting over the period (0..1) [-]
  double height_m = 0.0;                           ///< the observer's height estimate [m]
  /// Mean gauge pressure under which the observer takes a cell with its inlet shut for flat
  /// (CellObserver::flatPressure); 0: unknown, the landed test off [Pa].
  double flat_pressure_pa = 0.0;
  /// The gas the observer counted through the one valve acting in this period (0 with both or
  /// neither, or where a re-anchor set the gas) [kg], and how far it would move the plate at
  /// fixed pressure, V dm / (m dV/dh) [m].
  double counted_gas_kg = 0.0;
  double counted_height_m = 0.0;
};

/// One job: the sensor's own signature in its raw readings, whatever the plate does: the same
/// reading for frozen_s (a live sensor's noise and ADC step change it every few readings), or a
/// jump of more than jump_pa under a settled plate that the next reading holds (a load's step
/// keeps the plate moving over a quarter of its gas-spring period).
class SensorSignatureCheck {
 public:
  /// One reading; `settled`: both valves shut settle_s before it. Returns a non-empty reason
  /// for a frozen or jumped sensor.
  std::string update(double reading_pa, bool settled, double noise_sd_pa, double dt_s,
                     const ConsistencyMonitorParams& params);
  void restart();

 private:
  double last_pa_ = 0.0;  ///< the last reading [Pa]
  bool have_last_ = false;
  double same_for_s_ = 0.0;                       ///< the raw reading unchanged this long [s]
  bool jump_pending_ = false;                     ///< the last reading jumped (judged on this one)
  double jump_from_pa_ = 0.0, jump_to_pa_ = 0.0;  ///< that jump's readings [Pa]
};

/// One job: whether the readings over a recent span lay within a band (a plate at rest under a
/// load that is not changing).
class SteadyReadings {
 public:
  void add(double reading_pa, double dt_s);
  /// Whether readings cover the last `span_s` and lay within `range_pa` of each other there.
  bool within(double span_s, double range_pa) const;
  void clear();

 private:
  static constexpr int kReadings = 512;  ///< 0.5 s at 1 kHz
  std::array<double, kReadings> p_{}, dt_{};
  int next_ = 0, count_ = 0;
};

/// One job: the largest fixed-volume step a pulse counted within a quarter of the plate's swing
/// on its gas spring. Gas counted faster than the plate can move shows in the pressure; a slow
/// flow (a long, partly open vent) the plate takes up as it comes, its pressure held by the load.
class QuarterSwingSum {
 public:
  /// A pulse begins on a plate swinging with `plate_period_s`.
  void start(double plate_period_s);
  /// One period of the pulse, its counted step (either sign) [Pa].
  void add(double step_pa, double dt_s);
  double largestPa() const { return largest_pa_; }  ///< the largest |sum| so far [Pa]

 private:
  static constexpr int kSteps = 64;
  std::array<double, kSteps> step_pa_{}, dt_s_{};
  int next_ = 0, count_ = 0;
  double quarter_s_ = 0.0;
  double largest_pa_ = 0.0;
};

/// One job: whether a valve that was counted to pass gas moved the pressure at all. A valve
/// stuck shut passes nothing, so the readings stay within their noise where a working one
/// moves them by hundreds of pascals (even a light plate, which takes the gas up at once,
/// moves its pressure along the structure). Judged per pulse of one direction, and summed over
/// one valve's silent pulses in a row; an inlet held open (a move's full flow) is judged while
/// still open, once it is worth a single silent pulse.
class ValveResponseCheck {
 public:
  /// One period; returns a non-empty reason when a judged pulse had no response.
  std::string update(const ConsistencySample& sample, double dt_s, const ConsistencyMonitorParams& params);
  void restart();

 private:
  static constexpr int kPre = 10;    ///< readings averaged before a pulse
  static constexpr int kRecent = 4;  ///< readings averaged for the response
  std::array<double, kPre> pre_{};   ///< the last readings (ring)
  int pre_count_ = 0, pre_next_ = 0;
  std::array<double, kRecent> recent_{};
  int direction_ = 0;          ///< the pulse under way: +1 inlet, -1 vent, 0 none
  double baseline_pa_ = 0.0;   ///< mean reading before the pulse
  double counted_pa_ = 0.0;    ///< the pulse's fixed-volume change so far
  double best_pa_ = 0.0;       ///< largest move of the recent mean in its direction
  double after_s_ = 0.0;       ///< time since its counted flow ended
  double open_s_ = 0.0;        ///< time its valve has been counted open
  bool slow_enough_ = false;   ///< its plate swings slowly enough to show the gas
  SteadyReadings steady_;      ///< the readings before each pulse
  bool steady_start_ = false;  ///< the pulse under way began on steady readings
  QuarterSwingSum quarter_;    ///< the pulse's gas counted within a quarter swing
  /// One valve's judged pulses in a row without a response.
  struct SilentRun {
    double worth_pa = 0.0;  ///< their counted change summed [Pa]
    int pulses = 0;         ///< how many they were
  };
  std::array<SilentRun, 2> silent_{};  ///< [0] inlet, [1] vent
  /// Whether the pulse so far can show its valve working: worth response_min_pa, on a plate
  /// slow enough, a vent with room above ambient, and readings not held against it.
  bool judgeable(double needed_pa, const ConsistencyMonitorParams& params) const;
  /// The verdict on the pulse that just ended; non-empty when its valve's run of silent pulses
  /// shows the valve stuck shut.
  std::string judge(double noise_sd_pa, const ConsistencyMonitorParams& params);
  /// The verdict on an inlet pulse still under way: non-empty when it is worth a single silent
  /// pulse, has been open the response window and has not moved the readings.
  std::string judgeOpenInlet(double noise_sd_pa, const ConsistencyMonitorParams& params) const;
  /// The reason given for a valve stuck shut.
  std::string stuckShut(double worth_pa, int pulses, double needed_pa) const;
  /// Whether the silent pulse, worth `counted_pa`, shows its valve stuck shut alone: worth
  /// response_single_pa, or from steady readings response_steady_single_pa within a quarter swing
  /// (a vent with room above ambient for it).
  bool aloneShowsStuck(double counted_pa, const ConsistencyMonitorParams& params) const;
};

/// One job: failure to reach target. The gas counted through each valve is summed over its
/// pulses (the other valve's opening ends the sum); 0.1 s after it is worth its limit in height
/// (or when the other valve opens after that), the pressure's mean must have moved its way (at
/// its furthest) by progress_rel of its mean before the first pulse.
class ValveProgressCheck {
 public:
  /// One period; returns a non-empty reason when a valve's summed opening did not move the pressure.
  std::string update(const ConsistencySample& sample, double dt_s, const ConsistencyMonitorParams& params);
  void restart();
  /// The gas counted through the valves of the windows judged failures since the last call [kg].
  double takeDoubtKg();
  /// How many windows have been judged failures, and why the last one was.
  int failures() const { return failures_; }
  const std::string& lastFailure() const { return last_failure_; }

 private:
  /// A window is judged this long after its gas reached the limit (a few of the plate's swings
  /// on its gas spring, twice the readings' mean time) [s].
  static constexpr double kSettleS = 0.1;
  struct Window {
    bool active = false;
    double open_s = 0.0;     ///< the valve's opening summed over the window [s]
    double height_m = 0.0;   ///< the height its counted gas is worth, summed [m]
    double span_s = 0.0;     ///< the window's length [s]
    double start_pa = 0.0;   ///< the mean pressure before its first pulse [Pa]
    double best_pa = 0.0;    ///< the furthest the mean moved its way since [Pa]
    double gas_kg = 0.0;     ///< the gas counted through the valve over the window [kg]
    double reached_s = 0.0;  ///< time since its gas reached the limit [s]
  };
  /// Sums one valve's opening (and the gas counted through it); judges its window once it has
  /// run long enough and settled.
  std::string step(Window* w, int direction, double opening, const ConsistencySample& sample, double limit_m,
                   double dt_s, const ConsistencyMonitorParams& params);
  /// The other valve opened: a window whose sum reached its limit kSettleS ago is judged, any
  /// other dropped.
  std::string endWindow(Window* w, int direction, double limit_m, const ConsistencyMonitorParams& params);
  /// The verdict on a window that reached its limit (the window ends).
  std::string judge(Window* w, int direction, const ConsistencyMonitorParams& params);
  Window inlet_, vent_;
  double mean_pa_ = 0.0;  ///< the readings' running mean [Pa]
  bool have_mean_ = false;
  double doubt_kg_ = 0.0;  ///< failed windows' gas not yet taken [kg]
  int failures_ = 0;
  std::string last_failure_;
};

/**
 * Eight tests:
 *  - frozen: the raw reading unchanged for frozen_s (SensorSignatureCheck);
 *  - jump: a settled plate's reading moves more than jump_pa from one reading to the next and
 *    the next reading stays there (SensorSignatureCheck; the controller's answer to the jump
 *    acts only after the valves' dead time, so a test over longer would see only its response);
 *  - innovation: while both valves are shut and the plate settled, the pressure predicted is
 *    the hold's running mean (nothing moves gas, so a plate held by a steady load keeps its
 *    pressure); a two-sided CUSUM of the reading's departure from it beyond the noise
 *    (Page's test, in Pa s) crosses cusum_threshold_pa_s on a persistent step (an offset
 *    sensor, a sudden leak or valve flow under a settled plate, a terminal that restarted);
 *  - surprise: a correction of the observer's that does not prove the gas (a weight bound)
 *    larger than surprise_m: the estimate was that far wrong.
 *  - response: a valve's pulses, each counted to move the pressure by response_min_pa at fixed
 *    volume, none moving the readings by response_sds: one worth response_single_pa (or, after
 *    steady readings, response_steady_single_pa within a quarter of the plate's swing), or
 *    response_silent_pulses or more worth response_silent_sum_pa in all (ValveResponseCheck):
 *    a valve stuck shut;
 *  - load: the observer's load estimate above max_load_n (gas passing a shut valve);
 *  - landed: the readings flat (below the observer's flat pressure) under an estimate
 *    above landed_height_m (gas gone uncounted);
 *  - progress: a valve counted open long enough, over its pulses, without the pressure
 *    moving its way (ValveProgressCheck): failure to reach target, a valve stuck shut, or a
 *    load that grew meanwhile; the gas counted through it is doubted (takeDoubtKg), the cell
 *    not made inconsistent.
 * Once inconsistent it stays so until clear() (the cell's gas re-verified).
 */
class ConsistencyMonitor {
 public:
  /// Throws std::invalid_argument naming what is wrong in `params`.
  explicit ConsistencyMonitor(const ConsistencyMonitorParams& params = {});
  const ConsistencyMonitorParams& params() const { return params_; }

  /// One period of `dt_s`: true when this reading made the cell inconsistent.
  bool update(const ConsistencySample& sample, double dt_s);
  /// A period without readings (a lost link): the tests start again.
  void interrupt();
  /// The gas was re-verified: consistent again, the tests from the start.
  void clear();

  bool inconsistent() const { return !reason_.empty(); }
  /// Why the cell is inconsistent ("" when it is not).
  const std::string& reason() const { return reason_; }
  /// The larger of the two CUSUMs now [Pa s].
  double cusum() const;
  /// Gas whose count the readings did not bear out (the progress test) since the last call [kg].
  double takeDoubtKg() { return progress_.takeDoubtKg(); }
  const ValveProgressCheck& progress() const { return progress_; }

 private:
  bool innovation(const ConsistencySample& sample, double dt_s);
  /// The landed test: the readings' running mean over landed_time_s flat under a lifted estimate.
  bool landed(const ConsistencySample& sample, double dt_s);

  ConsistencyMonitorParams params_;
  SensorSignatureCheck sensor_;
  ValveResponseCheck response_;
  ValveProgressCheck progress_;
  std::string reason_;
  double shut_for_s_ = 0.0;    ///< both valves shut this long [s]
  double reference_pa_ = 0.0;  ///< the hold's running mean (valid once the plate settled)
  bool have_reference_ = false;
  double up_pa_s_ = 0.0, down_pa_s_ = 0.0;  ///< the two CUSUMs [Pa s]
  double landed_mean_pa_ = 0.0;             ///< the readings' running mean for the landed test [Pa]
  double landed_for_s_ = -1.0;              ///< flat under a lifted estimate this long; < 0: no mean yet [s]
};

}  // namespace nursing_bed
