#include "nursing_bed/core/control/airbag_cell.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

#include "nursing_bed/core/control/bus_sample_replay.h"

namespace nursing_bed {

std::string AirbagCellParams::validate() const {
  std::ostringstream err;
  for (const std::string& e : {cell.validate(), controller.validate(), safety.validate()})
    if (!e.empty()) err << e << "; ";
  if (!(control_period_s > 0.0 && control_period_s <= 0.1)) err << "control_period_s must lie in (0, 0.1] s; ";
  if (!(pressure_noise_pa >= 0.0) || !(height_noise_m >= 0.0)) err << "sensor noise must be >= 0; ";
  if (!(cpr_vacuum_pa <= 0.0 && cpr_vacuum_pa > -0.5 * cell.ambient_pressure_pa))
    err << "cpr/vacuum_pa must lie in (-half an atmosphere, 0] Pa; ";
  if (controller.max_pressure_pa >= safety.relief_pressure_pa)
    err << "controller max_pressure_pa must be below the relief pressure; ";
  std::string s = err.str();
  if (s.size() >= 2) s.resize(s.size() - 2);
  return s;
}

namespace {
const AirbagCellParams& validated(const AirbagCellParams& p) {
  const std::string error = p.validate();
  if (!error.empty()) throw std::invalid_argument("airbag parameters: " + error);
  return p;
}
}  // namespace

namespace {

/// Gas counted this long after a communication or sensor fault is doubtful in full [s].
constexpr double kUnsureCountS = 0.5;
/// A real-time period longer than this many control periods ran late: it is observed in the
/// driver's bus samples where they cover it, and its gas is doubtful in full either way. Two
/// missed ticks, not a tick's jitter [-].
constexpr double kLatePeriods = 3.0;

CellHardwarePtr simulatedHardware(const AirbagCellParams& p, const std::vector<CellEffectPtr>& effects) {
  HardwareConfig c;
  c.control_period_s = p.control_period_s;
  c.cell = p.cell;
  c.effects = effects;
  c.cpr_vacuum_pa = p.cpr_vacuum_pa;
  c.pressure_noise_pa = p.pressure_noise_pa;
  c.height_noise_m = p.height_noise_m;
  c.noise_seed = p.noise_seed;
  auto hardware = std::make_shared<SimulatedCellHardware>();
  hardware->configure(c);
  return hardware;
}

}  // namespace

AirbagCell::AirbagCell(const AirbagCellParams& params, const std::vector<CellEffectPtr>& effects)
    : AirbagCell(params, simulatedHardware(validated(params), effects), AirbagObserverSetup{}) {}

AirbagCell::AirbagCell(const AirbagCellParams& params, CellHardwarePtr hardware, const AirbagObserverSetup& observer)
    : params_(validated(params)),
      hardware_(std::move(hardware)),
      controller_(params.controller, CellCharacteristic::shared(params.cell)),
      supply_pressure_pa_(params.cell.supply_pressure_pa),
      safety_(params_.safety),
      gas_(observer.gas_check),
      monitor_(observer.monitor) {
  if (!hardware_) throw std::invalid_argument("airbag: no cell hardware");
  sim_ = dynamic_cast<SimulatedCellHardware*>(hardware_.get());
  capabilities_ = hardware_->capabilities();  // fixed for the hardware's lifetime
  use_estimate_ = observer.force || !capabilities_.height;
  // Real hardware always has an observer: it is where gas mass, volume and load come from.
  if (use_estimate_ || !sim_) {
    CellObserverParams op = observer.params;
    op.period_s = params_.control_period_s;
    observer_ = std::make_unique<CellObserver>(observer.model, op, observer.effects);
    // The valves act this late for the controller too: it counts the gas still in flight.
    controller_.setDeadTime(op.valve_dead_time_s);
  }
  reset(0.6);
}

void AirbagCell::resetControl(double load_n) {
  load_n_ = load_n;
  controller_.clearTarget();
  controller_.setLoadEstimate(load_n);
  mode_ = AirbagMode::kIdle;
  faults_ = kFaultNone;
  valves_ = ValveOpenings{};
  pressure_.clear();
  safety_.noteCommand(0.0);
  safety_.setLastPressure(0.0);
  time_s_ = 0.0;
  gas_.reset(true);
  monitor_.clear();
  recent_pressure_pa_ = std::numeric_limits<double>::quiet_NaN();
}

void AirbagCell::reset(double load_n) {
  resetControl(load_n);
  if (sim_) sim_->reset(load_n);
  if (observer_) observer_->reset(load_n);
  if (sim_) observe(sim_->read(0.0));
  // Real hardware keeps its gas through a reset (a node restarted over an inflated bed): the
  // observer's flat start holds once its re-anchor test finds the cell flat (half a second of
  // readings, not one: a flat cell reads an ADC step or two of noise, the plate alone lifted
  // 20-75 Pa). A height sensor measures the gas.
  if (observer_ && !sim_ && use_estimate_) gas_.reset(false);
}

void AirbagCell::resetToHeight(double height_m, double load_n) {
  resetControl(load_n);
  if (sim_) sim_->resetToHeight(height_m, load_n);
  if (observer_) observer_->resetToHeight(height_m, load_n);
  controller_.setTarget(height_m);
  mode_ = AirbagMode::kHeight;
  if (sim_) observe(sim_->read(0.0));
  safety_.setLastPressure(measurement_.gauge_pressure_pa);
}

std::string AirbagCell::checkLoad(double load_n) const { return safety_.checkLoad(load_n); }

std::string AirbagCell::setCommandTimeout(double timeout_s) {
  AirbagSafetyParams safety = safety_.params();
  safety.command_timeout_s = timeout_s;
  return setSafetyParams(safety);
}

std::string AirbagCell::setControllerParams(const HeightControllerParams& params) {
  AirbagCellParams all = params_;
  all.controller = params;
  std::string error = all.validate();
  if (error.empty()) error = controller_.setParams(params);
  if (error.empty()) params_ = all;
  return error;
}

std::string AirbagCell::setSafetyParams(const AirbagSafetyParams& params) {
  AirbagCellParams all = params_;
  all.safety = params;
  std::string error = all.validate();
  if (error.empty()) error = safety_.setParams(params);
  if (error.empty()) params_ = all;
  return error;
}

std::string AirbagCell::setLoad(double load_n) {
  std::string error = checkLoad(load_n);
  if (!error.empty()) return error;
  load_n_ = load_n;
  if (sim_) sim_->setLoad(load_n);
  return "";
}

void AirbagCell::setSensorFailure(bool failed) {
  if (!sim_) return;
  sim_->setSensorFailure(failed);
  measurement_.gauge_pressure_pa = sim_->measurement().gauge_pressure_pa;
  if (!use_estimate_) measurement_.height_m = sim_->measurement().height_m;
}

const CellVariables& AirbagCell::variables() const { return sim_ ? sim_->variables() : observer_->variables(); }
const CellModel& AirbagCell::model() const { return sim_ ? sim_->model() : observer_->model(); }
double AirbagCell::load() const { return sim_ ? load_n_ : observer_->estimate().load_n; }

double AirbagCell::heightSd() const {
  if (!use_estimate_) return params_.height_noise_m;
  if (gas_.unproven()) return std::numeric_limits<double>::infinity();  // finding its gas included
  const CellEstimate e = observer_->estimate();
  return std::hypot(e.height_sd_m, e.count_doubt_m);
}

double AirbagCell::readingNoise() const {
  // An estimate's error is correlated, its speed the observer's model's own: no landing on it.
  if (use_estimate_) return std::numeric_limits<double>::infinity();
  return sim_ || !observer_ ? params_.height_noise_m : observer_->params().height_noise_m;
}

AirbagMode AirbagCell::resumedMode() const {
  if (pressure_.active()) return AirbagMode::kPressure;
  return controller_.hasTarget() ? AirbagMode::kHeight : AirbagMode::kIdle;
}

std::string AirbagCell::checkHeight(double height_m) const {
  if (cpr_) return "CPR is running (bed-wide): no cell is inflated until it ends";
  return controller_.checkSetpoint(height_m);
}

std::string AirbagCell::requestHeight(double height_m, double now_s) {
  const std::string error = checkHeight(height_m);
  if (!error.empty()) return error;
  controller_.setTarget(height_m);
  if (use_estimate_) gas_.heightRequested(height_m, measurement_.height_m);
  pressure_.clear();
  enterMode(AirbagMode::kHeight);
  faults_ &= ~(kFaultCommandTimeout | kFaultModel);
  safety_.noteCommand(now_s);
  return "";
}

void AirbagCell::setCpr(bool on, double now_s) {
  if (on) requestVent(now_s);
  else if (cpr_ && mode_ == AirbagMode::kVent) mode_ = AirbagMode::kIdle;
  else if (cpr_ && (faults_ & kFaultCommunication) && mode_before_link_loss_ == AirbagMode::kVent)
    mode_before_link_loss_ = AirbagMode::kIdle;
  cpr_ = on;
}

void AirbagCell::enterMode(AirbagMode mode) {
  // With the link down nothing is commanded: the cell stays SAFE and takes the mode when the
  // link is back (onLink).
  if (faults_ & kFaultCommunication) mode_before_link_loss_ = mode;
  else mode_ = mode;
}

std::string AirbagCell::checkPressure(double pressure_pa) const {
  if (cpr_) return "CPR is running (bed-wide): no cell is inflated until it ends";
  if (std::isfinite(pressure_pa) && pressure_pa >= 0.0 && pressure_pa <= params_.controller.max_pressure_pa) return "";
  std::ostringstream msg;
  msg << "pressure setpoint " << pressure_pa << " Pa is outside [0, " << params_.controller.max_pressure_pa
      << "] Pa (controller/max_pressure_pa)";
  return msg.str();
}

std::string AirbagCell::requestPressure(double pressure_pa, double now_s) {
  const std::string error = checkPressure(pressure_pa);
  if (!error.empty()) return error;
  controller_.clearTarget();
  gas_.pressureRequested();  // a pressure is held from where the cell is
  pressure_.setSetpoint(pressure_pa);
  enterMode(AirbagMode::kPressure);
  faults_ &= ~(kFaultCommandTimeout | kFaultModel);
  safety_.noteCommand(now_s);
  return "";
}

void AirbagCell::requestVent(double now_s) {
  controller_.clearTarget();
  pressure_.clear();
  enterMode(AirbagMode::kVent);
  faults_ &= ~kFaultCommandTimeout;
  safety_.noteCommand(now_s);
}

void AirbagCell::heartbeat(double now_s) {
  safety_.noteCommand(now_s);
  if (faults_ & kFaultCommandTimeout) {
    faults_ &= ~kFaultCommandTimeout;
    if (mode_ == AirbagMode::kSafe && !(faults_ & (kFaultSensor | kFaultCommunication))) mode_ = resumedMode();
  }
}

void AirbagCell::setSupplyPressure(double pressure_pa) {
  supply_pressure_pa_ = pressure_pa;
  controller_.setSupplyPressure(pressure_pa);
  if (sim_) sim_->setSupplyPressure(pressure_pa);
}

void AirbagCell::advanceTo(double now_s) {
  if (!sim_) {
    stepReal(now_s);
    return;
  }
  while (sim_->time() + 0.5 * params_.control_period_s <= now_s) stepSimulated();
}

void AirbagCell::stepSimulated() {
  const double period = params_.control_period_s;
  controlStep();
  hardware_->write(openings(), time_s_);
  // The plant runs one period with these valves and is read at its end: what is published
  // with this time is the state at this time.
  const CellReadings readings = sim_->read(sim_->time() + period);
  if (readings.device_reset) {
    // The plant's solve failed and the simulated hardware reset it flat at rest.
    time_s_ = sim_->time();
    onDeviceReset();
    observe(readings);
    return;
  }
  // The simulated meter reads the period's mean flow (it totalises): exact for the period.
  addTotals(period, readings.inflow_kg_s.value);
  time_s_ = sim_->time();
  observe(readings);
}

void AirbagCell::stepReal(double now_s) {
  // The real time since the last period: a loaded machine's ticks run late, and the valves
  // kept their command meanwhile (the observer must integrate all of it).
  const double period = std::clamp(now_s - time_s_, 1e-4, 0.5);
  const double from_s = now_s - period;
  const CellReadings readings = hardware_->read(now_s);
  time_s_ = now_s;
  onLink(readings);
  if (readings.device_reset) onDeviceReset();
  if (faults_ & kFaultCommunication) {
    // Nothing is commanded while the link is down; the observer coasts with what the terminal
    // still drove (its outputs hold until its watchdog) where the driver knows it, else with
    // the last command over the period it acted, then with the valves shut.
    const CellEstimate before = observer_->estimate();
    observer_->predict(linkDownInputs(readings), period);
    doubtUnsureCount(before, false, period);
    valves_ = ValveOpenings{};
    controller_.noteWritten(valves_, period);  // nothing sent: nothing in flight once the link is back
    measurement_.gauge_pressure_pa = readings.gauge_pressure_pa.value;
    return;
  }
  observePeriod(readings, from_s, now_s);
  controlStep();
  hardware_->write(openings(), now_s);
  addTotals(period, readings.inflow_kg_s.present() ? readings.inflow_kg_s.value : 0.0);
}

void AirbagCell::observePeriod(const CellReadings& readings, double from_s, double now_s) {
  // A late period is observed as the periods the loop missed, where the driver's bus cycles
  // cover it. Its gas stays the count's doubt: on a starved bed such counts still came out
  // tens of millimetres off in some runs, the cause not traced (doc/real_bed.md, "Soak").
  const double late_s = kLatePeriods * params_.control_period_s;
  const std::vector<ReplayStep> steps = now_s - from_s > late_s
                                            ? busSampleSteps(readings, from_s, now_s, params_.control_period_s, late_s)
                                            : std::vector<ReplayStep>{};
  if (steps.empty()) {
    observe(readings, now_s - from_s);
    return;
  }
  const CellEstimate before = observer_ ? observer_->estimate() : CellEstimate{};
  for (const ReplayStep& step : steps) {
    time_s_ = step.end_s;
    observe(step.readings, step.dt_s);
  }
  time_s_ = now_s;
  // Within the unsure window the steps doubted their gas already.
  const CellEstimate after = observer_ ? observer_->estimate() : CellEstimate{};
  if (observer_ && time_s_ >= unsure_count_until_s_ && after.reanchors == before.reanchors)
    observer_->doubtCount(std::fabs(after.mass_kg - before.mass_kg));
}

void AirbagCell::addTotals(double period_s, double inflow_kg_s) {
  totals_.metered_inlet_mass_kg += inflow_kg_s * period_s;
  totals_.inlet_opening_s += valves_.inlet * period_s;
  totals_.vent_opening_s += valves_.vent * period_s;
}

ObserverInputs AirbagCell::linkDownInputs(const CellReadings& readings) const {
  ObserverInputs in;
  in.valves.inlet = readings.inlet_driven.present() ? readings.inlet_driven.value : valves_.inlet;
  in.valves.vent = readings.vent_driven.present() ? readings.vent_driven.value : valves_.vent;
  in.supply_pressure_pa = supply_pressure_pa_;
  return in;
}

ValveOpenings AirbagCell::gasCheckValves(double now_s, double gauge_pressure_pa, const ValveOpenings& wanted) {
  if (!observer_) return wanted;  // the gas is measured (no observer: nothing to check)
  const double period = params_.control_period_s;
  const ValveOpenings checked = gas_.linkCheckValves(now_s, period, gauge_pressure_pa, observer_.get(), wanted);
  bool found_after_vent = false;
  const ValveOpenings valves = gas_.findingValves(period, observer_.get(), checked, &found_after_vent);
  // Its integral ran on the flat start's error through the vent: restart it.
  if (found_after_vent && controller_.hasTarget()) controller_.setTarget(controller_.target());
  // The safe band of an unproven estimate: held or vented, never inflated.
  if (use_estimate_ && gas_.gasUnknown()) return ValveOpenings{0.0, valves.vent, valves.vent_to_vacuum};
  return valves;
}

void AirbagCell::onDeviceReset() {
  controller_.clearTarget();
  pressure_.clear();
  valves_ = ValveOpenings{};
  mode_ = AirbagMode::kSafe;
  faults_ |= kFaultModel;
  safety_.setLastPressure(0.0);
  // The cell is in its reset state (flat): the observer starts from there too.
  if (observer_) observer_->reset(sim_ ? load_n_ : observer_->estimate().load_n);
  // A real device reset may have kept gas: the flat start holds once the cell is found flat.
  if (observer_ && !sim_ && use_estimate_) gas_.suspect();
}

void AirbagCell::onLink(const CellReadings& readings) {
  const bool down = readings.link == LinkState::kDown;
  if (down && !(faults_ & kFaultCommunication)) {
    faults_ |= kFaultCommunication;
    mode_before_link_loss_ = mode_;
    mode_ = AirbagMode::kSafe;
    gas_.linkLost(recent_pressure_pa_);
    monitor_.interrupt();
  } else if (!down && (faults_ & kFaultCommunication)) {
    faults_ &= ~kFaultCommunication;
    // The observer keeps its gas: the terminal's watchdog shut the valves, so the gas is what
    // it was. A cell found flat (a restarted rig, a bed vented meanwhile) is re-anchored by the
    // observer's own test (its mean pressure that low for reanchor_time_s, inlet shut). Reset
    // on one reading below reanchor_pressure_pa instead, a light plate resting at 55-75 Pa
    // was taken for flat after a 50 ms bus timeout and filled to the bag's top at 30 kPa.
    mode_ = mode_before_link_loss_ == AirbagMode::kSafe ? resumedMode() : mode_before_link_loss_;
    gas_.linkRestored(time_s_);
  }
}

void AirbagCell::observe(const CellReadings& readings, double dt_s) {
  measurement_ = readingsOf(readings);
  notePressureSample(readings.gauge_pressure_pa);
  if (!observer_ || (sim_ && !use_estimate_)) return;
  ObserverInputs in;
  // What the driver applied where it says (PWM pulses), else what was commanded.
  in.valves.inlet = readings.inlet_driven.present() ? readings.inlet_driven.value : valves_.inlet;
  in.valves.vent = readings.vent_driven.present() ? readings.vent_driven.value : valves_.vent;
  // The vent's outlet as the hardware has it (a bed without a vacuum source vents to the air:
  // modelled with the vacuum, a vented cell's estimate fell 2.5 times too fast, 40 mm off).
  in.vent_back_pressure_pa = ventToVacuum() ? params_.cpr_vacuum_pa : 0.0;
  in.supply_pressure_pa = supply_pressure_pa_;
  if (readings.supply_pressure_pa.present()) in.measured_supply_pa = readings.supply_pressure_pa.value;
  // The height sensor is left out where the estimate stands for it, the simulated plant's
  // inflow (its flows are the observer's own model) and any hardware's without a flow meter.
  Readings z = measurement_;
  z.gauge_pressure_pa = fresh_pressure_pa_;
  if (use_estimate_) z.height_m = std::numeric_limits<double>::quiet_NaN();
  if (!capabilities_.inflow || sim_) z.inflow_kg_s = std::numeric_limits<double>::quiet_NaN();
  const CellEstimate before = observer_->estimate();
  // A repeated sample is no new evidence, nor the gap of a lost link: the tests pause.
  const bool repeated = std::isnan(fresh_pressure_pa_) && !std::isnan(measurement_.gauge_pressure_pa);
  const bool coasting = repeated && !std::isfinite(z.height_m);
  ObserverEvents events;
  if (coasting) observer_->coast(in, dt_s);
  else events = observer_->step(in, z, dt_s);
  doubtUnsureCount(before, events.reanchored, dt_s);
  gas_.note(events);
  if (use_estimate_) {
    const CellEstimate e = observer_->estimate();
    gas_.noteCountDoubt(e.count_doubt_m, e.load_n);
    measurement_.height_m = e.height_m;
  }
  const double period_s = dt_s > 0.0 ? dt_s : params_.control_period_s;
  if (sim_) return;
  if (coasting) {
    unmonitored_s_ += period_s;
    return;
  }
  // As the flat test: a sample stands for at most a few periods.
  monitorStep(events, before,
              std::min(period_s + unmonitored_s_, ReanchorDetector::kSampleCreditPeriods * params_.control_period_s));
  unmonitored_s_ = 0.0;
}

void AirbagCell::notePressureSample(const StampedReading& pressure) {
  // A driver whose read requests go unanswered repeats its last sample, with that sample's
  // stamp, until a new one comes. Taken again every period, one noisy reading of a light
  // plate's 20 Pa repeated for 0.2 s read as a flat cell and re-anchored a plate lifted 20-35 mm.
  // A stamp within clock jitter of the last one is the same sample; it counts once where it is
  // older than a period (the bus missed its cycles) or the link is unsure (a communication
  // fault now or within kUnsureCountS). On a steady link a period that comes early may find its
  // sample again: one sample more, where taken as none it would restart the observer's tests.
  constexpr double kSameSampleS = 1e-3;
  const bool repeated = std::isfinite(pressure.stamp_s) && std::isfinite(last_pressure_stamp_s_) &&
                        std::fabs(pressure.stamp_s - last_pressure_stamp_s_) < kSameSampleS;
  const bool missed = time_s_ - pressure.stamp_s > params_.control_period_s || time_s_ < unsure_count_until_s_;
  fresh_pressure_pa_ = repeated && missed ? std::numeric_limits<double>::quiet_NaN() : pressure.value;
  if (pressure.present()) last_pressure_stamp_s_ = pressure.stamp_s;
}

void AirbagCell::doubtUnsureCount(const CellEstimate& before, bool reanchored, double dt_s) {
  // Over a lost or lossy link (and stale readings) the count follows a record of the valves
  // that a dropped write or a tripped watchdog can leave wrong, while the checks after it only
  // show that the cell kept its gas: what was counted meanwhile is the count's doubt. So is
  // the gas of a period that ran late (a starved thread): its valves acted for all of it, but
  // their flows are taken at its end's reading, through a swing of the plate it never saw
  // (observePeriod doubts one counted from the bus cycles alike).
  if (faults_ & (kFaultCommunication | kFaultSensor)) unsure_count_until_s_ = time_s_ + kUnsureCountS;
  const bool late = dt_s > kLatePeriods * params_.control_period_s;
  if ((late || time_s_ < unsure_count_until_s_) && !reanchored)
    observer_->doubtCount(std::fabs(observer_->estimate().mass_kg - before.mass_kg));
}

int AirbagCell::countedDirection(const ObserverEvents& events) const {
  // One valve at a time (a step that also re-anchored the mass is no count of the valves).
  const ValveOpenings& v = observer_->appliedInputs().valves;
  if (events.reanchored) return 0;
  return v.inlet > 0.0 && v.vent == 0.0 ? 1 : (v.vent > 0.0 && v.inlet == 0.0 ? -1 : 0);
}

double AirbagCell::countedStepPa(const ObserverEvents& events, const CellEstimate& before) const {
  // Fixed volume: p = (gamma - 1) U / V with U ~ m, so dp = gamma p dm / m for gas passed
  // at about the cell's temperature.
  const int direction = countedDirection(events);
  if (direction == 0 || !(before.mass_kg > 0.0)) return 0.0;
  const double dm_kg = std::fabs(observer_->estimate().mass_kg - before.mass_kg);
  const double p_abs = measurement_.gauge_pressure_pa + params_.cell.ambient_pressure_pa;
  return direction * params_.cell.gas.heat_capacity_ratio * p_abs * dm_kg / before.mass_kg;
}

double AirbagCell::platePeriod() const {
  // The gas spring k = gamma p_abs A^2 / V with A the structure's dV/dh at the estimate (a
  // light plate's F / p would take a few pascals' noise for its area); the moving mass M = F / g.
  constexpr double kGravity = 9.81;
  const CellEstimate e = observer_->estimate();
  const double p = measurement_.gauge_pressure_pa;
  const double area_m2 = observer_->variables().structure.effective_area_m2;
  if (!(e.load_n > 0.0 && std::isfinite(p) && area_m2 > 0.0 && e.volume_m3 > 0.0)) return 0.0;
  const double stiffness_n_m =
      params_.cell.gas.heat_capacity_ratio * (p + params_.cell.ambient_pressure_pa) * area_m2 * area_m2 / e.volume_m3;
  return 2.0 * M_PI * std::sqrt(e.load_n / kGravity / stiffness_n_m);
}

void AirbagCell::monitorStep(const ObserverEvents& events, const CellEstimate& before, double dt_s) {
  const double height_before_m = before.height_m;
  // The pressure before a lost link, for the check after it (over a few periods: one
  // reading's noise is not the cell's pressure).
  const double p = fresh_pressure_pa_;
  if (std::isfinite(p))
    recent_pressure_pa_ =
        std::isfinite(recent_pressure_pa_) ? recent_pressure_pa_ + 0.2 * (p - recent_pressure_pa_) : p;
  if (!use_estimate_) return;
  ConsistencySample sample;
  sample.gauge_pressure_pa = p;
  sample.noise_sd_pa = observer_->estimate().pressure_noise_pa;
  const ObserverInputs& applied = observer_->appliedInputs();
  sample.valves_shut = applied.valves.inlet == 0.0 && applied.valves.vent == 0.0;
  sample.inlet_opening = applied.valves.inlet;
  sample.vent_opening = applied.valves.vent;
  // A re-anchor proves the gas (the cell found flat) whatever it corrected; a weight bound
  // only pulls the estimate to a bound, so a large one shows the inventory wrong, unless the
  // gas is already being found (a restarted terminal's empty cell under the link check).
  if (events.weight_bounded && !events.reanchored && !gas_.gasUnknown())
    sample.correction_m = observer_->estimate().height_m - height_before_m;
  sample.counted_step_pa = countedStepPa(events, before);
  if (countedDirection(events) != 0 && before.mass_kg > 0.0) {
    const double area_m2 = observer_->variables().structure.effective_area_m2;  // dV/dh
    sample.counted_gas_kg = std::fabs(observer_->estimate().mass_kg - before.mass_kg);
    if (area_m2 > 0.0) sample.counted_height_m = sample.counted_gas_kg / before.mass_kg * before.volume_m3 / area_m2;
  }
  sample.load_n = observer_->estimate().load_n;
  sample.plate_period_s = platePeriod();
  // A gas already unproven (a lost link, a reset) is being found: no height to contradict.
  sample.height_m = gas_.gasUnknown() ? 0.0 : observer_->estimate().height_m;
  sample.flat_pressure_pa = observer_->flatPressure();
  if (monitor_.update(sample, dt_s)) {
    faults_ |= kFaultInconsistent;
    gas_.suspectInconsistent();
  }
  observer_->doubtCount(monitor_.takeDoubtKg());  // a valve's gas the readings did not bear out
  // Found flat again: the count holds from there and the tests run again, but the fault stays
  // until a hold at height has proved the valves keep the gas.
  if ((faults_ & kFaultInconsistent) && monitor_.inconsistent() && !gas_.gasUnknown()) monitor_.clear();
  const bool correcting =
      sample.counted_step_pa != 0.0 && std::fabs(sample.counted_step_pa) < monitor_.params().hold_correction_pa;
  gas_.noteHold(sample.valves_shut || correcting, p, observer_->estimate().height_m, dt_s);
  if ((faults_ & kFaultInconsistent) && !gas_.unproven()) {
    faults_ &= ~kFaultInconsistent;
    monitor_.clear();
  }
}

void AirbagCell::controlStep() {
  const double now = time_s_;
  // The sensors were read at the end of the previous period (advanceTo), i.e. now.
  const double p = measurement_.gauge_pressure_pa, h = measurement_.height_m;
  if (!checkSensorsAndWatchdog(now, p, h)) return;
  controller_.setHeightNoise(readingNoise());
  const ValveOpenings wanted = controller_.update(params_.control_period_s, p, h);
  valves_ = modeValves(wanted, p);
  if (mode_ == AirbagMode::kHeight || mode_ == AirbagMode::kPressure) valves_ = gasCheckValves(now, p, valves_);
  applyRelief(p);
  controller_.noteWritten(valves_, params_.control_period_s);  // the gas in flight is what was sent
}

bool AirbagCell::checkSensorsAndWatchdog(double now_s, double gauge_pressure_pa, double height_m) {
  // A reading out of range holds the gas at once (both valves shut); it is a sensor fault once
  // it persists, until the sensors read sane values again.
  const SensorVerdict sensors = safety_.checkReadings(gauge_pressure_pa, height_m);
  if (sensors != SensorVerdict::kOk) {
    valves_ = ValveOpenings{};
    controller_.noteWritten(valves_, params_.control_period_s);
    if (sensors == SensorVerdict::kFault) {
      faults_ |= kFaultSensor;
      mode_ = AirbagMode::kSafe;
    }
    return false;
  }
  if (faults_ & kFaultSensor) {
    faults_ &= ~kFaultSensor;
    mode_ = resumedMode();
  }
  // Command watchdog: hold the gas (like a controller's brake()) when commands stop.
  if (mode_ != AirbagMode::kVent && safety_.commandTimedOut(now_s)) {
    faults_ |= kFaultCommandTimeout;
    mode_ = AirbagMode::kSafe;
  }
  return true;
}

ValveOpenings AirbagCell::modeValves(const ValveOpenings& wanted, double gauge_pressure_pa) const {
  switch (mode_) {
    case AirbagMode::kHeight: return wanted;
    case AirbagMode::kVent: return ValveOpenings{0.0, 1.0};
    case AirbagMode::kPressure: return pressure_.update(gauge_pressure_pa);
    case AirbagMode::kIdle:
    case AirbagMode::kSafe: break;
  }
  return ValveOpenings{};
}

void AirbagCell::applyRelief(double gauge_pressure_pa) {
  switch (safety_.relief(gauge_pressure_pa)) {
    case ReliefVerdict::kVent:
      faults_ |= kFaultOverpressure;
      valves_.inlet = 0.0;
      valves_.vent = 1.0;
      break;
    case ReliefVerdict::kClear: faults_ &= ~kFaultOverpressure; break;
    case ReliefVerdict::kKeep: break;
  }
}

}  // namespace nursing_bed
