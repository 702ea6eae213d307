#include "nursing_bed/core/physics/cell_model.h"
#include "nursing_bed/core/physics/fold_table_structure.h"
#include "nursing_bed/core/physics/tabulated_structure.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>
#include <mutex>
#include <sstream>
#include <stdexcept>

#include "nursing_bed/core/io/errors.h"
#include "nursing_bed/core/physics/orifice.h"

namespace nursing_bed {
namespace {

// ROS2 (Verwer, Spee, Blom, Hundsdorfer 1999): gamma = 1 + 1/sqrt(2) makes it L-stable; it is
// second order for any Jacobian approximation, so the Jacobian may be reused across steps.
constexpr double kRos2Gamma = 1.0 + 0.70710678118654752440;

// Sub-steps longer than this take a Jacobian of their own state: several times the time
// constants of the cell's stiff modes (the plate on its gas spring, the film's relaxation).
constexpr double kFreshJacobianStepS = 5.0e-3;

// A kept Jacobian serves such a step while it predicts the rate's change along the last step
// to this fraction (the orifice laws' slopes drift as their pressure difference does).
constexpr double kSecantTolerance = 0.1;

}  // namespace

std::string CellParams::validate() const {
  ErrorList errors;
  auto check = [&errors](bool ok, const char* name, double value, const char* rule) {
    errors.addIf(!ok, name, " ", rule, ", got ", value);
  };
  auto positive = [&check](const char* name, double v) {
    check(v > 0.0 && std::isfinite(v), name, v, "must be a positive finite number");
  };
  auto non_negative = [&check](const char* name, double v) {
    check(v >= 0.0 && std::isfinite(v), name, v, "must be >= 0 and finite");
  };
  errors.addNested(gas.validate(), "gas: ");
  positive("ambient_pressure_pa", ambient_pressure_pa);
  positive("ambient_temperature_k", ambient_temperature_k);
  positive("supply_temperature_k", supply_temperature_k);
  errors.addNested(structure.validate());
  if (structure_type != "pillow" && structure_type != "table" && structure_type != "fold_table" &&
      structure_type != "bellows") {
    errors.add("structure_type must be 'pillow', 'table', 'fold_table' or 'bellows', got '", structure_type, "'");
  } else if ((structure_type == "table" || structure_type == "fold_table") && structure_table_file.empty()) {
    errors.add("structure_table_file must be set when structure_type is '", structure_type, "'");
  } else if (structure_type == "bellows") {
    errors.addNested(bellows.validate());
  }
  errors.addNested(airway.validate());
  positive("plate_mass_kg", plate_mass_kg);
  non_negative("plate_damping_n_s_m", plate_damping_n_s_m);
  positive("bed_contact_stiffness_n_m", bed_contact_stiffness_n_m);
  non_negative("bed_contact_damping_s_m", bed_contact_damping_s_m);
  non_negative("supply_pressure_pa", supply_pressure_pa);
  non_negative("regulator_time_constant_s", regulator_time_constant_s);
  non_negative("inlet_area_m2", inlet_area_m2);
  non_negative("vent_area_m2", vent_area_m2);
  non_negative("leak_area_m2", leak_area_m2);
  positive("orifice_linear_band_pa", orifice_linear_band_pa);
  positive("relief_cracking_pressure_pa", relief_cracking_pressure_pa);
  check(relief_full_open_pressure_pa > relief_cracking_pressure_pa && std::isfinite(relief_full_open_pressure_pa),
        "relief_full_open_pressure_pa", relief_full_open_pressure_pa, "must exceed the cracking pressure");
  non_negative("relief_sonic_conductance_m3_s_pa", relief_sonic_conductance_m3_s_pa);
  check(relief_critical_ratio >= 0.0 && relief_critical_ratio < 1.0, "relief_critical_ratio", relief_critical_ratio,
        "must lie in [0, 1)");
  check(time_step_s > 0.0 && time_step_s <= 0.05, "time_step_s", time_step_s, "must lie in (0, 0.05] s");
  check(max_time_step_s > 0.0 && max_time_step_s <= 0.1, "max_time_step_s", max_time_step_s, "must lie in (0, 0.1] s");
  check(jacobian_refresh_steps >= 1 && jacobian_refresh_steps <= 100, "jacobian_refresh_steps", jacobian_refresh_steps,
        "must lie in 1..100");
  check(relative_tolerance >= 1e-10 && relative_tolerance <= 1e-1, "relative_tolerance", relative_tolerance,
        "must lie in [1e-10, 0.1]");
  return errors.text();
}

double CellParams::reliefOpening(double gauge_pressure_pa) const {
  return std::clamp(
      (gauge_pressure_pa - relief_cracking_pressure_pa) / (relief_full_open_pressure_pa - relief_cracking_pressure_pa),
      0.0, 1.0);
}

namespace {

std::shared_ptr<const CellStructure> buildTableStructure(const CellParams& params) {
  if (params.structure_type == "table")
    return std::make_shared<TabulatedStructure>(TabulatedStructure::load(params.structure_table_file),
                                                params.structure.film_relaxation_time_s,
                                                params.structure.dead_volume_m3, params.structure.fold_fraction);
  return std::make_shared<FoldTableStructure>(FoldTableStructure::load(params.structure_table_file),
                                              params.structure.film_relaxation_time_s, params.structure.dead_volume_m3,
                                              params.structure.fold_fraction);
}

}  // namespace

std::shared_ptr<const CellStructure> makeCellStructure(const CellParams& params) {
  if (params.structure_type == "table" || params.structure_type == "fold_table") {
    // A table is read once per process: a bed's cells (and each cell's plant, controller and
    // observer) share one immutable structure, as reading the file took ~20 ms per copy.
    static std::mutex mutex;
    static std::map<std::string, std::shared_ptr<const CellStructure>> cache;
    // The file's time and size are part of the key: a table rewritten in place is read again.
    std::error_code ec;
    const auto written = std::filesystem::last_write_time(params.structure_table_file, ec);
    const auto size = std::filesystem::file_size(params.structure_table_file, ec);
    std::ostringstream key;
    key.precision(17);
    key << params.structure_type << '\n'
        << params.structure_table_file << '\n'
        << written.time_since_epoch().count() << ' ' << size << '\n'
        << params.structure.film_relaxation_time_s << ' ' << params.structure.dead_volume_m3 << ' '
        << params.structure.fold_fraction;
    std::lock_guard<std::mutex> lock(mutex);
    auto& entry = cache[key.str()];
    if (!entry) entry = buildTableStructure(params);
    return entry;
  }
  if (params.structure_type == "bellows") return std::make_shared<BellowsStructure>(params.bellows);
  return std::make_shared<PillowStructure>(params.structure);
}

CellModel::CellModel(const CellParams& params, std::shared_ptr<const CellStructure> structure)
    : params_(params), structure_(std::move(structure)) {
  const std::string error = params_.validate();
  if (!error.empty()) throw std::invalid_argument("cell parameters: " + error);
  if (!structure_) structure_ = makeCellStructure(params_);
  shape_dofs_ = structure_->shapeDofs();
  if (params_.airway.active()) {
    effects_.push_back(std::make_shared<AirwayEffect>(params_.airway));
    effects_read_flows_ = effects_.back()->readsValveFlows();
  }
  reset();
}

void CellModel::addEffect(CellEffectPtr effect) {
  if (!effect) throw std::invalid_argument("addEffect: null effect");
  int total = kShape + shape_dofs_;
  for (const auto& e : effects_) total += e->stateSize();
  if (total + effect->stateSize() > kMaxStates)
    throw std::invalid_argument("addEffect: too many states for effect " + effect->name());
  effects_read_flows_ = effects_read_flows_ || effect->readsValveFlows();
  effects_.push_back(std::move(effect));
  reset(last_inputs_.load_n);
}

void CellModel::reset(double load_n) {
  effect_offsets_.clear();
  int n = kShape + shape_dofs_;
  for (const auto& e : effects_) {
    effect_offsets_.push_back(n);
    n += e->stateSize();
  }
  state_.setZero(n);
  const auto rest = structure_->restShape();
  for (int i = 0; i < shape_dofs_; ++i) state_[kShape + i] = rest[i];
  // A bottomed-out plate rests on the contact spring, the gas at ambient in the flat cell there.
  state_[kHeight] = -load_n / params_.bed_contact_stiffness_n_m;
  const double volume = structure_->evaluate(state_[kHeight], rest.data()).volume_m3;
  const double mass = massFromState(params_.gas, params_.ambient_pressure_pa, params_.ambient_temperature_k, volume);
  state_[kMass] = mass;
  state_[kEnergy] = mass * params_.gas.cv() * params_.ambient_temperature_k;
  state_[kRegulator] = 0.0;
  time_ = 0.0;
  metered_inlet_mass_kg_ = 0.0;
  last_inputs_ = CellInputs{};
  last_inputs_.load_n = load_n;
  refreshVariables(last_inputs_);
  for (std::size_t i = 0; i < effects_.size(); ++i)
    effects_[i]->initialState(params_, vars_, state_.data() + effect_offsets_[i]);
  refreshVariables(last_inputs_);
  steps_since_jacobian_ = 1 << 30;
  jacobian_fresh_ = false;
  jacobian_tracks_ = false;
  substep_s_ = 0.0;
}

void CellModel::resetToEquilibrium(double height_m, double load_n, double gas_temperature_k) {
  reset(load_n);
  const StructureEquilibrium eq = structure_->equilibriumAtHeight(height_m, load_n);
  if (!eq.converged) {
    std::ostringstream msg;
    msg << "resetToEquilibrium: no pressure holds " << load_n << " N at height " << height_m << " m";
    throw std::invalid_argument(msg.str());
  }
  const double p = params_.ambient_pressure_pa + eq.gauge_pressure_pa;
  const double temperature = std::isfinite(gas_temperature_k) ? gas_temperature_k : params_.ambient_temperature_k;
  const double mass = massFromState(params_.gas, p, temperature, eq.eval.volume_m3);
  state_[kMass] = mass;
  state_[kEnergy] = mass * params_.gas.cv() * temperature;
  state_[kHeight] = height_m;
  state_[kVelocity] = 0.0;
  state_[kRegulator] = params_.supply_pressure_pa;
  for (int i = 0; i < shape_dofs_; ++i) state_[kShape + i] = eq.shape[i];
  refreshVariables(last_inputs_);
  for (std::size_t i = 0; i < effects_.size(); ++i)
    effects_[i]->initialState(params_, vars_, state_.data() + effect_offsets_[i]);
  refreshVariables(last_inputs_);
}

namespace {

using StateVector = CellModel::StateVector;

// The steps of CellModel::rate, in the order it calls them. Each writes the variables it owns
// into the CellVariables (read by the later steps and by the effects); none allocates.

/// The variables the state gives directly: gas, plate, regulator, film shape and structure.
/// `known`, when given, is the structure's evaluation at x's height and shape.
inline void stateVariables(const CellParams& params, const CellStructure& structure, int shape_dofs, double time_s,
                           const StateVector& x, const CellInputs& in, CellVariables* out,
                           const StructureEval* known = nullptr) {
  const GasProperties& gas = params.gas;
  CellVariables& v = *out;
  v.time_s = time_s;
  // Floors for a trial stage of the integrator only: the gas never leaves the flat cell's folded
  // volume, whose few mg no valve empties (they stop at their back pressure).
  v.mass_kg = std::max(x[CellModel::kMass], 1e-12);
  v.internal_energy_j = std::max(x[CellModel::kEnergy], 1e-9);
  v.height_m = x[CellModel::kHeight];
  v.velocity_m_s = x[CellModel::kVelocity];
  v.regulator_pressure_pa =
      params.regulator_time_constant_s > 0.0
          ? x[CellModel::kRegulator]
          : (std::isnan(in.supply_pressure_pa) ? params.supply_pressure_pa : in.supply_pressure_pa);
  for (int i = 0; i < shape_dofs; ++i) v.shape[i] = x[CellModel::kShape + i];
  v.structure = known ? *known : structure.evaluate(v.height_m, v.shape.data());
  v.pressure_pa = pressureFromEnergy(gas, v.internal_energy_j, v.structure.volume_m3);
  v.gauge_pressure_pa = v.pressure_pa - params.ambient_pressure_pa;
  v.temperature_k = temperatureFromEnergy(gas, v.internal_energy_j, v.mass_kg);
  v.load_n = in.load_n;
  v.moving_mass_kg = std::max(params.plate_mass_kg, in.load_n / kGravity);
}

/// The cell pressure the orifices see: the model's, or one given (an observer's measurement).
inline double flowPressure(const CellParams& params, const CellInputs& in, const CellVariables& v) {
  return std::isfinite(in.flow_gauge_pressure_pa) ? params.ambient_pressure_pa + in.flow_gauge_pressure_pa
                                                  : v.pressure_pa;
}

/// The inlet valve's flow from the regulator's outlet into the cell at `flow_pressure_pa`.
inline OrificeFlow inletValve(const CellParams& params, const CellInputs& in, double flow_pressure_pa,
                              const CellVariables& v) {
  const double opening = std::clamp(in.inlet_opening, 0.0, 1.0);
  return orificeFlow(params.gas, opening * params.inlet_area_m2, params.ambient_pressure_pa + v.regulator_pressure_pa,
                     params.supply_temperature_k, flow_pressure_pa, v.temperature_k, params.orifice_linear_band_pa);
}

/// Inlet: a prescribed (metered) series, or the regulator through the inlet valve. Sets the
/// inflow variables; returns the enthalpy flow the inflow brings [W].
inline double inletFlow(const CellParams& params, const CellInputs& in, double flow_pressure_pa, CellVariables* out) {
  const double cp = params.gas.cp();
  CellVariables& v = *out;
  if (in.prescribed_inflow || std::isfinite(in.prescribed_inflow_kg_s)) {
    v.inflow_prescribed = 1.0;
    v.inlet_closed = in.inlet_closed ? 1.0 : 0.0;
    v.metered_inflow_kg_s = in.prescribed_inflow ? in.prescribed_inflow->at(v.time_s) : in.prescribed_inflow_kg_s;
    v.inflow_kg_s = v.metered_inflow_kg_s;
    const double t_in = v.inflow_kg_s >= 0.0 ? params.supply_temperature_k : v.temperature_k;
    return v.inflow_kg_s * cp * t_in;
  }
  v.inflow_prescribed = 0.0;
  const OrificeFlow f = inletValve(params, in, flow_pressure_pa, v);
  v.inflow_kg_s = f.mass_flow_kg_s;
  v.metered_inflow_kg_s = v.inflow_kg_s;
  return v.inflow_kg_s * cp * f.upstream_temperature_k;
}

/// What leaves the cell to ambient besides the effects' flows.
struct Outflows {
  OrificeFlow vent;
  OrificeFlow leak;
  double relief_kg_s = 0.0;
};

/// The relief valve's flow (ISO 6358) at the cell's absolute pressure and temperature.
inline double reliefFlow(const CellParams& params, double pressure_pa, double temperature_k) {
  const double opening = params.reliefOpening(pressure_pa - params.ambient_pressure_pa);
  return opening > 0.0
             ? opening * iso6358MassFlow(params.relief_sonic_conductance_m3_s_pa, params.relief_critical_ratio,
                                         pressure_pa, temperature_k, params.ambient_pressure_pa)
             : 0.0;
}

/// Vent valve and leakage (eq. 17-23 with the choked branch) and the relief valve, for the gas
/// at `temperature_k`.
inline Outflows outflowLaws(const CellParams& params, const CellInputs& in, double flow_pressure_pa,
                            double temperature_k) {
  Outflows o;
  o.vent = orificeFlow(params.gas, std::clamp(in.vent_opening, 0.0, 1.0) * params.vent_area_m2, flow_pressure_pa,
                       temperature_k, params.ambient_pressure_pa + in.vent_back_pressure_pa,
                       params.ambient_temperature_k, params.orifice_linear_band_pa);
  o.leak = orificeFlow(params.gas, params.leak_area_m2, flow_pressure_pa, temperature_k, params.ambient_pressure_pa,
                       params.ambient_temperature_k, params.orifice_linear_band_pa);
  o.relief_kg_s = reliefFlow(params, flow_pressure_pa, temperature_k);
  return o;
}

/// outflowLaws at the variables' temperature; sets the vent and leak flow variables.
inline Outflows outflows(const CellParams& params, const CellInputs& in, double flow_pressure_pa, CellVariables* out) {
  const Outflows o = outflowLaws(params, in, flow_pressure_pa, out->temperature_k);
  out->vent_flow_kg_s = o.vent.mass_flow_kg_s;
  out->leak_flow_kg_s = o.leak.mass_flow_kg_s;
  return o;
}

/// The effects' terms, summed; each effect writes its own states' rates into dx.
inline EffectTerms effectTerms(const std::vector<CellEffectPtr>& effects, const std::vector<int>& offsets,
                               int shape_dofs, const CellParams& params, const CellVariables& v, const StateVector& x,
                               StateVector* dx) {
  EffectTerms terms;
  for (std::size_t i = 0; i < effects.size(); ++i) {
    EffectTerms t;
    const int off = offsets[i];
    effects[i]->contribute(params, v, x.data() + off, &t, dx->data() + off);
    terms.mass_flow_kg_s += t.mass_flow_kg_s;
    terms.enthalpy_flow_w += t.enthalpy_flow_w;
    terms.heat_flow_w += t.heat_flow_w;
    terms.plate_force_n += t.plate_force_n;
    for (int k = 0; k < shape_dofs; ++k) terms.shape_force[k] += t.shape_force[k];
  }
  return terms;
}

/// Mass (eq. 17), film shape and energy: dU/dt = sum mdot h + Q - p dV/dt (eq. 12-16
/// generalised to flow). The film shape relaxes towards dW/dq = p_gauge dV/dq. Sets dV/dt.
inline void gasRates(const CellParams& params, int shape_dofs, double inflow_enthalpy_w, const Outflows& o,
                     const EffectTerms& terms, CellVariables* out, StateVector* rates) {
  const double cp = params.gas.cp();
  CellVariables& v = *out;
  StateVector& dx = *rates;
  const StructureEval& s = v.structure;
  const double outflow_enthalpy_w = o.vent.mass_flow_kg_s * cp * o.vent.upstream_temperature_k +
                                    o.leak.mass_flow_kg_s * cp * o.leak.upstream_temperature_k +
                                    o.relief_kg_s * cp * v.temperature_k;
  dx[CellModel::kMass] = v.inflow_kg_s - v.vent_flow_kg_s - v.leak_flow_kg_s - o.relief_kg_s + terms.mass_flow_kg_s;
  double volume_rate = s.effective_area_m2 * v.velocity_m_s;
  for (int i = 0; i < shape_dofs; ++i) {
    const double imbalance = s.elastic_force[i] + terms.shape_force[i] - v.gauge_pressure_pa * s.dvolume_dshape[i];
    dx[CellModel::kShape + i] = -imbalance / s.shape_damping[i];
    volume_rate += s.dvolume_dshape[i] * dx[CellModel::kShape + i];
  }
  v.volume_rate_m3_s = volume_rate;
  dx[CellModel::kEnergy] =
      inflow_enthalpy_w - outflow_enthalpy_w + terms.enthalpy_flow_w + terms.heat_flow_w - v.pressure_pa * volume_rate;
}

/// Plate: gas force on the effective area against load, guide damping and the bed. Sets the
/// bed contact force.
inline void plateRates(const CellParams& params, const CellInputs& in, const EffectTerms& terms, CellVariables* out,
                       StateVector* rates) {
  CellVariables& v = *out;
  v.bed_contact_force_n = 0.0;
  if (v.height_m < 0.0) {
    // Hunt-Crossley contact k x (1 + alpha dx/dt), x = -h: no force at first touch, and a heavy
    // plate that lands fast stays down instead of bouncing off the bed (it cannot pull).
    v.bed_contact_force_n = std::max(
        0.0, -params.bed_contact_stiffness_n_m * v.height_m * (1.0 - params.bed_contact_damping_s_m * v.velocity_m_s));
  }
  const double net_force = v.gauge_pressure_pa * v.structure.effective_area_m2 - in.load_n -
                           params.plate_damping_n_s_m * v.velocity_m_s + v.bed_contact_force_n + terms.plate_force_n +
                           v.structure.plate_force_n;
  (*rates)[CellModel::kHeight] = v.velocity_m_s;
  (*rates)[CellModel::kVelocity] = net_force / v.moving_mass_kg;
}

/// The pressure-reducing valve's outlet follows its setting with a first-order lag.
inline void regulatorRate(const CellParams& params, const CellInputs& in, const StateVector& x, StateVector* rates) {
  if (params.regulator_time_constant_s > 0.0) {
    const double setting = std::isnan(in.supply_pressure_pa) ? params.supply_pressure_pa : in.supply_pressure_pa;
    (*rates)[CellModel::kRegulator] = (setting - x[CellModel::kRegulator]) / params.regulator_time_constant_s;
  }
}

/// Typical magnitude of each state: finite-difference increments and error tolerances.
StateVector stateScales(int n, int shape_dofs) {
  StateVector scale = StateVector::Constant(n, 1e-3);
  scale[CellModel::kMass] = 1e-4;
  scale[CellModel::kEnergy] = 10.0;
  scale[CellModel::kHeight] = 1e-2;
  scale[CellModel::kVelocity] = 1.0;
  scale[CellModel::kRegulator] = 1e3;
  for (int i = 0; i < shape_dofs; ++i) scale[CellModel::kShape + i] = 1.0;
  return scale;
}

/// Slopes of the net mass [kg/s] and energy [W] flows through the valves, leak and relief with
/// respect to the gas pressure, temperature and regulator pressure: the part of the nominal
/// rate that depends on them. Each orifice's flow scales with 1/sqrt(T_up), so a flow the
/// cell's gas drives has d(mdot)/dT = -mdot / (2 T) and d(mdot cp T)/dT = cp mdot / 2.
struct FlowSlopes {
  double mass_p = 0.0, energy_p = 0.0;
  double mass_t = 0.0, energy_t = 0.0;
  double mass_r = 0.0, energy_r = 0.0;

