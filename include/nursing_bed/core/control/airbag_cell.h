// One airbag cell as a bed runs it: the control side (height or pressure controller, safety
// layer, and the height observer where the hardware has no height sensor) over a cell hardware
// (CellHardware): the simulated plant and its sensors by default, a real valve terminal
// otherwise. ROS-free; the airbag node and nodelet wrap it.
#pragma once

#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "nursing_bed/core/control/gas_verifier.h"
#include "nursing_bed/core/control/height_controller.h"
#include "nursing_bed/core/control/pressure_mode_controller.h"
#include "nursing_bed/core/control/safety_layer.h"
#include "nursing_bed/core/hardware/simulated_cell_hardware.h"
#include "nursing_bed/core/observer/cell_observer.h"
#include "nursing_bed/core/observer/consistency_monitor.h"

namespace nursing_bed {

struct AirbagCellParams {
  CellParams cell;
  HeightControllerParams controller;
  AirbagSafetyParams safety;
  double control_period_s = 0.005;  ///< controller and safety period [s]
  /// Gauge pressure the vents see while venting for CPR (vent mode): a vacuum source empties a
  /// cell that carries only its plate in seconds instead of half a minute; 0: vent to ambient.
  double cpr_vacuum_pa = -5000.0;
  double pressure_noise_pa = 0.0;  ///< sd of the pressure sensor's noise [Pa]
  double height_noise_m = 0.0;     ///< sd of the height sensor's noise [m]
  std::uint32_t noise_seed = 1;
  std::string validate() const;
};

enum class AirbagMode : std::uint8_t { kIdle = 0, kHeight = 1, kVent = 2, kSafe = 3, kPressure = 4 };

/// Fault bits (the AirbagState message's FAULT_ constants).
enum AirbagFault : std::uint32_t {
  kFaultNone = 0,
  kFaultSensor = 1,
  kFaultOverpressure = 2,
  kFaultCommandTimeout = 4,
  kFaultLowPressure = 8,
  /// The plant's solve failed or left an invalid state (the hardware reported
  /// CellReadings::device_reset): the cell was reset (flat, valves shut), mode SAFE.
  kFaultModel = 16,
  kFaultCommunication = 32,  ///< the hardware link is down: valves not commanded, setpoint kept
  /// The readings persistently disagree with the observer (ConsistencyMonitor): the gas is
  /// found again (vented flat) before the cell is inflated; cleared once it is.
  kFaultInconsistent = 64,
};

/// Where AirbagCell's height comes from (the AirbagState message's HEIGHT_ constants).
enum class HeightSource : std::uint8_t { kMeasured = 0, kEstimated = 1 };

/// The observer of a cell without a height sensor: its tuning and its model (a calibrated
/// parameter set and the effects diagnosed for the bed, else the nominal cell).
struct AirbagObserverSetup {
  CellObserverParams params;
  GasVerifierParams gas_check;       ///< the cell's checks of the observer's gas (keys under observer/)
  ConsistencyMonitorParams monitor;  ///< the readings against the observer (keys under observer/monitor_)
  CellParams model;
  std::vector<CellEffectPtr> effects;
  bool force = false;  ///< run it (and report its height) even when a height sensor is fitted
};

/// One cell's mode and the wiring of its parts: the height controller, the pressure mode, the
/// safety layer, the gas check and the observer over the hardware.
/// Size: the airbag node's and the bed's whole interface to a cell (commands and state
/// queries, ~45 one-line methods) and the wiring's ~21 members; the logic lives in the parts.
class AirbagCell {
 public:
  /// The simulated cell (plant and sensors, `effects` hidden in the plant) run in lockstep with
  /// the control periods. Throws std::invalid_argument naming what is wrong in `params`.
  explicit AirbagCell(const AirbagCellParams& params, const std::vector<CellEffectPtr>& effects = {});
  /// A configured hardware. A SimulatedCellHardware is run in lockstep like the above; any
  /// other is real: one control period per advanceTo() call at its time. The observer runs when
  /// the hardware has no height sensor (or `observer.force`).
  AirbagCell(const AirbagCellParams& params, CellHardwarePtr hardware, const AirbagObserverSetup& observer);

