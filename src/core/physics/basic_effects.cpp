#include "nursing_bed/core/physics/basic_effects.h"

#include "nursing_bed/core/physics/cell_model.h"
#include "nursing_bed/core/physics/orifice.h"

namespace nursing_bed {

void HeatTransferEffect::contribute(const CellParams& params, const CellVariables& cell, const double*,
                                    EffectTerms* terms, double*) const {
  const double wall_k = wall_temperature_k_ > 0.0 ? wall_temperature_k_ : params.ambient_temperature_k;
  terms->heat_flow_w = coefficient_w_m2_k_ * cell.structure.surface_area_m2 * (wall_k - cell.temperature_k);
}

void LeakEffect::contribute(const CellParams& params, const CellVariables& cell, const double*, EffectTerms* terms,
                            double*) const {
  const OrificeFlow f =
      orificeFlow(params.gas, leak_area_m2_, cell.pressure_pa, cell.temperature_k, params.ambient_pressure_pa,
                  params.ambient_temperature_k, params.orifice_linear_band_pa);
  terms->mass_flow_kg_s = -f.mass_flow_kg_s;
  terms->enthalpy_flow_w = -f.mass_flow_kg_s * params.gas.cp() * f.upstream_temperature_k;
}

}  // namespace nursing_bed
