#include "nursing_bed/core/control/airbag_cell.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace nursing_bed {

std::string AirbagSafetyParams::validate() const {
  std::ostringstream err;
  if (!(relief_pressure_pa > 0.0 && std::isfinite(relief_pressure_pa))) err << "relief_pressure_pa must be positive; ";
  if (!(relief_margin_pa >= 0.0 && relief_margin_pa < relief_pressure_pa))
    err << "relief_margin_pa must lie in [0, relief_pressure_pa); ";
  if (!(command_timeout_s >= 0.0)) err << "command_timeout_s must be >= 0; ";
  if (!(sensor_pressure_max_pa > sensor_pressure_min_pa)) err << "sensor pressure range is empty; ";
  if (!(sensor_height_max_m > sensor_height_min_m)) err << "sensor height range is empty; ";
  if (!(sensor_fault_periods >= 1 && sensor_fault_periods <= 100)) err << "sensor_fault_periods must lie in 1..100; ";
  if (!(max_load_n > 0.0 && std::isfinite(max_load_n))) err << "max_load_n must be a positive finite load; ";
  if (!(max_height_rate_m_s > 0.0 && std::isfinite(max_height_rate_m_s)))
    err << "max_height_rate_m_s must be a positive finite rate; ";
  std::string s = err.str();
  if (s.size() >= 2) s.resize(s.size() - 2);
  return s;
}

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

// Pressure mode: a valve opens fully at this error and stays shut within the tolerance.
constexpr double kPressureBandPa = 1000.0;
constexpr double kPressureTolerancePa = 50.0;

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
      supply_pressure_pa_(params.cell.supply_pressure_pa) {
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
  valves_ = ValveCommand{};
  pressure_setpoint_pa_ = std::numeric_limits<double>::quiet_NaN();
  last_command_s_ = 0.0;
  last_pressure_pa_ = 0.0;
  time_s_ = 0.0;
  gas_check_pending_ = false;
  gas_check_vent_left_s_ = 0.0;
  gas_check_until_s_ = -1.0;
  gas_ = GasKnowledge::kKnown;
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
  if (observer_ && !sim_ && use_estimate_) {
    gas_ = GasKnowledge::kUnverified;
    finding_reanchors_ = observer_->estimate().reanchors;
  }
}

void AirbagCell::resetToHeight(double height_m, double load_n) {
  resetControl(load_n);
  if (sim_) sim_->resetToHeight(height_m, load_n);
  if (observer_) observer_->resetToHeight(height_m, load_n);
  controller_.setTarget(height_m);
  mode_ = AirbagMode::kHeight;
  if (sim_) observe(sim_->read(0.0));
  last_pressure_pa_ = measurement_.gauge_pressure_pa;
}

std::string AirbagCell::checkLoad(double load_n) const {
  if (std::isfinite(load_n) && load_n >= 0.0 && load_n <= params_.safety.max_load_n) return "";
  std::ostringstream msg;
  msg << "load " << load_n << " N refused: must be finite and within [0, " << params_.safety.max_load_n
      << "] N (safety/max_load_n)";
  return msg.str();
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
  if (gas_ == GasKnowledge::kFinding) return std::numeric_limits<double>::infinity();  // its gas is unknown
  return use_estimate_ ? observer_->estimate().height_sd_m : params_.height_noise_m;
}

AirbagMode AirbagCell::resumedMode() const {
  if (std::isfinite(pressure_setpoint_pa_)) return AirbagMode::kPressure;
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
  planAnchor(height_m);
  pressure_setpoint_pa_ = std::numeric_limits<double>::quiet_NaN();
  mode_ = AirbagMode::kHeight;
  faults_ &= ~(kFaultCommandTimeout | kFaultModel);
  last_command_s_ = now_s;
  return "";
}

void AirbagCell::setCpr(bool on, double now_s) {
  if (on) requestVent(now_s);
  else if (cpr_ && mode_ == AirbagMode::kVent) mode_ = AirbagMode::kIdle;
  cpr_ = on;
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
  if (gas_ == GasKnowledge::kAnchoring) gas_ = GasKnowledge::kKnown;  // a pressure is held from where the cell is
  pressure_setpoint_pa_ = pressure_pa;
  mode_ = AirbagMode::kPressure;
  faults_ &= ~(kFaultCommandTimeout | kFaultModel);
  last_command_s_ = now_s;
  return "";
}

ValveCommand AirbagCell::pressureValves(double gauge_pressure_pa) const {
  const double error = pressure_setpoint_pa_ - gauge_pressure_pa;
  ValveCommand v;
  if (error > kPressureTolerancePa) v.inlet = std::min(1.0, error / kPressureBandPa);
  if (error < -kPressureTolerancePa) v.vent = std::min(1.0, -error / kPressureBandPa);
  return v;
}

