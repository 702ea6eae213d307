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

AirbagCell::AirbagCell(const AirbagCellParams& params, const std::vector<CellEffectPtr>& effects)
    : params_(validated(params)),
      model_(params.cell),
      controller_(params.controller, CellCharacteristic::shared(params.cell)),
      supply_pressure_pa_(params.cell.supply_pressure_pa),
      rng_(params.noise_seed) {
  for (const auto& e : effects) model_.addEffect(e);
  reset(0.6);
}

void AirbagCell::reset(double load_n) {
  load_n_ = load_n;
  model_.reset(load_n);
  controller_.clearTarget();
  controller_.setLoadEstimate(load_n);
  mode_ = AirbagMode::kIdle;
  faults_ = kFaultNone;
  valves_ = ValveCommand{};
  last_command_s_ = 0.0;
  last_pressure_pa_ = 0.0;
  sense();
}

void AirbagCell::resetToHeight(double height_m, double load_n) {
  reset(load_n);
  model_.resetToEquilibrium(height_m, load_n);
  controller_.setTarget(height_m);
  mode_ = AirbagMode::kHeight;
  sense();
  last_pressure_pa_ = measurement_.gauge_pressure_pa;
}

std::string AirbagCell::checkHeight(double height_m) const {
  if (cpr_) return "CPR is running (bed-wide): no cell is inflated until it ends";
  return controller_.checkSetpoint(height_m);
}

std::string AirbagCell::requestHeight(double height_m, double now_s) {
  const std::string error = checkHeight(height_m);
  if (!error.empty()) return error;
  controller_.setTarget(height_m);
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

std::string AirbagCell::checkLoad(double load_n) const {
  if (std::isfinite(load_n) && load_n >= 0.0 && load_n <= params_.safety.max_load_n) return "";
  std::ostringstream msg;
  msg << "load " << load_n << " N refused: must be finite and within [0, " << params_.safety.max_load_n
      << "] N (safety/max_load_n)";
  return msg.str();
}

std::string AirbagCell::setLoad(double load_n) {
  std::string error = checkLoad(load_n);
  if (error.empty()) load_n_ = load_n;
  return error;
}

void AirbagCell::requestVent(double now_s) {
  controller_.clearTarget();
  mode_ = AirbagMode::kVent;
  faults_ &= ~kFaultCommandTimeout;
  last_command_s_ = now_s;
}

void AirbagCell::heartbeat(double now_s) {
  last_command_s_ = now_s;
  if (faults_ & kFaultCommandTimeout) {
    faults_ &= ~kFaultCommandTimeout;
    if (mode_ == AirbagMode::kSafe && !(faults_ & kFaultSensor))
      mode_ = controller_.hasTarget() ? AirbagMode::kHeight : AirbagMode::kIdle;
  }
}

void AirbagCell::setSupplyPressure(double pressure_pa) {
  supply_pressure_pa_ = pressure_pa;
  controller_.setSupplyPressure(pressure_pa);
}

void AirbagCell::advanceTo(double now_s) {
  const double period = params_.control_period_s;
  while (model_.time() + 0.5 * period <= now_s) {
    controlStep();
    CellInputs in;
    in.load_n = load_n_;
    in.supply_pressure_pa = supply_pressure_pa_;
    in.inlet_opening = valves_.inlet;
    in.vent_opening = valves_.vent;
    in.vent_back_pressure_pa = mode_ == AirbagMode::kVent ? params_.cpr_vacuum_pa : 0.0;
    if (!plantStep(in)) {
      resetAfterModelFault();
      continue;
    }
    // The valve holds over the period: its end flow stands for the period.
    metered_inlet_mass_kg_ += model_.measure().inflow_kg_s * period;
    inlet_opening_s_ += valves_.inlet * period;
    vent_opening_s_ += valves_.vent * period;
    // Read at the period's end: what is published with this time is the state at this time
    // (read at the start instead, a recording's pressure lagged its metered gas by a period).
    sense();
  }
}

bool AirbagCell::plantStep(const CellInputs& in) {
  try {
    model_.advance(params_.control_period_s, in);
  } catch (const std::exception&) {
    return false;
  }
  // What an absurd input left behind (seen: volume -0.05 m^3, 1.4 K). No upper bound on the
  // temperature: the nominal model heats the last milligram of gas to ~1400 K for a few ms when
  // CPR's vacuum empties the cell onto its dead volume, and recovers by itself (doc/safety.md).
  const CellVariables& v = model_.variables();
  return model_.state().allFinite() && v.structure.volume_m3 > 0.0 && v.mass_kg > 0.0 && v.temperature_k > 10.0 &&
         std::isfinite(v.gauge_pressure_pa) && std::isfinite(v.height_m);
}

void AirbagCell::resetAfterModelFault() {
  const double time = model_.time() + params_.control_period_s;
  model_.reset(load_n_);
  CellModel::StateVector state = model_.state();
  model_.setState(time, state);
  controller_.clearTarget();
  valves_ = ValveCommand{};
  mode_ = AirbagMode::kSafe;
  faults_ |= kFaultModel;
  last_pressure_pa_ = 0.0;
  sense();
}

void AirbagCell::sense() {
  measurement_ = model_.measure();
  measurement_.gauge_pressure_pa += params_.pressure_noise_pa * unit_noise_(rng_);
  measurement_.height_m += params_.height_noise_m * unit_noise_(rng_);
  if (sensor_failed_) {
    measurement_.gauge_pressure_pa = std::numeric_limits<double>::quiet_NaN();
    measurement_.height_m = std::numeric_limits<double>::quiet_NaN();
  }
}

void AirbagCell::controlStep() {
  const double now = model_.time();
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
    if (++bad_readings_ >= s.sensor_fault_periods) {
      faults_ |= kFaultSensor;
      mode_ = AirbagMode::kSafe;
    }
    return;
  }
  bad_readings_ = 0;
  if (faults_ & kFaultSensor) {
    faults_ &= ~kFaultSensor;
    mode_ = controller_.hasTarget() ? AirbagMode::kHeight : AirbagMode::kIdle;
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
    case AirbagMode::kIdle:
    case AirbagMode::kSafe:
      valves_ = ValveCommand{};
      break;
  }
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
}

}  // namespace nursing_bed
