#include "nursing_bed/core/hardware/simulated_cell_hardware.h"

#include <cmath>
#include <sstream>
#include <stdexcept>

namespace nursing_bed {

void SimulatedCellHardware::configure(const HardwareConfig& config) {
  if (!(config.control_period_s > 0.0)) throw std::runtime_error("simulated hardware: control_period_s must be > 0");
  if (!(rig_.adc_step_pa >= 0.0) || !(rig_.valve_dead_time_s >= 0.0))
    throw std::runtime_error("simulated hardware: adc step and valve dead time must be >= 0");
  config_ = config;
  try {
    model_ = std::make_unique<CellModel>(config.cell);
    for (const auto& e : config.effects) model_->addEffect(e);
  } catch (const std::invalid_argument& e) {
    throw std::runtime_error(std::string("simulated hardware: ") + e.what());
  }
  supply_pressure_pa_ = config.cell.supply_pressure_pa;
  if (config.initial_height_m > 0.0) {
    resetToHeight(config.initial_height_m, config.load_n);
  } else {
    reset(config.load_n);
  }
  // Seeded after the initial reset: the noise sequence starts with the owner's first reset.
  rng_.seed(config.noise_seed);
}

HardwareCapabilities SimulatedCellHardware::capabilities() const {
  HardwareCapabilities c;
  c.height = rig_.height_sensor;
  c.inflow = true;
  c.gas_temperature = true;
  c.supply_pressure = true;
  c.vent_vacuum = true;
  return c;
}

void SimulatedCellHardware::reset(double load_n) {
  load_n_ = load_n;
  model_->reset(load_n);
  commanded_ = acting_ = ValveOpenings{};
  valve_line_.clear();
  metered_inlet_mass_kg_ = inlet_opening_s_ = vent_opening_s_ = 0.0;
  sense();
}

void SimulatedCellHardware::resetToHeight(double height_m, double load_n) {
  reset(load_n);
  model_->resetToEquilibrium(height_m, load_n);
  sense();
}

void SimulatedCellHardware::setSensorFailure(bool failed) {
  sensor_failed_ = failed;
  sense();
}

CellInputs SimulatedCellHardware::plantInputs() const {
  CellInputs in;
  in.load_n = load_n_;
  in.supply_pressure_pa = supply_pressure_pa_;
  in.inlet_opening = acting_.inlet;
  in.vent_opening = acting_.vent;
  in.vent_back_pressure_pa = acting_.vent_to_vacuum ? config_.cpr_vacuum_pa : 0.0;
  return in;
}

void SimulatedCellHardware::stepPeriod() {
  const double period = config_.control_period_s;
  const auto delay = static_cast<std::size_t>(std::lround(rig_.valve_dead_time_s / period));
  valve_line_.push_back(commanded_);
  if (valve_line_.size() > delay) {
    acting_ = valve_line_.front();
    valve_line_.pop_front();
  }
  const double start_s = model_->time();
  const double metered_start_kg = model_->meteredInletMassKg();
  bool solved = true;
  try {
    model_->advance(period, plantInputs());
  } catch (const std::exception&) {
    solved = false;
  }
  if (!solved || !plantValid()) {
    resetAfterFault(start_s + period);
    return;
  }
  // The meter totalises: the gas it counted over the period, however the flow changed in it
  // (a fold snapping open mid-period draws more through the inlet than the end flow says).
  const double metered_kg = model_->meteredInletMassKg() - metered_start_kg;
  metered_inlet_mass_kg_ += metered_kg;
  inlet_opening_s_ += acting_.inlet * period;
  vent_opening_s_ += acting_.vent * period;
  // Read at the period's end: what is reported with this time is the state at this time; the
  // flow as the period's mean, what the totalised count gives a reader of one period.
  sense();
  if (std::isfinite(measurement_.inflow_kg_s)) measurement_.inflow_kg_s = metered_kg / period;
}

bool SimulatedCellHardware::plantValid() const {
  // What an absurd input leaves behind (a negative volume, a gas at a few K, a few nanograms of
  // gas at millions of K that never recover). The bounds stay far outside what the nominal
  // model passes through: it heats the last milligram of gas to ~1400 K for a few ms when
  // CPR's vacuum empties the cell onto its dead volume, and recovers by itself.
  constexpr double kMinGasKg = 1e-9, kMinTemperatureK = 10.0, kMaxTemperatureK = 1e5;
  const CellVariables& v = model_->variables();
  return model_->state().allFinite() && v.structure.volume_m3 > 0.0 && v.mass_kg > kMinGasKg &&
         v.temperature_k > kMinTemperatureK && v.temperature_k < kMaxTemperatureK &&
         std::isfinite(v.gauge_pressure_pa) && std::isfinite(v.height_m);
}

void SimulatedCellHardware::resetAfterFault(double time_s) {
  model_->reset(load_n_);
  CellModel::StateVector state = model_->state();
  model_->setState(time_s, state);
  commanded_ = acting_ = ValveOpenings{};
  valve_line_.clear();
  device_reset_ = true;
  sense();
}

CellReadings SimulatedCellHardware::read(double now_s) {
  while (model_->time() + 0.5 * config_.control_period_s <= now_s) stepPeriod();
  const double t = model_->time();
  CellReadings r;
  r.gauge_pressure_pa = {measurement_.gauge_pressure_pa, t};
  if (rig_.height_sensor) r.height_m = {measurement_.height_m, t};
  r.inflow_kg_s = {measurement_.inflow_kg_s, t};
  r.gas_temperature_k = {measurement_.gas_temperature_k, t};
  r.supply_pressure_pa = {model_->variables().regulator_pressure_pa, t};
  r.device_reset = device_reset_;
  device_reset_ = false;
  return r;
}

void SimulatedCellHardware::write(const ValveOpenings& valves, double /*now_s*/) { commanded_ = valves; }

void SimulatedCellHardware::sense() {
  measurement_ = model_->measure();
  measurement_.gauge_pressure_pa += config_.pressure_noise_pa * unit_noise_(rng_);
  measurement_.height_m += config_.height_noise_m * unit_noise_(rng_);
  if (rig_.adc_step_pa > 0.0)
    measurement_.gauge_pressure_pa = rig_.adc_step_pa * std::round(measurement_.gauge_pressure_pa / rig_.adc_step_pa);
  if (sensor_failed_) {
    measurement_.gauge_pressure_pa = std::numeric_limits<double>::quiet_NaN();
    measurement_.height_m = std::numeric_limits<double>::quiet_NaN();
  }
}

std::string SimulatedCellHardware::describe() const {
  std::ostringstream s;
  s << "simulated cell " << config_.cell_id << " (" << (model_ ? model_->structure().describe() : "unconfigured")
    << ")";
  if (rig_.adc_step_pa > 0.0) s << ", ADC step " << rig_.adc_step_pa << " Pa";
  if (rig_.valve_dead_time_s > 0.0) s << ", valve dead time " << rig_.valve_dead_time_s << " s";
  return s.str();
}

}  // namespace nursing_bed
