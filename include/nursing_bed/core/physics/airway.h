// A series airway between the flow meter and pressure sensor (both at the supply: a ventilator)
// and the chamber: a circuit volume and a resistor of linear and quadratic law. Configured in a
// parameter file under `airway/` (doc/cell_model.md#the-series-airway); part of the nominal
// model of every cell that has one.
#pragma once

#include <string>

#include "nursing_bed/core/io/status.h"
#include "nursing_bed/core/physics/cell_effect.h"

namespace nursing_bed {

/// Numbers of the airway. All zero: no airway (the meter and sensor are at the chamber).
struct AirwayParams {
  double volume_m3 = 0.0;                      ///< circuit gas volume upstream of the resistor [m^3]
  double resistance_pa_s_m3 = 0.0;             ///< R1 of dp = R1 q + R2 q |q|, q volume flow [Pa s/m^3]
  double quadratic_resistance_pa_s2_m6 = 0.0;  ///< R2 [Pa s^2/m^6]

  bool active() const { return volume_m3 > 0.0 || resistance_pa_s_m3 > 0.0 || quadratic_resistance_pa_s2_m6 > 0.0; }
  /// Success when valid (non-negative; a circuit volume needs a resistance), else an error.
  Status validate() const;
  /// Pressure drop across the resistor at volume flow q [m^3/s] (+ towards the chamber).
  double pressureDrop(double q_m3_s) const;
  /// The volume flow whose pressure drop is dp_pa (the inverse of pressureDrop()).
  double flowAt(double dp_pa) const;
};

/**
 * The airway as a plug-in effect. Without circuit volume the resistor carries the metered flow:
 * the sensor reads p + R1 q + R2 q |q| (q the inflow over the chamber's gas density). With a
 * circuit volume V_c (isothermal at the supply temperature, one state: its pressure p_c) the
 * metered flow fills the circuit, the resistor's flow q(p_c - p) fills the chamber, and the
 * sensor reads p_c.
 */
class AirwayEffect : public CellEffect {
 public:
  explicit AirwayEffect(const AirwayParams& params) : params_(params) {}
  std::string name() const override { return "airway"; }
  std::map<std::string, double> parameters() const override;
  int stateSize() const override { return params_.volume_m3 > 0.0 ? 1 : 0; }
  void initialState(const CellParams& params, const CellVariables& cell, double* state) const override;
  void contribute(const CellParams& params, const CellVariables& cell, const double* state, EffectTerms* terms,
                  double* state_rate) const override;
  void measure(const CellParams& params, const CellVariables& cell, const double* state,
               Readings* measurement) const override;

 private:
  AirwayParams params_;
};

}  // namespace nursing_bed