  /// Adds an orifice whose side a (`cell_is_a`) or b is the cell; `sign` +1 counts its flow into
  /// the cell, -1 out of it.
  void addOrifice(const OrificeFlow& f, bool cell_is_a, double sign, double cp, double temperature_k,
                  bool pressure_state) {
    const double d_cell = cell_is_a ? f.d_flow_d_pa : f.d_flow_d_pb;
    const double d_other = cell_is_a ? f.d_flow_d_pb : f.d_flow_d_pa;
    if (pressure_state) {
      mass_p += sign * d_cell;
      energy_p += sign * cp * f.upstream_temperature_k * d_cell;
    }
    const bool from_cell = cell_is_a ? f.mass_flow_kg_s > 0.0 : f.mass_flow_kg_s < 0.0;
    if (from_cell) {
      mass_t += -sign * f.mass_flow_kg_s / (2.0 * temperature_k);
      energy_t += sign * cp * f.mass_flow_kg_s / 2.0;
    }
    if (!cell_is_a) {  // the inlet: its side a is the regulator
      mass_r += sign * d_other;
      energy_r += sign * cp * f.upstream_temperature_k * d_other;
    }
  }
};

FlowSlopes flowSlopes(const CellParams& params, const CellInputs& in, const CellVariables& v, bool regulator_state) {
  const double cp = params.gas.cp();
  const double t = v.temperature_k;
  // A pressure given to the orifices (an observer's measurement) does not move with the state's.
  const bool pressure_state = !std::isfinite(in.flow_gauge_pressure_pa);
  const double flow_pressure_pa = flowPressure(params, in, v);
  FlowSlopes s;
  if (in.prescribed_inflow || std::isfinite(in.prescribed_inflow_kg_s)) {
    const double metered = in.prescribed_inflow ? in.prescribed_inflow->at(v.time_s) : in.prescribed_inflow_kg_s;
    if (metered < 0.0) s.energy_t += metered * cp;  // a metered outflow carries the gas's enthalpy
  } else {
    s.addOrifice(inletValve(params, in, flow_pressure_pa, v), false, 1.0, cp, t, pressure_state);
  }
  const Outflows o = outflowLaws(params, in, flow_pressure_pa, t);
  s.addOrifice(o.vent, true, -1.0, cp, t, pressure_state);
  s.addOrifice(o.leak, true, -1.0, cp, t, pressure_state);
  if (!regulator_state) s.mass_r = s.energy_r = 0.0;
  // The relief (no pow in its law): by differences of its flow alone.
  const double base = o.relief_kg_s;
  if (pressure_state) {
    const double dp = 1e-7 * flow_pressure_pa;
    const double slope = (reliefFlow(params, flow_pressure_pa + dp, t) - base) / dp;
    s.mass_p -= slope;
    s.energy_p -= slope * cp * t;
  }
  const double dt = 1e-7 * t;
  const double at_t = reliefFlow(params, flow_pressure_pa, t + dt);
  s.mass_t -= (at_t - base) / dt;
  s.energy_t -= (at_t * (t + dt) - base * t) * cp / dt;
  return s;
}

/// How one state moves the variables the nominal rate is built from: pressure, temperature,
/// regulator pressure and the structure (its fields' derivatives, in a StructureEval).
struct ColumnSlopes {
  double pressure = 0.0;
  double temperature = 0.0;
  double regulator = 0.0;
  const StructureEval* structure = nullptr;  // d(field)/dx_j; all zero unless x_j is the height or a shape
};

/// `scratch` holds the structure's derivatives for a column that moves it, and `perturbed`
/// (when given) its evaluation at the perturbed state.
ColumnSlopes columnSlopes(const CellParams& params, const CellStructure& structure, int shape_dofs,
                          const CellVariables& v, int j, StructureEval* scratch, StructureEval* perturbed) {
  static const StructureEval kUnmoved{};
  ColumnSlopes c;
  c.structure = &kUnmoved;
  if (j == CellModel::kMass) {
    c.temperature = -v.temperature_k / v.mass_kg;
  } else if (j == CellModel::kEnergy) {
    c.pressure = v.pressure_pa / v.internal_energy_j;
    c.temperature = v.temperature_k / v.internal_energy_j;
  } else if (j == CellModel::kRegulator) {
    c.regulator = params.regulator_time_constant_s > 0.0 ? 1.0 : 0.0;
  } else if (j == CellModel::kHeight || (j >= CellModel::kShape && j < CellModel::kShape + shape_dofs)) {
    // The structure's second derivatives by forward differences of its evaluation.
    double height = v.height_m;
    std::array<double, kMaxShapeDofs> shape = v.shape;
    const double delta = j == CellModel::kHeight ? 1e-7 * std::max(std::fabs(height), 1e-2)
                                                 : 1e-7 * std::max(std::fabs(shape[j - CellModel::kShape]), 1.0);
    (j == CellModel::kHeight ? height : shape[j - CellModel::kShape]) += delta;
    const StructureEval a = structure.evaluate(height, shape.data());
    if (perturbed) *perturbed = a;
    const StructureEval& b = v.structure;
    *scratch = StructureEval{};
    StructureEval& d = *scratch;
    c.structure = scratch;
    d.volume_m3 = (a.volume_m3 - b.volume_m3) / delta;
    d.effective_area_m2 = (a.effective_area_m2 - b.effective_area_m2) / delta;
    d.plate_force_n = (a.plate_force_n - b.plate_force_n) / delta;
    for (int i = 0; i < shape_dofs; ++i) {
      d.dvolume_dshape[i] = (a.dvolume_dshape[i] - b.dvolume_dshape[i]) / delta;
      d.elastic_force[i] = (a.elastic_force[i] - b.elastic_force[i]) / delta;
      d.shape_damping[i] = (a.shape_damping[i] - b.shape_damping[i]) / delta;
    }
    c.pressure = -v.pressure_pa * d.volume_m3 / b.volume_m3;
  }
  return c;
}

/// What the effects' terms add to the nominal states' rates (gasRates and plateRates are linear
/// in them), written into `part` beside the effect states' own rates.
inline void addTermsPart(const EffectTerms& terms, const CellVariables& v, int shape_dofs, StateVector* part) {
  const StructureEval& s = v.structure;
  StateVector& out = *part;
  out[CellModel::kMass] = terms.mass_flow_kg_s;
  double volume_rate = 0.0;
  for (int i = 0; i < shape_dofs; ++i) {
    out[CellModel::kShape + i] = -terms.shape_force[i] / s.shape_damping[i];
    volume_rate += s.dvolume_dshape[i] * out[CellModel::kShape + i];
  }
  out[CellModel::kEnergy] = terms.enthalpy_flow_w + terms.heat_flow_w - v.pressure_pa * volume_rate;
  out[CellModel::kVelocity] = terms.plate_force_n / v.moving_mass_kg;
}

}  // namespace

CellModel::StateVector CellModel::rateAndEffectPart(double time_s, const StateVector& x, const CellInputs& in,
                                                    CellVariables* vars_out, StateVector* effect_part) const {
  CellVariables local;
  CellVariables* v = vars_out ? vars_out : &local;
  stateVariables(params_, *structure_, shape_dofs_, time_s, x, in, v);
  const double flow_pressure_pa = flowPressure(params_, in, *v);
  const double inflow_enthalpy_w = inletFlow(params_, in, flow_pressure_pa, v);
  const Outflows out = outflows(params_, in, flow_pressure_pa, v);
  StateVector dx = StateVector::Zero(x.size());
  const EffectTerms terms = effectTerms(effects_, effect_offsets_, shape_dofs_, params_, *v, x, &dx);
  if (effect_part) {
    *effect_part = StateVector::Zero(x.size());
    const int nominal = kShape + shape_dofs_;
    effect_part->tail(x.size() - nominal) = dx.tail(x.size() - nominal);
    addTermsPart(terms, *v, shape_dofs_, effect_part);
  }
  gasRates(params_, shape_dofs_, inflow_enthalpy_w, out, terms, v, &dx);
  plateRates(params_, in, terms, v, &dx);
  regulatorRate(params_, in, x, &dx);
  return dx;
}

CellModel::StateMatrix CellModel::jacobian(double time_s, const StateVector& x, const CellInputs& in) const {
  CellVariables v;
  rate(time_s, x, in, &v);
  return jacobianAt(time_s, x, in, v);
}

CellModel::StateMatrix CellModel::jacobianAt(double time_s, const StateVector& x, const CellInputs& in,
                                             const CellVariables& v) const {
  const int n = static_cast<int>(x.size());
  const int nominal = kShape + shape_dofs_;
  if (n == nominal && effects_.empty()) return nominalJacobian(in, v);
  StateMatrix jac = StateMatrix::Zero(n, n);
  PerturbedStructures perturbed;
  jac.topLeftCorner(nominal, nominal) = nominalJacobian(in, v, &perturbed);
  // What the effects add to the rate, by forward differences of that part alone (exactly zero
  // for effects that add nothing, so those leave the nominal step unchanged). The structure
  // depends on the height and the shape only: the other columns reuse its evaluation at x, and
  // those two reuse the nominal part's evaluations at the same perturbed states.
  const StateVector scale = stateScales(n, shape_dofs_);
  const StateVector base = effectPart(time_s, x, in, &v.structure);
  for (int j = 0; j < n; ++j) {
    StateVector xp = x;
    const double dxj = 1e-7 * std::max(std::fabs(x[j]), scale[j]);
    xp[j] += dxj;
    const StructureEval* known = &v.structure;
    if (j == kHeight) known = &perturbed[0];
    if (j >= kShape && j < nominal) known = &perturbed[1 + j - kShape];
    jac.col(j) += (effectPart(time_s, xp, in, known) - base) / dxj;
  }
  return jac;
}

CellModel::StateVector CellModel::effectPart(double time_s, const StateVector& x, const CellInputs& in,
                                             const StructureEval* structure) const {
  CellVariables v;
  stateVariables(params_, *structure_, shape_dofs_, time_s, x, in, &v, structure);
  // The valves' flows enter the rate with and without the effects alike: needed only when an
  // effect reads them.
  if (effects_read_flows_) {
    const double flow_pressure_pa = flowPressure(params_, in, v);
    inletFlow(params_, in, flow_pressure_pa, &v);
    outflows(params_, in, flow_pressure_pa, &v);
  }
  StateVector part = StateVector::Zero(x.size());
  const EffectTerms terms = effectTerms(effects_, effect_offsets_, shape_dofs_, params_, v, x, &part);
  addTermsPart(terms, v, shape_dofs_, &part);
  return part;
}

CellModel::StateMatrix CellModel::nominalJacobian(const CellInputs& in, const CellVariables& v,
                                                  PerturbedStructures* perturbed) const {
  const int n = kShape + shape_dofs_;
  const StructureEval& s = v.structure;
  const double p = v.pressure_pa;
  const double pg = v.gauge_pressure_pa;
  const bool regulator_state = params_.regulator_time_constant_s > 0.0;
  const FlowSlopes flow = flowSlopes(params_, in, v, regulator_state);
  // The film's rates and the volume rate at the state (gasRates without effect forces).
  std::array<double, kMaxShapeDofs> shape_rate{};
  double volume_rate = s.effective_area_m2 * v.velocity_m_s;
  for (int i = 0; i < shape_dofs_; ++i) {
    shape_rate[i] = -(s.elastic_force[i] - pg * s.dvolume_dshape[i]) / s.shape_damping[i];
    volume_rate += s.dvolume_dshape[i] * shape_rate[i];
  }
  // The bed's Hunt-Crossley force F = -k h (1 - alpha v) acts while the plate presses into it
  // (plateRates): dF/dh = -k (1 - alpha v), dF/dv = k alpha h.
  const double k = params_.bed_contact_stiffness_n_m;
  const double alpha = params_.bed_contact_damping_s_m;
  const bool in_contact = v.height_m < 0.0 && 1.0 - alpha * v.velocity_m_s > 0.0;
  StateMatrix jac = StateMatrix::Zero(n, n);
  StructureEval moved;
  for (int j = 0; j < n; ++j) {
    StructureEval* at_perturbed = nullptr;
    if (perturbed && j == kHeight) at_perturbed = &(*perturbed)[0];
    if (perturbed && j >= kShape) at_perturbed = &(*perturbed)[1 + j - kShape];
    const ColumnSlopes c = columnSlopes(params_, *structure_, shape_dofs_, v, j, &moved, at_perturbed);
    const StructureEval& d = *c.structure;
    const double is_velocity = j == kVelocity ? 1.0 : 0.0;
    jac(kMass, j) = flow.mass_p * c.pressure + flow.mass_t * c.temperature + flow.mass_r * c.regulator;
    double volume_rate_slope = d.effective_area_m2 * v.velocity_m_s + s.effective_area_m2 * is_velocity;
    for (int i = 0; i < shape_dofs_; ++i) {
      const double imbalance = s.elastic_force[i] - pg * s.dvolume_dshape[i];
      const double imbalance_slope = d.elastic_force[i] - c.pressure * s.dvolume_dshape[i] - pg * d.dvolume_dshape[i];
      const double slope = -imbalance_slope / s.shape_damping[i] +
                           imbalance * d.shape_damping[i] / (s.shape_damping[i] * s.shape_damping[i]);
      jac(kShape + i, j) = slope;
      volume_rate_slope += d.dvolume_dshape[i] * shape_rate[i] + s.dvolume_dshape[i] * slope;
    }
    jac(kEnergy, j) = flow.energy_p * c.pressure + flow.energy_t * c.temperature + flow.energy_r * c.regulator -
                      c.pressure * volume_rate - p * volume_rate_slope;
    jac(kHeight, j) = is_velocity;
    double force_slope = c.pressure * s.effective_area_m2 + pg * d.effective_area_m2 + d.plate_force_n -
                         params_.plate_damping_n_s_m * is_velocity;
    if (in_contact && j == kHeight) force_slope -= k * (1.0 - alpha * v.velocity_m_s);
    if (in_contact && j == kVelocity) force_slope += k * alpha * v.height_m;
    jac(kVelocity, j) = force_slope / v.moving_mass_kg;
  }
  if (regulator_state) jac(kRegulator, kRegulator) = -1.0 / params_.regulator_time_constant_s;
  return jac;
}

void CellModel::updateJacobian(const CellInputs& in) {
  jacobian_ = jacobianAt(time_, state_, in, vars_);
  jacobian_fresh_ = true;
  steps_since_jacobian_ = 0;
  lu_dt_ = 0.0;
}

double CellModel::attemptStep(double dt, const CellInputs& in, const StateVector& f0, StateVector* next) {
  const int n = stateSize();
  // ROS2 is second order with W = I - gamma dt A for any A: a factorisation made for a step
  // within 25 % of this one (A = J times the ratio of the two) serves it as well.
  if (!(dt <= 1.25 * lu_dt_ && dt >= 0.8 * lu_dt_)) {
    step_matrix_.factor(jacobian_, kRos2Gamma * dt);
    lu_dt_ = dt;
  }
  if (step_matrix_.size() == StepMatrix::kNominalStates) return attemptNominalStep(dt, in, f0, next);
  // Time-dependent input (a prescribed inflow series): its time derivative enters both stages.
  StateVector k1, k2;
  if (in.prescribed_inflow) {
    const StateVector ft = timeDerivativeAt(time_, state_, in, vars_, &effect_part_at_state_);
    k1 = step_matrix_.solve(f0 + kRos2Gamma * dt * ft);
    k2 = step_matrix_.solve(rate(time_ + dt, state_ + dt * k1, in) - 2.0 * k1 - kRos2Gamma * dt * ft);
  } else {
    k1 = step_matrix_.solve(f0);
    k2 = step_matrix_.solve(rate(time_ + dt, state_ + dt * k1, in) - 2.0 * k1);
  }
  *next = state_ + dt * (1.5 * k1 + 0.5 * k2);
  // Local error: the second-order solution minus the embedded first-order x + dt k1, filtered
  // through W^-1 (Hairer and Wanner, Solving ODEs II, IV.8): the stiff components (the plate
  // ringing on its gas spring) that the L-stable step damps no longer shrink the step.
  const StateVector estimate = step_matrix_.solve(0.5 * dt * (k1 + k2));
  double sum = 0.0;
  for (int i = 0; i < n; ++i) {
    const double tol = params_.relative_tolerance * errorScale(i);
    const double e = estimate[i] / tol;
    sum += e * e;
  }
  const double err = std::sqrt(sum / n);
  return std::isfinite(err) && next->allFinite() ? err : 1e10;
}

double CellModel::attemptNominalStep(double dt, const CellInputs& in, const StateVector& f0, StateVector* next) {
  // attemptStep on fixed-size vectors: the same arithmetic without run-time sizes.
  using Vector = StepMatrix::NominalVector;
  constexpr int n = StepMatrix::kNominalStates;
  const Vector x = state_.head<n>();
  Vector ft = Vector::Zero();
  if (in.prescribed_inflow) ft = timeDerivativeAt(time_, state_, in, vars_, &effect_part_at_state_).head<n>();
  const Vector k1 = step_matrix_.solveNominal(f0.head<n>() + kRos2Gamma * dt * ft);
  const StateVector stage = x + dt * k1;
  const Vector k2 = step_matrix_.solveNominal(rate(time_ + dt, stage, in).head<n>() - 2.0 * k1 - kRos2Gamma * dt * ft);
  const Vector x_next = x + dt * (1.5 * k1 + 0.5 * k2);
  *next = x_next;
  const Vector estimate = step_matrix_.solveNominal(0.5 * dt * (k1 + k2));
  Vector tolerance;
  for (int i = 0; i < n; ++i) tolerance[i] = params_.relative_tolerance * errorScale(i);
  const double err = std::sqrt((estimate.cwiseQuotient(tolerance)).squaredNorm() / n);
  return std::isfinite(err) && x_next.allFinite() ? err : 1e10;
}

CellModel::StateVector CellModel::timeDerivative(double time_s, const StateVector& x, const CellInputs& in) const {
  CellVariables v;
  rate(time_s, x, in, &v);
  return timeDerivativeAt(time_s, x, in, v, nullptr);
}

CellModel::StateVector CellModel::timeDerivativeAt(double time_s, const StateVector& x, const CellInputs& in,
                                                   const CellVariables& v, const StateVector* effect_part) const {
  // The nominal rate depends on time through the prescribed inflow series alone: dm/dt gains
  // dq/dt and dU/dt its enthalpy (the supply's temperature in, the gas's out). dq/dt is a
  // forward difference: at a sample (or a rounding short of one) the slope the step goes on with.
  const double dt_fd = 1e-6;
  StateVector ft = StateVector::Zero(x.size());
  if (in.prescribed_inflow) {
    const double metered = in.prescribed_inflow->at(time_s);
    const double dq_dt = (in.prescribed_inflow->at(time_s + dt_fd) - metered) / dt_fd;
    ft[kMass] = dq_dt;
    ft[kEnergy] = dq_dt * params_.gas.cp() * (metered >= 0.0 ? params_.supply_temperature_k : v.temperature_k);
  }
  // Effects may depend on time themselves or through the flows: a forward difference of their
  // part (exactly zero for effects that add nothing).
  if (!effects_.empty()) {
    const StateVector now = effect_part ? *effect_part : effectPart(time_s, x, in, &v.structure);
    ft += (effectPart(time_s + dt_fd, x, in, &v.structure) - now) / dt_fd;
  }
  return ft;
}

void CellModel::integrate(double duration_s, double max_step_s, const CellInputs& in) {
  const int n = stateSize();
  if (scale_.size() != n) scale_ = stateScales(n, shape_dofs_);
  double remaining = duration_s;
  double h = std::min(substep_s_ > 0.0 ? substep_s_ : params_.time_step_s, max_step_s);
  int rejections = 0;
  // The rate at the current state is already known when the inputs did not change. New inputs
  // take a new Jacobian: the error estimate is filtered through (I - gamma h J)^-1, and a J
  // made for other inputs (an inlet opened, a vent shut) hides the next steps' error.
  if (remaining > 1e-15 && (!sameInputs(in, last_inputs_) || rate_at_state_.size() != n)) {
    last_inputs_ = in;
    refreshVariables(in);
    jacobian_fresh_ = false;
    jacobian_tracks_ = false;
    steps_since_jacobian_ = 1 << 30;
  }
  while (remaining > 1e-15) {
    // The last sub-steps reach the end exactly, without a sliver of a step.
    double hs = h;
    if (remaining - hs < 1e-3 * hs) {
      hs = remaining;
    } else if (remaining - hs < 0.1 * hs) {
      hs = 0.5 * remaining;
    }
    const StateVector f0 = rate_at_state_;
    // Long steps make the stiff modes (the plate on its gas spring, the film, the gas through
    // an open orifice) |h lambda| >> 1; only a Jacobian that describes the current state damps
    // them there. One made a few steps before in a changing state leaves them ringing from step
    // to step, so a kept one serves only while the last step's secant confirms it.
    const bool needs_current = hs > kFreshJacobianStepS && !jacobian_tracks_;
    if (!jacobian_fresh_ && (needs_current || steps_since_jacobian_ >= params_.jacobian_refresh_steps))
      updateJacobian(in);
    StateVector next;
    const double err = attemptStep(hs, in, f0, &next);
    if (err <= 1.0 || hs < 1e-9) {
      double proposed = std::min(acceptSubstep(hs, err, next, in), max_step_s);
      if (rejections > 0) proposed = std::min(proposed, hs);  // no growth right after a rejection
      remaining -= hs;
      // A sub-step shortened to reach the end says nothing against the size it was cut from.
      h = hs < h ? std::max(proposed, std::min(h, proposed * 4.0)) : proposed;
      substep_s_ = h;
      rejections = 0;
    } else {
      // Retry at the size the estimate asks for (at most 0.9 of this one), with a Jacobian taken
      // at the current state; halving regardless cycled through rejections on the way back up.
      if (!jacobian_fresh_) updateJacobian(in);
      h = hs * std::clamp(0.9 / std::sqrt(err), 0.1, 0.9);
      if (++rejections > 60) throw std::runtime_error("CellModel::step: no step size meets the tolerance");
    }
  }
}

double CellModel::acceptSubstep(double h, double err, const StateVector& next, const CellInputs& in) {
  // Grow when the error allows, at most doubling.
  const double proposed = h * std::clamp(err > 1e-8 ? 0.9 / std::sqrt(err) : 2.0, 0.2, 2.0);
  // Whether the kept Jacobian still tracks the state matters only before a step longer than
  // kFreshJacobianStepS that the refresh count would not give a new one anyway.
  const bool may_keep = proposed > kFreshJacobianStepS && steps_since_jacobian_ + 1 < params_.jacobian_refresh_steps;
  StateVector dx, rate_before;
  if (may_keep) {
    dx = next - state_;
    rate_before = rate_at_state_;
  }
  const double metered_before = metered_flow_at_state_;
  state_ = next;
  state_[kMass] = std::max(state_[kMass], 1e-12);
  time_ += h;
  refreshVariables(in);
  metered_inlet_mass_kg_ += 0.5 * h * (metered_before + metered_flow_at_state_);
  jacobian_tracks_ = may_keep && jacobianTracksStep(h, dx, rate_before);
  if (++substeps_ > substep_budget_ && substep_budget_ > 0)
    throw std::runtime_error("CellModel::step: more than " + std::to_string(substep_budget_) +
                             " integration steps (too stiff)");
  jacobian_fresh_ = false;
  ++steps_since_jacobian_;
  return proposed;
}

bool CellModel::jacobianTracksStep(double h, const StateVector& dx, const StateVector& rate_before) const {
  // The secant f(x + dx) - f(x) against J dx, in the error norm's weights: a Jacobian that still
  // predicts how the rate changed along the step's path describes the modes the path excites.
  // Below a hundredth of the tolerance over the step, the miss cannot move the solution.
  const int n = stateSize();
  if (jacobian_.rows() != n) return false;
  const double* jac = jacobian_.data();
  const int stride = static_cast<int>(jacobian_.outerStride());
  double predicted[kMaxStates] = {};
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) predicted[i] += jac[i + j * stride] * dx[j];
  double miss_sq = 0.0, change_sq = 0.0;
  for (int i = 0; i < n; ++i) {
    const double change = rate_at_state_[i] - rate_before[i];
    const double scale = errorScale(i);
    const double w_sq = 1.0 / (scale * scale);
    miss_sq += w_sq * (change - predicted[i]) * (change - predicted[i]);
    change_sq += w_sq * change * change;
  }
  const double floor = 1e-2 * params_.relative_tolerance / h;
  return miss_sq <= kSecantTolerance * kSecantTolerance * change_sq || miss_sq <= n * floor * floor;
}