void AirbagCell::requestVent(double now_s) {
  controller_.clearTarget();
  pressure_setpoint_pa_ = std::numeric_limits<double>::quiet_NaN();

  mode_ = AirbagMode::kVent;
  faults_ &= ~kFaultCommandTimeout;
  last_command_s_ = now_s;
}

void AirbagCell::heartbeat(double now_s) {
  last_command_s_ = now_s;
  if (faults_ & kFaultCommandTimeout) {
    faults_ &= ~kFaultCommandTimeout;
    if (mode_ == AirbagMode::kSafe && !(faults_ & (kFaultSensor | kFaultCommunication))) mode_ = resumedMode();
  }
}

void AirbagCell::retune(const AirbagCellParams& params) {
  const std::string error = params.validate();
  if (!error.empty()) throw std::invalid_argument("airbag parameters: " + error);
  controller_.retune(params.controller);  // throws before anything here changes
  const double command_timeout_s = params_.safety.command_timeout_s;
  params_.controller = params.controller;
  params_.safety = params.safety;
  params_.safety.command_timeout_s = command_timeout_s;
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
  // The valve holds over the period: its end flow stands for the period.
  metered_inlet_mass_kg_ += readings.inflow_kg_s.value * period;
  inlet_opening_s_ += valves_.inlet * period;
  vent_opening_s_ += valves_.vent * period;
  time_s_ = sim_->time();
  observe(readings);
}

void AirbagCell::stepReal(double now_s) {
  // The real time since the last period: a loaded machine's ticks run late, and the valves
  // kept their command meanwhile (the observer must integrate all of it).
  const double period = std::clamp(now_s - time_s_, 1e-4, 0.5);
  const CellReadings readings = hardware_->read(now_s);
  time_s_ = now_s;
  onLink(readings);
  if (readings.device_reset) onDeviceReset();
  if (faults_ & kFaultCommunication) {
    // Nothing is commanded while the link is down; the observer coasts with what the terminal
    // still drove (its outputs hold until its watchdog) where the driver knows it, else with
    // the last command over the period it acted, then with the valves shut.
    observer_->predict(linkDownInputs(readings), period);
    valves_ = ValveCommand{};
    controller_.noteWritten(valves_, period);  // nothing sent: nothing in flight once the link is back
    measurement_.gauge_pressure_pa = readings.gauge_pressure_pa.value;
    return;
  }
  observe(readings, period);
  controlStep();
  hardware_->write(openings(), now_s);
  if (readings.inflow_kg_s.present()) metered_inlet_mass_kg_ += readings.inflow_kg_s.value * period;
  inlet_opening_s_ += valves_.inlet * period;
  vent_opening_s_ += valves_.vent * period;
}

ObserverInputs AirbagCell::linkDownInputs(const CellReadings& readings) const {
  ObserverInputs in{valves_.inlet, valves_.vent, 0.0, supply_pressure_pa_};
  if (readings.inlet_driven.present()) in.inlet_opening = readings.inlet_driven.value;
  if (readings.vent_driven.present()) in.vent_opening = readings.vent_driven.value;
  return in;
}

ValveCommand AirbagCell::checkingGas(double now_s, const ValveCommand& wanted) {
  // Over a lost link the gas is unverified: the bed may have been emptied meanwhile (a restarted
  // terminal, a CPR dump). Pressure cannot tell: a sealed flat cell under 15.6 N floats its plate on its residual
  // gas at 487 Pa (a restarted emulator's cell after one inlet pulse), as a cell lifted under
  // half the load reads; the observer kept its gas, lowered its load, and with the controller
  // holding quietly on target nothing told them apart (a flat cell reported at 60 mm for 40 s).
  // Venting does: the floating flat cell grounds and reads ambient within a few tens of ms, and
  // the observer's re-anchor test takes it with the valves shut; a lifted cell keeps its load's
  // pressure and loses 1-3 mm, which the controller restores after the check.
  const CellObserverParams& op = observer_->params();
  if (gas_check_pending_) {
    gas_check_pending_ = false;
    gas_check_vent_left_s_ = op.resume_vent_s;
    gas_check_reanchors_ = observer_->estimate().reanchors;
  }
  const double period = params_.control_period_s;
  if (gas_check_vent_left_s_ > 0.0) {
    const bool grounded = measurement_.gauge_pressure_pa < observer_->flatPressure();
    const double opening = grounded ? 0.0 : std::min(1.0, gas_check_vent_left_s_ / period);
    gas_check_vent_left_s_ = grounded ? 0.0 : std::max(0.0, gas_check_vent_left_s_ - period);
    // The test's mean pressure starts above the flat cell's: twice its time, after the dead time.
    if (gas_check_vent_left_s_ <= 0.0) {
      gas_check_until_s_ = now_s + period + op.valve_dead_time_s + 2.0 * op.reanchor_time_s;
      observer_->expectFlat(gas_check_until_s_ - now_s);
    }
    return ValveCommand{0.0, opening};
  }
  if (gas_check_until_s_ < 0.0) return wanted;
  // Found flat (re-anchored), the controller takes over at once; else after the test's time.
  if (now_s < gas_check_until_s_ && observer_->estimate().reanchors == gas_check_reanchors_) return ValveCommand{};
  gas_check_until_s_ = -1.0;
  return wanted;
}

