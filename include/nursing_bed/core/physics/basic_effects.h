// Two effects that plug into CellModel through CellEffect: heat exchange with the film and an
// extra leak. They are also the first of the gap diagnosis' candidate effects.
#pragma once

#include "nursing_bed/core/physics/cell_effect.h"

namespace nursing_bed {

/// Newton heat exchange between the gas and a film held at the wall temperature:
/// Q = h_c A_surface (T_wall - T_gas). h_c = 0 gives back the adiabatic paper model exactly.
/// Plausible h_c for a gas in a closed bag: 2-25 W/(m^2 K) (free convection).
class HeatTransferEffect : public CellEffect {
 public:
  explicit HeatTransferEffect(double coefficient_w_m2_k, double wall_temperature_k = 0.0)
      : coefficient_w_m2_k_(coefficient_w_m2_k), wall_temperature_k_(wall_temperature_k) {}
  std::string name() const override { return "heat_transfer"; }
  std::map<std::string, double> parameters() const override {
    return {{"heat_transfer_coefficient_w_m2_k", coefficient_w_m2_k_}};
  }
  bool readsValveFlows() const override { return false; }
  void contribute(const CellParams& params, const CellVariables& cell, const double* state, EffectTerms* terms,
                  double* state_rate) const override;

 private:
  double coefficient_w_m2_k_;
  double wall_temperature_k_;  // 0: ambient temperature
};

/// Leak through an orifice of effective area A_leak to ambient (seams, film, valve seat),
/// on top of the nominal leak of CellParams. A_leak = 0 is the nominal model.
class LeakEffect : public CellEffect {
 public:
  explicit LeakEffect(double leak_area_m2) : leak_area_m2_(leak_area_m2) {}
  std::string name() const override { return "leak"; }
  std::map<std::string, double> parameters() const override { return {{"leak_area_m2", leak_area_m2_}}; }
  bool readsValveFlows() const override { return false; }
  void contribute(const CellParams& params, const CellVariables& cell, const double* state, EffectTerms* terms,
                  double* state_rate) const override;

 private:
  double leak_area_m2_;
};

}  // namespace nursing_bed
