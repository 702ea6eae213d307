#include "nursing_bed/core/observer/observer_params_io.h"

namespace nursing_bed {
namespace {

using P = CellObserverParams;
#define NB_FIELD(key, desc, expr) realField<P>(key, desc, [](P& p) -> double& { return expr; })

ParamTable<P> makeFields() {
  return {
      NB_FIELD("pressure_noise_pa", "sd of the pressure reading, model mismatch included [Pa]", p.pressure_noise_pa),
      NB_FIELD("height_noise_m", "sd of a height reading [m]", p.height_noise_m),
      NB_FIELD("inflow_noise_kg_s", "sd of an inflow reading [kg/s]", p.inflow_noise_kg_s),
      NB_FIELD("flow_uncertainty", "relative sd of the modelled valve and leak flows over 1 s [-]", p.flow_uncertainty),
      NB_FIELD("mass_walk_kg_sqrt_s", "random walk of the gas mass [kg/sqrt(s)]", p.mass_walk_kg_sqrt_s),
      NB_FIELD("heat_walk_w_sqrt_s", "random walk of the gas energy [J/sqrt(s)]", p.heat_walk_w_sqrt_s),
      NB_FIELD("force_noise_n", "unmodelled force on the plate [N sqrt(s)]", p.force_noise_n),
      NB_FIELD("load_walk_n_sqrt_s", "random walk of the load [N/sqrt(s)]", p.load_walk_n_sqrt_s),
      NB_FIELD("initial_load_sd_n", "sd of the load guess at reset [N]", p.initial_load_sd_n),
      NB_FIELD("valve_dead_time_s", "a valve command acts this late [s]", p.valve_dead_time_s),
      NB_FIELD("reading_time_sd_s", "sd of a reading's time against the model's [s]", p.reading_time_sd_s),
      NB_FIELD("reanchor_pressure_pa", "|gauge pressure| under which a venting cell is flat [Pa]", p.reanchor_pressure_pa),
      NB_FIELD("mass_lock_height_m", "above this estimated height the gas mass is integrated, not corrected [m]", p.mass_lock_height_m),
      NB_FIELD("reanchor_time_s", "vented and that flat this long: re-anchor the gas mass [s]", p.reanchor_time_s),
      integerField<P>("jacobian_refresh_steps", "periods between linearisations [-]",
                      [](P& p) -> int& { return p.jacobian_refresh_steps; }),
  };
}
#undef NB_FIELD

}  // namespace

const ParamTable<CellObserverParams>& observerParamFields() {
  static const ParamTable<CellObserverParams> fields = makeFields();
  return fields;
}

}  // namespace nursing_bed
