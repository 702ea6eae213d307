#include "nursing_bed/core/gap/discovery_terms.h"

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <sstream>

#include "nursing_bed/core/physics/cell_model.h"

namespace nursing_bed {
namespace {

// A typical state and a strong correction (see DictionaryTerm::scale).
constexpr double kSpeedMS = 0.05, kHeightM = 0.1, kPressurePa = 1.0e4, kTemperatureK = 10.0;
constexpr double kForceN = 3.0, kMassFlowKgS = 5.0e-6, kHeatW = 3.0;
// sign(v) smoothed as plate_friction is, so that the integrator sees a continuous force.
constexpr double kSmoothingSpeedMS = 1.0e-3;

double speed(const CellParams&, const CellVariables& c) { return c.velocity_m_s; }
double speedSquared(const CellParams&, const CellVariables& c) { return std::abs(c.velocity_m_s) * c.velocity_m_s; }
double direction(const CellParams&, const CellVariables& c) { return std::tanh(c.velocity_m_s / kSmoothingSpeedMS); }
double height(const CellParams&, const CellVariables& c) { return c.height_m; }
double pressure(const CellParams&, const CellVariables& c) { return c.gauge_pressure_pa; }
double rootPressure(const CellParams&, const CellVariables& c) {
  return std::copysign(std::sqrt(std::abs(c.gauge_pressure_pa)), c.gauge_pressure_pa);
}
double pressureToOneAndAHalf(const CellParams&, const CellVariables& c) {
  return std::copysign(std::pow(std::abs(c.gauge_pressure_pa), 1.5), c.gauge_pressure_pa);
}
double pressureSquared(const CellParams&, const CellVariables& c) {
  return std::abs(c.gauge_pressure_pa) * c.gauge_pressure_pa;
}
double pressureHeight(const CellParams&, const CellVariables& c) { return c.gauge_pressure_pa * c.height_m; }
double excessTemperature(const CellParams& p, const CellVariables& c) {
  return c.temperature_k - p.ambient_temperature_k;
}

std::vector<DictionaryTerm> makeDictionary() {
  using B = Balance;
  const double v = kSpeedMS, h = kHeightM, p = kPressurePa;
  return {
      {"discovered_plate_v", B::kPlateForce, "v", "N·s/m", speed, kForceN / v},
      {"discovered_plate_abs_v_v", B::kPlateForce, "|v|v", "N·s²/m²", speedSquared, kForceN / (v * v)},
      {"discovered_plate_sign_v", B::kPlateForce, "sign(v)", "N", direction, kForceN},
      {"discovered_plate_h", B::kPlateForce, "h", "N/m", height, kForceN / h},
      {"discovered_plate_p", B::kPlateForce, "p", "m²", pressure, kForceN / p},
      {"discovered_mass_p", B::kGasMass, "p", "kg/(s·Pa)", pressure, kMassFlowKgS / p},
      {"discovered_mass_sqrt_p", B::kGasMass, "sqrt(p)", "kg/(s·Pa^0.5)", rootPressure, kMassFlowKgS / std::sqrt(p)},
      {"discovered_mass_p_1_5", B::kGasMass, "p^1.5", "kg/(s·Pa^1.5)", pressureToOneAndAHalf,
       kMassFlowKgS / std::pow(p, 1.5)},
      {"discovered_mass_p_p", B::kGasMass, "|p|p", "kg/(s·Pa²)", pressureSquared, kMassFlowKgS / (p * p)},
      {"discovered_mass_p_h", B::kGasMass, "p·h", "kg/(s·Pa·m)", pressureHeight, kMassFlowKgS / (p * h)},
      {"discovered_energy_dt", B::kGasEnergy, "(T − T_amb)", "W/K", excessTemperature, kHeatW / kTemperatureK},
  };
}

EffectSpec specOf(const DictionaryTerm& t) {
  EffectSpec e;
  e.name = t.name;
  e.candidate = false;
  e.description = balanceName(t.balance) + " correction c · " + t.function;
  e.signature = "found by the discovery, never fitted as a candidate";
  EffectParamSpec c;
  c.name = t.name.substr(std::string("discovered_").size()) + "_coefficient";
  c.unit = t.unit;
  c.description = "coefficient c of " + t.function;
  c.off_value = 0.0;
  // Linear axis through 0: either sign is a correction.
  c.lo = -t.scale;
  c.hi = t.scale;
  c.min_value = -100.0 * t.scale;
  c.max_value = 100.0 * t.scale;
  e.switch_param = c.name;
  e.params = {c};
  return e;
}

}  // namespace

const std::vector<DictionaryTerm>& discoveryDictionary() {
  static const std::vector<DictionaryTerm> dictionary = makeDictionary();
  return dictionary;
}

const std::vector<EffectSpec>& discoveryCatalog() {
  static const std::vector<EffectSpec> catalog = [] {
    std::vector<EffectSpec> out;
    for (const auto& t : discoveryDictionary()) out.push_back(specOf(t));
    return out;
  }();
  return catalog;
}

const DictionaryTerm* dictionaryTerm(const std::string& name) {
  for (const auto& t : discoveryDictionary())
    if (t.name == name) return &t;
  return nullptr;
}

std::string balanceName(Balance balance) {
  switch (balance) {
    case Balance::kPlateForce: return "plate force";
    case Balance::kGasMass: return "gas mass";
    case Balance::kGasEnergy: return "gas energy";
  }
  return "";
}

std::string termEquation(const DictionaryTerm& term, double coefficient) {
  // Three significant digits, positional between 1e-3 and 1e6 ("-1510", "0.42"), else scientific.
  std::ostringstream s;
  const double magnitude = std::abs(coefficient);
  if (magnitude >= 1e-3 && magnitude < 1e6) {
    const int decimals = std::max(0, 2 - static_cast<int>(std::floor(std::log10(magnitude))));
    const double step = std::pow(10.0, std::max(0, static_cast<int>(std::floor(std::log10(magnitude))) - 2));
    s << std::fixed << std::setprecision(decimals) << std::round(coefficient / step) * step;
  } else {
    s << std::setprecision(3) << coefficient;
  }
  std::string number = s.str();
  if (coefficient < 0.0) number = "−" + number.substr(1);
  return balanceName(term.balance) + ": " + number + " " + term.unit + " · " + term.function;
}

std::map<std::string, double> DiscoveredTermEffect::parameters() const {
  for (const auto& e : discoveryCatalog())
    if (e.name == term_.name) return {{e.params.front().name, coefficient_}};
  return {};
}

void DiscoveredTermEffect::contribute(const CellParams& params, const CellVariables& cell, const double*,
                                      EffectTerms* terms, double*) const {
  if (coefficient_ == 0.0) return;
  const double value = coefficient_ * term_.evaluate(params, cell);
  switch (term_.balance) {
    case Balance::kPlateForce: terms->plate_force_n = value; break;
    case Balance::kGasMass: {
      const double t_k = value < 0.0 ? cell.temperature_k : params.ambient_temperature_k;
      terms->mass_flow_kg_s = value;
      terms->enthalpy_flow_w = value * params.gas.cp() * t_k;
      break;
    }
    case Balance::kGasEnergy: terms->heat_flow_w = value; break;
  }
}

}  // namespace nursing_bed