void AirbagCell::planAnchor(double target_m) {
  // Near the bag's top 1 % of gas moves a light plate 8-10 mm, and pressure alone cannot tell
  // a plate higher than counted from a heavier load on it: each move's count error (0.4-2 % on
  // the bed) stays in the inventory until the cell is found flat. A cell lowered into the low
  // band has little height to lose there, so it passes through flat on the way.
  if (!use_estimate_) return;
  const double band = observer_->params().reanchor_below_m;
  const bool low = target_m <= band;
  if (gas_ == GasKnowledge::kAnchoring && !low) {
    gas_ = GasKnowledge::kKnown;  // raised again before it was found flat
  } else if (gas_ == GasKnowledge::kKnown && low && band > 0.0 && measurement_.height_m > band) {
    gas_ = GasKnowledge::kAnchoring;
    finding_reanchors_ = observer_->estimate().reanchors;
  }
}

ValveCommand AirbagCell::findingGas(const ValveCommand& wanted) {
  // Started flat over a cell that holds gas, the observer would count every fill from nothing:
  // commanded to 80 mm, such a cell filled to the bag's top at the supply pressure (140-150 mm,
  // 20 kPa, the estimate at 30 mm). Its pressure alone cannot give its gas (nor its height or
  // load); a flat cell's can. So it vents, the one safe direction, until the observer's
  // re-anchor test finds it flat (below ambient counts: a heavy plate's vented cell settles
  // there), and is then controlled to its kept setpoint. A cell anchoring (planAnchor) does the
  // same with its height tracked meanwhile.
  if (gas_ == GasKnowledge::kKnown) return wanted;
  if (observer_->estimate().reanchors > finding_reanchors_) {
    const bool vented = gas_ != GasKnowledge::kUnverified;
    gas_ = GasKnowledge::kKnown;
    if (!vented) return wanted;  // found flat before any command (a bed started flat)
    // Its integral ran on the flat start's error through the vent: restart it.
    if (controller_.hasTarget()) controller_.setTarget(controller_.target());
    return ValveCommand{};
  }
  if (gas_ == GasKnowledge::kUnverified) gas_ = GasKnowledge::kFinding;
  observer_->expectFlat(2.0 * params_.control_period_s);
  return ValveCommand{0.0, 1.0};
}

void AirbagCell::onDeviceReset() {
  controller_.clearTarget();
  pressure_setpoint_pa_ = std::numeric_limits<double>::quiet_NaN();
  valves_ = ValveCommand{};
  mode_ = AirbagMode::kSafe;
  faults_ |= kFaultModel;
  last_pressure_pa_ = 0.0;
  // The cell is in its reset state (flat): the observer starts from there too.
  if (observer_) observer_->reset(sim_ ? load_n_ : observer_->estimate().load_n);
}

void AirbagCell::onLink(const CellReadings& readings) {
  const bool down = readings.link == LinkState::kDown;
  if (down && !(faults_ & kFaultCommunication)) {
    faults_ |= kFaultCommunication;
    mode_before_link_loss_ = mode_;
    mode_ = AirbagMode::kSafe;
  } else if (!down && (faults_ & kFaultCommunication)) {
    faults_ &= ~kFaultCommunication;
    // The observer keeps its gas: the terminal's watchdog shut the valves, so the gas is what
    // it was. A cell found flat (a restarted rig, a bed vented meanwhile) is re-anchored by the
    // observer's own test (its mean pressure that low for reanchor_time_s, inlet shut). Reset
    // on one reading below reanchor_pressure_pa instead, a light plate resting at 55-75 Pa
    // was taken for flat after a 50 ms bus timeout and filled to the bag's top at 30 kPa.
    mode_ = mode_before_link_loss_ == AirbagMode::kSafe ? resumedMode() : mode_before_link_loss_;
    gas_check_pending_ = observer_->params().resume_vent_s > 0.0;
  }
}