  /// Flat cell, plate on the bed, valves shut, idle; time 0.
  void reset(double load_n);
  /// Plate at rest at `height_m` holding that height.
  void resetToHeight(double height_m, double load_n);

  /// Empty when `height_m` is a valid setpoint now, else why not (nothing changes then); while
  /// bed-wide CPR runs every height is refused.
  std::string checkHeight(double height_m) const;
  /// Sets the height setpoint at time `now_s`; returns checkHeight's message (empty: done).
  std::string requestHeight(double height_m, double now_s);
  /// Empty when `pressure_pa` is a valid gauge pressure setpoint, else why not.
  std::string checkPressure(double pressure_pa) const;
  /// Pressure setpoint mode (how therapy mattresses are run); a height request ends it.
  std::string requestPressure(double pressure_pa, double now_s);
  /// Vents the cell as fast as the vent allows (CPR); a height request ends it.
  void requestVent(double now_s);
  /// Bed-wide CPR: while on, the cell vents and refuses every height (nothing inflates it);
  /// switched off, it holds its gas (idle) until a height is requested.
  void setCpr(bool on, double now_s);
  bool cpr() const { return cpr_; }

  /// Empty when `load_n` is a load the cell accepts (finite, 0..safety.max_load_n), else why not.
  std::string checkLoad(double load_n) const;
  /// Sets the external load (the simulated plant's; real hardware: the observer estimates it);
  /// returns checkLoad's message (empty: done, else nothing changes).
  std::string setLoad(double load_n);
  /// Keeps the command watchdog alive without changing the setpoint.
  void heartbeat(double now_s);
  /// Changes safety.command_timeout_s (0: off); the watchdog counts from the last command.
  /// Returns why not (and changes nothing) when it is negative or not a number.
  std::string setCommandTimeout(double timeout_s);
  /// Replaces the height controller's gains, bands and limits (e.g. dynamic reconfigure) and
  /// returns "", or returns why not and changes nothing (invalid, or max_pressure_pa not below
  /// the relief pressure). The setpoint is kept.
  std::string setControllerParams(const HeightControllerParams& params);
  /// Replaces the safety thresholds (relief, sensor range, watchdog, load limit) and returns "",
  /// or returns why not and changes nothing (invalid, or the relief not above the controller's
  /// max_pressure_pa).
  std::string setSafetyParams(const AirbagSafetyParams& params);

  void setSupplyPressure(double pressure_pa);
  /// Test hook: the sensors fail (read NaN) while set; read again at once.
  void setSensorFailure(bool failed);

  /// Simulated: runs plant, sensors, safety and controller up to `now_s` in control periods.
  /// Real hardware: one control period at `now_s` (read, observe, control, write).
  void advanceTo(double now_s);