void CellModel::advance(double duration_s, const CellInputs& in) {
  integrate(duration_s, std::max(params_.time_step_s, params_.max_time_step_s), in);
}

void CellModel::setState(double time_s, const StateVector& state, bool keep_jacobian) {
  if (state.size() != state_.size())
    throw std::invalid_argument("setState: expected " + std::to_string(state_.size()) + " states, got " +
                                std::to_string(state.size()));
  state_ = state;
  time_ = time_s;
  jacobian_fresh_ = false;
  jacobian_tracks_ = false;
  if (!keep_jacobian) {
    steps_since_jacobian_ = 1 << 30;
    substep_s_ = 0.0;
  }
  refreshVariables(last_inputs_);
}

void CellModel::refreshVariables(const CellInputs& in) {
  rate_at_state_ = rateAndEffectPart(time_, state_, in, &vars_, effects_.empty() ? nullptr : &effect_part_at_state_);
  metered_flow_at_state_ = effects_.empty() ? vars_.metered_inflow_kg_s : measure().inflow_kg_s;
}

bool CellModel::sameInputs(const CellInputs& a, const CellInputs& b) {
  auto same = [](double x, double y) { return x == y || (std::isnan(x) && std::isnan(y)); };
  return same(a.inlet_opening, b.inlet_opening) && same(a.vent_opening, b.vent_opening) &&
         same(a.vent_back_pressure_pa, b.vent_back_pressure_pa) && same(a.load_n, b.load_n) &&
         same(a.supply_pressure_pa, b.supply_pressure_pa) && a.prescribed_inflow == b.prescribed_inflow &&
         same(a.prescribed_inflow_kg_s, b.prescribed_inflow_kg_s) && a.inlet_closed == b.inlet_closed &&
         same(a.flow_gauge_pressure_pa, b.flow_gauge_pressure_pa);
}

Readings CellModel::measure() const {
  Readings m;
  m.gauge_pressure_pa = vars_.gauge_pressure_pa;
  m.height_m = vars_.height_m;
  m.inflow_kg_s = vars_.metered_inflow_kg_s;
  m.gas_temperature_k = vars_.temperature_k;
  for (std::size_t i = 0; i < effects_.size(); ++i)
    effects_[i]->measure(params_, vars_, state_.data() + effect_offsets_[i], &m);
  return m;
}

}  // namespace nursing_bed