void AirbagCell::observe(const CellReadings& readings, double dt_s) {
  measurement_.gauge_pressure_pa = readings.gauge_pressure_pa.value;
  measurement_.height_m = readings.height_m.value;
  measurement_.inflow_kg_s = readings.inflow_kg_s.value;
  measurement_.temperature_k = readings.gas_temperature_k.value;
  if (!observer_ || (sim_ && !use_estimate_)) return;
  ObserverInputs in;
  // What the driver applied where it says (PWM pulses), else what was commanded.
  in.inlet_opening = readings.inlet_driven.present() ? readings.inlet_driven.value : valves_.inlet;
  in.vent_opening = readings.vent_driven.present() ? readings.vent_driven.value : valves_.vent;
  // The vent's outlet as the hardware has it (a bed without a vacuum source vents to the air:
  // modelled with the vacuum, a vented cell's estimate fell 2.5 times too fast, 40 mm off).
  in.vent_back_pressure_pa = ventToVacuum() ? params_.cpr_vacuum_pa : 0.0;
  in.supply_pressure_pa = supply_pressure_pa_;
  if (readings.supply_pressure_pa.present()) in.measured_supply_pa = readings.supply_pressure_pa.value;
  ObserverReadings z;
  z.gauge_pressure_pa = readings.gauge_pressure_pa.value;
  if (!use_estimate_) z.height_m = readings.height_m.value;
  if (capabilities_.inflow && !sim_) z.inflow_kg_s = readings.inflow_kg_s.value;
  observer_->step(in, z, dt_s);
  if (use_estimate_) measurement_.height_m = observer_->estimate().height_m;
}

void AirbagCell::controlStep() {
  const double now = time_s_;
  // The sensors were read at the end of the previous period (advanceTo), i.e. now.
  const AirbagSafetyParams& s = params_.safety;
  const double p = measurement_.gauge_pressure_pa, h = measurement_.height_m;
  const bool sensor_ok = std::isfinite(p) && std::isfinite(h) && p >= s.sensor_pressure_min_pa &&
                         p <= s.sensor_pressure_max_pa && h >= s.sensor_height_min_m && h <= s.sensor_height_max_m;
  // A reading out of range holds the gas at once (both valves shut); it is a sensor fault once
  // it persists for sensor_fault_periods, until the sensors read sane values again. A single
  // out-of-range sample is what a plate lifting off a flat cell gives for a few ms (the gas
  // sucked below -50 kPa for up to 15 ms), and a fault there levelled the whole bed.
  if (!sensor_ok) {
    valves_ = ValveCommand{};
    controller_.noteWritten(valves_, params_.control_period_s);
    if (++bad_readings_ >= s.sensor_fault_periods) {
      faults_ |= kFaultSensor;
      mode_ = AirbagMode::kSafe;
    }
    return;
  }
  bad_readings_ = 0;
  if (faults_ & kFaultSensor) {
    faults_ &= ~kFaultSensor;
    mode_ = resumedMode();
  }
  // Command watchdog: hold the gas (like a controller's brake()) when commands stop.
  if (s.command_timeout_s > 0.0 && mode_ != AirbagMode::kVent && now - last_command_s_ > s.command_timeout_s) {
    faults_ |= kFaultCommandTimeout;
    mode_ = AirbagMode::kSafe;
  }

  const ValveCommand wanted = controller_.update(params_.control_period_s, p, h);
  switch (mode_) {
    case AirbagMode::kHeight:
      valves_ = wanted;
      break;
    case AirbagMode::kVent:
      valves_ = ValveCommand{0.0, 1.0};
      break;
    case AirbagMode::kPressure:
      valves_ = pressureValves(p);
      break;
    case AirbagMode::kIdle:
    case AirbagMode::kSafe:
      valves_ = ValveCommand{};
      break;
  }
  if (mode_ == AirbagMode::kHeight || mode_ == AirbagMode::kPressure) valves_ = findingGas(checkingGas(now, valves_));
  // Relief, whatever the mode: act before the next period's rise could cross it.
  const double rise = std::max(0.0, p - last_pressure_pa_);
  last_pressure_pa_ = p;
  if (p + rise + s.relief_margin_pa >= s.relief_pressure_pa) {
    faults_ |= kFaultOverpressure;
    valves_.inlet = 0.0;
    valves_.vent = 1.0;
  } else if (p < s.relief_pressure_pa - 2.0 * s.relief_margin_pa - rise) {
    faults_ &= ~kFaultOverpressure;
  }
  controller_.noteWritten(valves_, params_.control_period_s);  // the gas in flight is what was sent
}

}  // namespace nursing_bed