  double time() const { return time_s_; }
  /// The simulated plant's variables; on real hardware the observer's estimate of them.
  const CellVariables& variables() const;
  /// Last sensor readings (NaN after a sensor failure), taken at time(): at the end of the
  /// last control period, which is the start of the next (the controller acts on them there).
  /// Without a height sensor, height_m is the observer's estimate.
  const Readings& measurement() const { return measurement_; }
  /// Gas that the inlet's flow meter has counted since reset [kg] (a totaliser: its change over
  /// an interval divided by the interval is the mean metered inflow, which a sampled replay can
  /// integrate without losing the mass of valve switches between samples).
  double meteredInletMassKg() const { return totals_.metered_inlet_mass_kg; }
  /// Integrals of the valve openings over time since reset [s] (their change over an interval
  /// divided by it is the mean opening: a valve that switches every control period is recorded
  /// faithfully at a lower rate).
  double inletOpeningSeconds() const { return totals_.inlet_opening_s; }
  double ventOpeningSeconds() const { return totals_.vent_opening_s; }
  const ValveOpenings& valves() const { return valves_; }
  AirbagMode mode() const { return mode_; }
  std::uint32_t faults() const { return faults_; }
  double setpoint() const {
    return controller_.hasTarget() ? controller_.target() : std::numeric_limits<double>::quiet_NaN();
  }
  /// Gauge pressure setpoint in pressure mode [Pa] (NaN otherwise).
  double pressureSetpoint() const { return pressure_.setpoint(); }
  double loadEstimate() const { return controller_.loadEstimate(); }
  /// The simulated load; on real hardware the observer's estimate.
  double load() const;
  HeightSource heightSource() const { return use_estimate_ ? HeightSource::kEstimated : HeightSource::kMeasured; }
  /// Standard deviation of the reported height [m]: the sensor's noise, or the observer's with
  /// its count's doubt; infinite while the cell's gas is unproven.
  double heightSd() const;
  const AirbagCellParams& params() const { return params_; }
  const CellModel& model() const;
  const HeightController& controller() const { return controller_; }
  const CellHardware& hardware() const { return *hardware_; }
  /// The observer (null when the height is measured).
  const CellObserver* observer() const { return observer_.get(); }
  /// Reset over hardware without a height sensor and commanded before the observer found the
  /// cell flat: its gas is unknown, and it vents flat before it is controlled.
  bool findingGas() const { return gas_.findingGas(); }
  /// Lowered into the low band (gas check reanchor_below_m): venting flat so that the observer
  /// re-anchors its gas, the target kept; its height is still tracked.
  bool anchoringGas() const { return gas_.anchoringGas(); }
  /// Anchoring because the observer's vent count became doubtful (observer/recount_doubt_m).
  bool recountingGas() const { return gas_.recounting(); }
  /// The checks of the observer's gas (with their parameters).
  const GasVerifier& gasVerifier() const { return gas_; }
  /// The reported height is an estimate whose gas is not proven (a lost link not yet checked,
  /// an inconsistency, a reset over real hardware not yet found flat: the cell is never
  /// inflated meanwhile, only held or vented to find its gas) or whose vent count is doubtful
  /// (GasVerifierParams::flag_doubt_m: controlled, flagged until found flat).
  bool heightUnverified() const { return observer_ && use_estimate_ && gas_.unverified(); }
  /// The readings against the observer (null when the height is measured).
  const ConsistencyMonitor* monitor() const { return observer_ ? &monitor_ : nullptr; }

 private:
  void controlStep();
  /// The safety layer's sensor range check and watchdog on this period's readings: false when
  /// the readings hold the gas (valves shut, the period done).
  bool checkSensorsAndWatchdog(double now_s, double gauge_pressure_pa, double height_m);
  /// The valves the mode wants (the controller's `wanted` in height mode).
  ValveOpenings modeValves(const ValveOpenings& wanted, double gauge_pressure_pa) const;
  /// The safety layer's relief over the valves about to be written.
  void applyRelief(double gauge_pressure_pa);
  /// Adds one period of the valves (and the metered inflow) to the totals.
  void addTotals(double period_s, double inflow_kg_s);
  /// Simulated lockstep: one period of the plant with the valves just commanded.
  void stepSimulated();
  /// Real hardware: read, observe, control and write once at `now_s`.
  void stepReal(double now_s);
  /// The gas the observer counted since `before`, while the link or readings were unsure
  /// (unsure_count_until_s_) or over a period `dt_s` that ran late (kLatePeriods), goes to its
  /// count's doubt.
  void doubtUnsureCount(const CellEstimate& before, bool reanchored, double dt_s);
  /// Sets fresh_pressure_pa_: the reading, or NaN where its stamp says the driver repeated it
  /// after missing its bus cycles (older than a period, or over an unsure link).
  void notePressureSample(const StampedReading& pressure);
  /// Turns readings into measurement_ (the observer's height where there is no sensor); the
  /// observer's events go to the gas check.
  void observe(const CellReadings& readings, double dt_s = 0.0);
  /// observe() over the period from `from_s` to `now_s`; one that came late, in the steps the
  /// driver's bus samples give (busSampleSteps) where they cover it.
  void observePeriod(const CellReadings& readings, double from_s, double now_s);
  void onLink(const CellReadings& readings);
  /// The consistency monitor on this period's readings (`before`: the estimate before the
  /// observer's step); an inconsistency suspects the gas and flags the cell.
  void monitorStep(const ObserverEvents& events, const CellEstimate& before, double dt_s);
  /// The one valve the observer's last step counted gas through (+1 inlet, -1 vent, 0 none,
  /// both, or a re-anchor).
  int countedDirection(const ObserverEvents& events) const;
  /// The fixed-volume pressure change of the gas the observer counted through one valve in
  /// its last step (+ inlet, - vent, 0 none) [Pa].
  double countedStepPa(const ObserverEvents& events, const CellEstimate& before) const;
  /// The plate's period on its gas spring at the observer's estimate (0: unknown) [s].
  double platePeriod() const;
  /// The observer's inputs over a period with the link down.
  ObserverInputs linkDownInputs(const CellReadings& readings) const;
  /// The gas check's valve filters (GasVerifier) over the mode's valves, where an observer
  /// gives the gas.
  ValveOpenings gasCheckValves(double now_s, double gauge_pressure_pa, const ValveOpenings& wanted);
  ValveOpenings openings() const { return {valves_.inlet, valves_.vent, ventToVacuum()}; }
  /// CPR's vent goes to the vacuum source where the hardware has one, else to the atmosphere.
  bool ventToVacuum() const { return mode_ == AirbagMode::kVent && capabilities_.vent_vacuum; }
  void resetControl(double load_n);
  /// Takes a commanded mode (held for the link's return while it is down).
  void enterMode(AirbagMode mode);
  /// The mode a cleared fault returns to: pressure, height or idle by the setpoint held.
  AirbagMode resumedMode() const;
  /// The height readings' noise the controller's landing allows for [m]: the simulated
  /// sensor's, a fitted sensor's (the observer's setting), infinite for an estimate.
  double readingNoise() const;
  /// After the hardware reported a device reset (the simulated plant's failed solve, reset flat
  /// at rest by the hardware): controller target cleared, valves shut, mode SAFE, flag
  /// kFaultModel (cleared by the next height request, which starts from the fresh state).
  void onDeviceReset();

