#include "nursing_bed/core/gap/effects.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include "nursing_bed/core/gap/discovery_terms.h"
#include "nursing_bed/core/gap/distortions.h"
#include "nursing_bed/core/physics/cell_model.h"
#include "nursing_bed/core/physics/orifice.h"
#include "nursing_bed/core/physics/pillow_structure.h"

namespace nursing_bed {
namespace {

// Pressure states are kept in units of 100 kPa (absolute): see the header.
constexpr double kPressureStateUnitPa = 1.0e5;

// Temperature that an inlet flow q carries: supply air in, cell gas out (as CellModel does).
double inletFlowTemperature(const CellParams& params, const CellVariables& cell, double q) {
  return q >= 0.0 ? params.supply_temperature_k : cell.temperature_k;
}

std::string shortNumber(double v) {
  char buf[64];
  const auto r = std::to_chars(buf, buf + sizeof(buf), v);
  return std::string(buf, r.ptr);
}

EffectParamSpec param(const std::string& name, const std::string& unit, const std::string& description, double off,
                      double lo, double hi, bool log_scale, double min_value, double max_value,
                      bool symmetric = false) {
  EffectParamSpec p;
  p.name = name;
  p.unit = unit;
  p.description = description;
  p.off_value = off;
  p.lo = lo;
  p.hi = hi;
  p.log_scale = log_scale;
  p.symmetric = symmetric;
  p.min_value = min_value;
  p.max_value = max_value;
  return p;
}

/// Out-of-library effects for the blind check: the generator plants them, the diagnosis never fits them.
std::vector<EffectSpec> testOnlyEffects() {
  constexpr bool kTestOnly = false;
  return {
      {"ambient_drift",
       kTestOnly,
       "gas exchanges heat (8 W/(m^2 K)) with surroundings whose temperature drifts linearly",
       "pressure drifts during hold, up or down, steadily over the whole run",
       "drift_k_s",
       {param("drift_k_s", "K/s", "drift rate of the surroundings' temperature", 0.0, 0.02, 0.1, false, -1.0, 1.0,
              true)},
       "",
       "",
       ""},
      {"pressure_offset_drift",
       kTestOnly,
       "the pressure sensor's zero drifts linearly with time",
       "pressure reading offset growing linearly with time, whatever the cell does",
       "drift_pa_s",
       {param("drift_pa_s", "Pa/s", "drift rate of the pressure reading", 0.0, 1.0, 5.0, false, -100.0, 100.0, true)},
       "",
       "",
       ""},
      {"plate_quadratic_drag",
       kTestOnly,
       "aerodynamic-like drag on the plate, F = -c_d |v| v",
       "pressure offset growing with the square of the plate speed, against the motion",
       "drag_coefficient_n_s2_m2",
       {param("drag_coefficient_n_s2_m2", "N s^2/m^2", "drag coefficient c_d", 0.0, 300.0, 3000.0, true, 0.0, 1e5)},
       "",
       "",
       ""},
      {"power_leak",
       kTestOnly,
       "leak through the film whose flow follows a power of the gauge pressure: q = q_ref (p / 10 kPa)^n",
       "pressure and height keep falling during hold, faster at high pressure than an orifice's",
       "leak_flow_kg_s",
       {param("leak_flow_kg_s", "kg/s", "leak flow q_ref at 10 kPa gauge", 0.0, 1e-6, 5e-6, true, 0.0, 1e-4),
        param("exponent", "-", "pressure exponent n (any value is off when q_ref = 0)", 1.0, 1.0, 2.0, false, 0.5,
              4.0)},
       "",
       "",
       ""},
  };
}

std::vector<EffectSpec> makeCatalog() {
  constexpr bool kCandidate = true;
  std::vector<EffectSpec> catalog{
      {"heat_transfer",
       kCandidate,
       "gas exchanges heat with the film at ambient temperature: Q = h_c A_surface (T_amb - T)",
       "pressure relaxes towards a lower plateau after inflow stops",
       "heat_transfer_coefficient_w_m2_k",
       {param("heat_transfer_coefficient_w_m2_k", "W/(m^2 K)", "heat transfer coefficient h_c", 0.0, 2.0, 25.0, true,
              0.0, 500.0)},
       "",
       "",
       ""},
      {"leak",
       kCandidate,
       "extra leak to ambient through an orifice (seams, film, valve seat)",
       "pressure and height keep falling during hold",
       "leak_area_m2",
       {param("leak_area_m2", "m^2", "effective leak area Cd*A", 0.0, 3e-9, 5e-8, true, 0.0, 1e-5)},
       "",
       "",
       ""},
      {"membrane_viscoelasticity",
       kCandidate,
       "standard-linear-solid branch on the film: creep and stress relaxation of the TPU",
       "height creeps at constant mass; loading/unloading loops differ",
       "relative_stiffness",
       {param("relaxation_time_s", "s", "relaxation time tau of the branch (any value is off when g = 0)", 10.0, 3.0,
              60.0, true, 0.01, 3600.0),
        param("relative_stiffness", "-", "branch stiffness g relative to the film's elastic law", 0.0, 0.1, 0.5, true,
              0.0, 5.0)},
       "pillow",
       "",
       ""},
      {"pressure_sensor_lag",
       kCandidate,
       "first-order lag of the pressure reading (sensor, tubing)",
       "pressure trace phase-shifted, worst where dp/dt is large",
       "time_constant_s",
       {param("time_constant_s", "s", "time constant of the reading", 0.0, 0.05, 1.0, true, 0.0, 10.0)},
       "",
       "pressure",
       "lag"},
      {"supply_line",
       kCandidate,
       "tube between meter/valve and cell: isothermal dead volume and an orifice; pressure read in it",
       "pressure reads high while flowing (low while venting), drops when the flow stops",
       "line_volume_m3",
       {param("line_volume_m3", "m^3", "gas volume of the line", 0.0, 5e-6, 1e-4, true, 0.0, 1e-3),
        param("line_area_m2", "m^2",
              "effective area Cd*A between line and cell (any value is off when the volume is 0)", 1e-5, 2e-6, 3e-5,
              true, 1e-7, 1e-3)},
       "",
       "",
       ""},
      {"inflow_bias",
       kCandidate,
       "flow meter reads (1 + k) q_true + b",
       "accumulated mass error grows with integrated flow (and with time through b)",
       "",
       {param("scale_error", "-", "relative scale error k of the flow meter", 0.0, -0.15, 0.15, false, -0.5, 0.5),
        param("offset_kg_s", "kg/s", "zero offset b of the flow meter", 0.0, -2e-5, 2e-5, false, -1e-3, 1e-3)},
       "",
       "inflow",
       "gain+offset"},
      {"plate_friction",
       kCandidate,
       "Coulomb friction in the plate guide, F = -F_c tanh(v / 1 mm/s)",
       "pressure offset +-F_c/A_eff that flips sign with the motion; h(p) loop widens",
       "friction_force_n",
       {param("friction_force_n", "N", "Coulomb friction force F_c", 0.0, 0.6, 3.0, true, 0.0, 50.0)},
       "",
       "",
       ""},
  };
  for (auto& e : testOnlyEffects()) catalog.push_back(std::move(e));
  return catalog;
}

}  // namespace

// ---- catalogue -------------------------------------------------------------------------------

std::map<std::string, double> EffectSpec::offParams() const {
  std::map<std::string, double> out;
  for (const auto& p : params) out[p.name] = p.off_value;
  return out;
}

const EffectParamSpec* EffectSpec::param(const std::string& key) const {
  for (const auto& p : params)
    if (p.name == key) return &p;
  return nullptr;
}

const std::vector<EffectSpec>& effectCatalog() {
  static const std::vector<EffectSpec> catalog = makeCatalog();
  return catalog;
}

const EffectSpec& effectSpec(const std::string& name) {
  for (const auto* catalog : {&effectCatalog(), &distortionCatalog(), &discoveryCatalog()})
    for (const auto& e : *catalog)
      if (e.name == name) return e;
  std::vector<EffectSpec> all = effectCatalog();
  all.insert(all.end(), distortionCatalog().begin(), distortionCatalog().end());
  all.insert(all.end(), discoveryCatalog().begin(), discoveryCatalog().end());
  catalogEntry(all, name, "effect");  // throws, naming every known effect
  throw std::logic_error("effectSpec: '" + name + "' not found");
}

std::vector<std::string> candidateEffectNames() {
  std::vector<std::string> out;
  for (const auto& e : effectCatalog())
    if (e.candidate) out.push_back(e.name);
  return out;
}

CellEffectPtr makeEffect(const std::string& name, const std::map<std::string, double>& params) {
  const EffectSpec& spec = effectSpec(name);
  std::string expected;
  for (const auto& p : spec.params) expected += (expected.empty() ? "" : ", ") + p.name;
  for (const auto& [key, value] : params) {
    const EffectParamSpec* p = spec.param(key);
    if (!p)
      throw std::invalid_argument("effect '" + name + "': unknown parameter '" + key + "' (expected: " + expected +
                                  ")");
    if (!std::isfinite(value) || value < p->min_value || value > p->max_value)
      throw std::invalid_argument("effect '" + name + "': parameter " + key + " = " + shortNumber(value) +
                                  " is outside the admissible range [" + shortNumber(p->min_value) + ", " +
                                  shortNumber(p->max_value) + "] " + p->unit);
  }
  for (const auto& p : spec.params)
    if (!params.count(p.name))
      throw std::invalid_argument("effect '" + name + "': missing parameter '" + p.name + "' (expected: " + expected +
                                  ")");
  auto v = [&params](const char* key) { return params.at(key); };
  if (name == "heat_transfer") return std::make_shared<HeatTransferEffect>(v("heat_transfer_coefficient_w_m2_k"));
  if (name == "leak") return std::make_shared<LeakEffect>(v("leak_area_m2"));
  if (name == "membrane_viscoelasticity")
    return std::make_shared<MembraneViscoelasticityEffect>(v("relaxation_time_s"), v("relative_stiffness"));
  if (name == "inflow_bias") return std::make_shared<InflowBiasEffect>(v("scale_error"), v("offset_kg_s"));
  if (name == "pressure_sensor_lag") return std::make_shared<PressureSensorLagEffect>(v("time_constant_s"));
  if (name == "supply_line") return std::make_shared<SupplyLineEffect>(v("line_volume_m3"), v("line_area_m2"));
  if (name == "plate_friction") return std::make_shared<PlateFrictionEffect>(v("friction_force_n"));
  if (name == "ambient_drift") return std::make_shared<AmbientDriftEffect>(v("drift_k_s"));
  if (name == "pressure_offset_drift") return std::make_shared<PressureOffsetDriftEffect>(v("drift_pa_s"));
  if (name == "plate_quadratic_drag") return std::make_shared<PlateQuadraticDragEffect>(v("drag_coefficient_n_s2_m2"));
  if (name == "power_leak") return std::make_shared<PowerLeakEffect>(v("leak_flow_kg_s"), v("exponent"));
  if (const DictionaryTerm* term = dictionaryTerm(name))
    return std::make_shared<DiscoveredTermEffect>(*term, v(spec.params.front().name.c_str()));
  if (!spec.channel.empty()) {
    const EffectParamSpec& p = spec.params.front();
    return std::make_shared<ChannelDistortionEffect>(name, spec.channel, spec.kind, p.name, v(p.name.c_str()));
  }
  throw std::logic_error("makeEffect: catalogue effect '" + name + "' has no factory");
}

void sortEffectsForModel(std::vector<CellEffectPtr>* effects) {
  const auto& catalog = effectCatalog();
  auto rank = [&catalog](const CellEffectPtr& e) {
    for (std::size_t i = 0; i < catalog.size(); ++i)
      if (catalog[i].name == e->name()) return i;
    return catalog.size();
  };
  std::stable_sort(effects->begin(), effects->end(),
                   [&rank](const CellEffectPtr& a, const CellEffectPtr& b) { return rank(a) < rank(b); });
}

std::map<std::string, double> randomEffectParams(const std::string& name, std::mt19937& rng) {
  const EffectSpec& spec = effectSpec(name);
  std::map<std::string, double> out;
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  for (const auto& p : spec.params) {
    const double u = unit(rng);
    double x =
        p.log_scale ? std::exp(std::log(p.lo) + u * (std::log(p.hi) - std::log(p.lo))) : p.lo + u * (p.hi - p.lo);
    if (p.symmetric && unit(rng) < 0.5) x = -x;
    out[p.name] = x;
  }
  return out;
}

std::string describeEffect(const std::string& name, const std::map<std::string, double>& params) {
  std::string s = name + "(";
  bool first = true;
  for (const auto& [k, v] : params) {
    s += (first ? "" : ", ") + k + "=" + shortNumber(v);
    first = false;
  }
  return s + ")";
}

// ---- membrane_viscoelasticity ----------------------------------------------------------------

std::map<std::string, double> MembraneViscoelasticityEffect::parameters() const {
  return {{"relaxation_time_s", relaxation_time_s_}, {"relative_stiffness", relative_stiffness_}};
}

void MembraneViscoelasticityEffect::initialState(const CellParams&, const CellVariables& cell, double* state) const {
  if (stateSize() > 0) state[0] = cell.shape[0];  // relaxed: the branch carries no force
}

void MembraneViscoelasticityEffect::contribute(const CellParams& params, const CellVariables& cell, const double* state,
                                               EffectTerms* terms, double* state_rate) const {
  if (relative_stiffness_ == 0.0) return;
  const double stretch = cell.shape[0];
  const double internal_stretch = state[0];
  // The film's elastic force at the internal stretch, as the structure gives it at the stretch.
  const double force_at_internal = PillowStructure::elasticForce(params.structure, internal_stretch);
  terms->shape_force[0] = relative_stiffness_ * (cell.structure.elastic_force[0] - force_at_internal);
  state_rate[0] = (stretch - internal_stretch) / relaxation_time_s_;
}

// ---- inflow_bias -----------------------------------------------------------------------------

std::map<std::string, double> InflowBiasEffect::parameters() const {
  return {{"scale_error", scale_error_}, {"offset_kg_s", offset_kg_s_}};
}

void InflowBiasEffect::contribute(const CellParams& params, const CellVariables& cell, const double*,
                                  EffectTerms* terms, double*) const {
  if (off() || cell.inflow_prescribed != 1.0) return;
  // The prescribed series is what the meter read; the cell receives the true flow.
  const double metered = cell.metered_inflow_kg_s;
  // A closed inlet (the diagnosis' replay zeroes the meter's noise there, zeroClosedInletFlow):
  // no gas flows, whatever the meter's error.
  if (cell.inlet_closed == 1.0) return;
  const double truth = (metered - offset_kg_s_) / (1.0 + scale_error_);
  const double cp = params.gas.cp();
  terms->mass_flow_kg_s = truth - metered;
  terms->enthalpy_flow_w =
      cp * (truth * inletFlowTemperature(params, cell, truth) - metered * inletFlowTemperature(params, cell, metered));
}

void InflowBiasEffect::measure(const CellParams&, const CellVariables& cell, const double*, Readings* m) const {
  if (off() || cell.inflow_prescribed == 1.0) return;  // a prescribed series is already the reading
  m->inflow_kg_s = (1.0 + scale_error_) * m->inflow_kg_s + offset_kg_s_;
}

// ---- pressure_sensor_lag ---------------------------------------------------------------------

void PressureSensorLagEffect::initialState(const CellParams&, const CellVariables& cell, double* state) const {
  if (stateSize() > 0) state[0] = cell.pressure_pa / kPressureStateUnitPa;
}

void PressureSensorLagEffect::contribute(const CellParams&, const CellVariables& cell, const double* state,
                                         EffectTerms*, double* state_rate) const {
  if (stateSize() == 0) return;
  state_rate[0] = (cell.pressure_pa / kPressureStateUnitPa - state[0]) / time_constant_s_;
}

void PressureSensorLagEffect::measure(const CellParams&, const CellVariables& cell, const double* state,
                                      Readings* m) const {
  if (stateSize() == 0) return;
  m->gauge_pressure_pa += state[0] * kPressureStateUnitPa - cell.pressure_pa;
}

// ---- supply_line -----------------------------------------------------------------------------

std::map<std::string, double> SupplyLineEffect::parameters() const {
  return {{"line_volume_m3", line_volume_m3_}, {"line_area_m2", line_area_m2_}};
}

void SupplyLineEffect::initialState(const CellParams&, const CellVariables& cell, double* state) const {
  if (stateSize() > 0) state[0] = cell.pressure_pa / kPressureStateUnitPa;  // line at the cell's pressure
}

double SupplyLineEffect::lineInflow(const CellParams& params, const CellVariables& cell,
                                    double line_pressure_pa) const {
  if (cell.inflow_prescribed == 1.0) return cell.metered_inflow_kg_s;
  // Valve-driven: the inlet valve sits between the regulator and the line, but CellModel
  // computed its flow against the cell's pressure. The orifice law is linear in the area, so
  // the valve's open area is that flow over the flow of a unit area at the same pressures.
  const double p_supply = params.ambient_pressure_pa + cell.regulator_pressure_pa;
  const double unit_flow = orificeFlow(params.gas, 1.0, p_supply, params.supply_temperature_k, cell.pressure_pa,
                                       cell.temperature_k, params.orifice_linear_band_pa)
                               .mass_flow_kg_s;
  if (unit_flow == 0.0 || cell.inflow_kg_s == 0.0) return 0.0;
  const double open_area = std::max(0.0, cell.inflow_kg_s / unit_flow);
  return orificeFlow(params.gas, open_area, p_supply, params.supply_temperature_k, line_pressure_pa,
                     params.supply_temperature_k, params.orifice_linear_band_pa)
      .mass_flow_kg_s;
}

void SupplyLineEffect::contribute(const CellParams& params, const CellVariables& cell, const double* state,
                                  EffectTerms* terms, double* state_rate) const {
  if (stateSize() == 0) return;
  const double t_line = params.supply_temperature_k;
  const double p_line = state[0] * kPressureStateUnitPa;
  const double cp = params.gas.cp();
  // Line -> cell through the orifice (either way).
  const OrificeFlow to_cell = orificeFlow(params.gas, line_area_m2_, p_line, t_line, cell.pressure_pa,
                                          cell.temperature_k, params.orifice_linear_band_pa);
  // The inlet flow CellModel put into the cell goes into the line instead: take it back out.
  const double direct = cell.inflow_kg_s;
  terms->mass_flow_kg_s = to_cell.mass_flow_kg_s - direct;
  terms->enthalpy_flow_w = cp * (to_cell.mass_flow_kg_s * to_cell.upstream_temperature_k -
                                 direct * inletFlowTemperature(params, cell, direct));
  // Isothermal line: dm/dt = q_in - q_to_cell, m = p V / (R T).
  const double into_line = lineInflow(params, cell, p_line);
  state_rate[0] = params.gas.gas_constant_j_kg_k * t_line / line_volume_m3_ * (into_line - to_cell.mass_flow_kg_s) /
                  kPressureStateUnitPa;
}

void SupplyLineEffect::measure(const CellParams& params, const CellVariables& cell, const double* state,
                               Readings* m) const {
  if (stateSize() == 0) return;
  const double p_line = state[0] * kPressureStateUnitPa;
  m->gauge_pressure_pa += p_line - cell.pressure_pa;
  // The meter sits upstream of the line: valve-driven, it reads the valve's flow into the line.
  if (cell.inflow_prescribed != 1.0) m->inflow_kg_s += lineInflow(params, cell, p_line) - cell.metered_inflow_kg_s;
}

// ---- plate_friction --------------------------------------------------------------------------

void PlateFrictionEffect::contribute(const CellParams&, const CellVariables& cell, const double*, EffectTerms* terms,
                                     double*) const {
  if (friction_force_n_ == 0.0) return;
  terms->plate_force_n = -friction_force_n_ * std::tanh(cell.velocity_m_s / kSmoothingSpeedMS);
}

// ---- ambient_drift ---------------------------------------------------------------------------

void AmbientDriftEffect::contribute(const CellParams& params, const CellVariables& cell, const double*,
                                    EffectTerms* terms, double*) const {
  if (drift_k_s_ == 0.0) return;
  const double surroundings_k = params.ambient_temperature_k + drift_k_s_ * cell.time_s;
  terms->heat_flow_w =
      kExchangeCoefficientWM2K * cell.structure.surface_area_m2 * (surroundings_k - cell.temperature_k);
}

// ---- pressure_offset_drift -------------------------------------------------------------------

void PressureOffsetDriftEffect::measure(const CellParams&, const CellVariables& cell, const double*,
                                        Readings* m) const {
  if (drift_pa_s_ == 0.0) return;
  m->gauge_pressure_pa += drift_pa_s_ * cell.time_s;
}

// ---- plate_quadratic_drag --------------------------------------------------------------------

void PlateQuadraticDragEffect::contribute(const CellParams&, const CellVariables& cell, const double*,
                                          EffectTerms* terms, double*) const {
  if (drag_coefficient_n_s2_m2_ == 0.0) return;
  terms->plate_force_n = -drag_coefficient_n_s2_m2_ * std::abs(cell.velocity_m_s) * cell.velocity_m_s;
}

// ---- power_leak ------------------------------------------------------------------------------

std::map<std::string, double> PowerLeakEffect::parameters() const {
  return {{"leak_flow_kg_s", leak_flow_kg_s_}, {"exponent", exponent_}};
}

void PowerLeakEffect::contribute(const CellParams& params, const CellVariables& cell, const double*, EffectTerms* terms,
                                 double*) const {
  if (leak_flow_kg_s_ == 0.0 || cell.gauge_pressure_pa <= 0.0) return;
  // Outflow only; the gas leaves with its own temperature.
  const double q = leak_flow_kg_s_ * std::pow(cell.gauge_pressure_pa / kReferencePressurePa, exponent_);
  terms->mass_flow_kg_s = -q;
  terms->enthalpy_flow_w = -q * params.gas.cp() * cell.temperature_k;
}

}  // namespace nursing_bed
