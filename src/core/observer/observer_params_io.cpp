#include "nursing_bed/core/observer/observer_params_io.h"

namespace nursing_bed {
namespace {

using P = CellObserverParams;
#define NB_FIELD(key, desc, expr) realField<P>(key, desc, [](P& p) -> double& { return expr; })

ParamTable<P> makeFields() {
  return {
      NB_FIELD("pressure_noise_pa", "sd of a pressure reading until measured from the still gas's readings [Pa]",
               p.pressure_noise_pa),
      NB_FIELD("height_noise_m", "sd of a height reading [m]", p.height_noise_m),
      NB_FIELD("flow_uncertainty", "relative sd of the modelled valve and leak flows over 1 s [-]", p.flow_uncertainty),
      NB_FIELD("mass_walk_kg_sqrt_s", "random walk of the gas mass [kg/sqrt(s)]", p.mass_walk_kg_sqrt_s),
      NB_FIELD("heat_walk_w_sqrt_s", "random walk of the gas energy [J/sqrt(s)]", p.heat_walk_w_sqrt_s),
      NB_FIELD("load_filter_time_s", "time constant of the load estimate [s]", p.load_filter_time_s),
      NB_FIELD("initial_load_sd_n", "sd of the load guess at reset [N]", p.initial_load_sd_n),
      NB_FIELD("valve_dead_time_s", "a valve command acts this late [s]", p.valve_dead_time_s),
      NB_FIELD("reanchor_pressure_pa", "|mean gauge pressure| under which a cell with its inlet shut is flat [Pa]",
               p.reanchor_pressure_pa),
      NB_FIELD("reanchor_time_s", "inlet shut and that flat this long: re-anchor the gas mass [s]", p.reanchor_time_s),
      NB_FIELD("weight_bound_window_s",
               "valves shut this long (settling), then readings averaged as long: the plate alone's rest height at "
               "that mean bounds the height; 0 = off [s]",
               p.weight_bound_window_s),
  };
}
#undef NB_FIELD

}  // namespace

const ParamTable<CellObserverParams>& observerParamFields() {
  static const ParamTable<CellObserverParams> fields = makeFields();
  return fields;
}

}  // namespace nursing_bed
