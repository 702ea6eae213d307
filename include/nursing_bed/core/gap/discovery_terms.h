// The dictionary of the discovery (doc/gap_diagnosis.md, "Discovery"): state functions that may
// enter one of the cell model's balance equations (plate force, gas mass, gas energy) as an
// additive correction c * f(state), each with the unit of its coefficient. A term is an effect
// (CellEffect) with one parameter, its coefficient; 0 is off, the nominal model bit for bit.
#pragma once

#include <string>
#include <vector>

#include "nursing_bed/core/gap/effects.h"
#include "nursing_bed/core/physics/cell_effect.h"

namespace nursing_bed {

/// The balance equation a dictionary term corrects.
enum class Balance { kPlateForce, kGasMass, kGasEnergy };

/// One state function of the dictionary.
struct DictionaryTerm {
  std::string name;      ///< effect name, "discovered_<balance>_<function>"
  Balance balance;       ///< where c * f enters: upward plate force [N], dm/dt [kg/s], heat into the gas [W]
  std::string function;  ///< f for people ("|v|v", "sqrt(p)")
  std::string unit;      ///< unit of the coefficient for people ("N·s²/m²")
  /// f of the cell's state (v plate velocity [m/s], h height [m], p gauge pressure [Pa], T gas
  /// temperature [K]).
  double (*evaluate)(const CellParams& params, const CellVariables& cell);
  /// Coefficient whose term reaches a strong correction (3 N, 5 mg/s, 3 W) at a typical state
  /// (0.05 m/s, 0.1 m, 10 kPa, 10 K): the fit's plausible range is [-scale, scale].
  double scale;
};

/// The dictionary, plate force first, then gas mass, then gas energy.
const std::vector<DictionaryTerm>& discoveryDictionary();
/// The dictionary as effect specs (one parameter each, "<name minus discovered_>_coefficient",
/// off value 0, never a candidate), dictionary order.
const std::vector<EffectSpec>& discoveryCatalog();
/// The dictionary term of that effect name, or null.
const DictionaryTerm* dictionaryTerm(const std::string& name);
/// "plate force", "gas mass", "gas energy".
std::string balanceName(Balance balance);
/// "plate force: -420 N·s²/m² · |v|v" (coefficient to 3 significant digits).
std::string termEquation(const DictionaryTerm& term, double coefficient);

/// A dictionary term with its coefficient, added to its balance. Outflow of gas (a negative mass
/// term) carries the gas's enthalpy, inflow that of ambient air.
class DiscoveredTermEffect : public CellEffect {
 public:
  DiscoveredTermEffect(const DictionaryTerm& term, double coefficient) : term_(term), coefficient_(coefficient) {}
  std::string name() const override { return term_.name; }
  std::map<std::string, double> parameters() const override;
  void contribute(const CellParams& params, const CellVariables& cell, const double* state, EffectTerms* terms,
                  double* state_rate) const override;

 private:
  const DictionaryTerm& term_;
  double coefficient_;
};

}  // namespace nursing_bed