  AirbagCellParams params_;
  CellHardwarePtr hardware_;
  SimulatedCellHardware* sim_ = nullptr;  ///< hardware_ when it is the simulated plant
  std::unique_ptr<CellObserver> observer_;
  bool use_estimate_ = false;  ///< the reported height is the observer's
  AirbagMode mode_before_link_loss_ = AirbagMode::kIdle;
  HeightController controller_;
  double time_s_ = 0.0;
  double load_n_ = 0.6;
  PressureModeController pressure_;  ///< the pressure setpoint mode's law and setpoint
  /// Totals since construction (see meteredInletMassKg, inletOpeningSeconds).
  struct Totals {
    double metered_inlet_mass_kg = 0.0;
    double inlet_opening_s = 0.0, vent_opening_s = 0.0;
  };
  Totals totals_;
  double supply_pressure_pa_;
  AirbagMode mode_ = AirbagMode::kIdle;
  std::uint32_t faults_ = kFaultNone;
  ValveOpenings valves_;
  Readings measurement_{0.0, 0.0, 0.0, 0.0};  ///< zeros until the first reading
  bool cpr_ = false;
  HardwareCapabilities capabilities_;  ///< the hardware's, read once (they do not change)
  SafetyLayer safety_;                 ///< sensor range, command watchdog, relief
  GasVerifier gas_;                    ///< what the observer's gas is worth, and its checks
  ConsistencyMonitor monitor_;         ///< the readings against the observer's belief
  double recent_pressure_pa_ = std::numeric_limits<double>::quiet_NaN();  ///< readings, filtered
  /// The pressure reading as information: NaN where the driver repeated its last sample because
  /// no new one came (notePressureSample), which the observer and the tests must count once.
  double fresh_pressure_pa_ = std::numeric_limits<double>::quiet_NaN();
  double last_pressure_stamp_s_ = std::numeric_limits<double>::quiet_NaN();  ///< fresh_pressure_pa_'s stamp [s]
  double unmonitored_s_ = 0.0;  ///< periods of repeated samples since the monitor's last update [s]
  /// Gas counted until then is doubtful in full: a communication or sensor fault was flagged
  /// less than kUnsureCountS ago (a lossy link's writes and the terminal's watchdog) [s].
  double unsure_count_until_s_ = -std::numeric_limits<double>::infinity();
};

}  // namespace nursing_bed
