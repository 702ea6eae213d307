#include "nursing_bed/core/physics/airway.h"

#include <cmath>

#include "nursing_bed/core/io/errors.h"
#include "nursing_bed/core/physics/cell_model.h"

namespace nursing_bed {
namespace {

// The circuit pressure state is kept in units of 100 kPa (absolute), as the effects' are.
constexpr double kPressureStateUnitPa = 1.0e5;

// Gas density of the chamber (the resistor's flow is a volume flow of it).
double chamberDensity(const CellVariables& cell) {
  return cell.structure.volume_m3 > 0.0 ? cell.mass_kg / cell.structure.volume_m3 : 1.2;
}

}  // namespace

Status AirwayParams::validate() const {
  ErrorList errors;
  auto non_negative = [&errors](const char* name, double v) {
    errors.addIf(!(v >= 0.0) || !std::isfinite(v), "airway ", name, " must be >= 0 and finite, got ", v);
  };
  non_negative("volume_m3", volume_m3);
  non_negative("resistance_pa_s_m3", resistance_pa_s_m3);
  non_negative("quadratic_resistance_pa_s2_m6", quadratic_resistance_pa_s2_m6);
  errors.addIf(volume_m3 > 0.0 && resistance_pa_s_m3 <= 0.0 && quadratic_resistance_pa_s2_m6 <= 0.0,
               "airway volume_m3 ", volume_m3,
               " needs a resistance (resistance_pa_s_m3 or quadratic_resistance_pa_s2_m6)");
  return errors.status();
}

double AirwayParams::pressureDrop(double q) const {
  return resistance_pa_s_m3 * q + quadratic_resistance_pa_s2_m6 * q * std::fabs(q);
}

double AirwayParams::flowAt(double dp) const {
  const double r1 = resistance_pa_s_m3, r2 = quadratic_resistance_pa_s2_m6, a = std::fabs(dp);
  // Positive root of r2 q^2 + r1 q - |dp| = 0, in the form that stays exact as r2 -> 0.
  const double q = r2 > 0.0 ? 2.0 * a / (r1 + std::sqrt(r1 * r1 + 4.0 * r2 * a)) : a / r1;
  return std::copysign(q, dp);
}

std::map<std::string, double> AirwayEffect::parameters() const {
  return {{"volume_m3", params_.volume_m3},
          {"resistance_pa_s_m3", params_.resistance_pa_s_m3},
          {"quadratic_resistance_pa_s2_m6", params_.quadratic_resistance_pa_s2_m6}};
}

void AirwayEffect::initialState(const CellParams&, const CellVariables& cell, double* state) const {
  if (stateSize() > 0) state[0] = cell.pressure_pa / kPressureStateUnitPa;  // at rest: no flow
}

void AirwayEffect::contribute(const CellParams& params, const CellVariables& cell, const double* state,
                              EffectTerms* terms, double* state_rate) const {
  if (stateSize() == 0) return;
  const double p_circuit = state[0] * kPressureStateUnitPa;
  const double t_circuit = params.supply_temperature_k;
  const double to_chamber =
      (p_circuit / (params.gas.gas_constant_j_kg_k * t_circuit)) * params_.flowAt(p_circuit - cell.pressure_pa);
  // The metered inflow CellModel put into the chamber fills the circuit instead.
  const double metered = cell.inflow_kg_s;
  const double cp = params.gas.cp();
  auto temperature = [&](double q) { return q >= 0.0 ? t_circuit : cell.temperature_k; };
  terms->mass_flow_kg_s = to_chamber - metered;
  terms->enthalpy_flow_w = cp * (to_chamber * temperature(to_chamber) - metered * temperature(metered));
  // Isothermal circuit: m = p V / (R T).
  state_rate[0] =
      params.gas.gas_constant_j_kg_k * t_circuit / params_.volume_m3 * (metered - to_chamber) / kPressureStateUnitPa;
}

void AirwayEffect::measure(const CellParams&, const CellVariables& cell, const double* state, Readings* m) const {
  if (stateSize() > 0) {
    m->gauge_pressure_pa += state[0] * kPressureStateUnitPa - cell.pressure_pa;
    return;
  }
  m->gauge_pressure_pa += params_.pressureDrop(cell.inflow_kg_s / chamberDensity(cell));
}

}  // namespace nursing_bed
