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
      NB_FIELD("weight_bound_lift_window_s",
               "the same while the plate is lifted (inlet open, vent shut, not falling): after this long, readings "
               "averaged as long again; 0 = off [s]",
               p.weight_bound_lift_window_s),
      NB_FIELD("vent_count_doubt",
               "share of the vent gas counted while the plate may ring that the count may be off, in [0, 1] [-]",
               p.vent_count_doubt),
  };
}
#undef NB_FIELD

ParamTable<ConsistencyMonitorParams> makeMonitorFields() {
  using M = ConsistencyMonitorParams;
  auto field = [](const char* key, const char* desc, double M::*member) {
    return realField<M>(std::string("monitor_") + key, desc, [member](M& p) -> double& { return p.*member; });
  };
  return {
      field("frozen_s", "the same raw reading this long is a frozen sensor; 0 = off [s]", &M::frozen_s),
      field("settle_s", "both valves shut this long before a hold's pressure is tested [s]", &M::settle_s),
      field("reference_time_s", "time constant of the hold's reference pressure [s]", &M::reference_time_s),
      field("load_rate_pa_s",
            "the hold's reference follows the readings beyond the noise at up to this rate (a body's load "
            "changing); 0 = the hold's mean alone [Pa/s]",
            &M::load_rate_pa_s),
      field("hold_correction_pa",
            "a valve period counted to move the pressure less than this at fixed volume does not end a hold; 0 = "
            "any does [Pa]",
            &M::hold_correction_pa),
      field("drift_sds", "innovation within this many reading sds is noise [-]", &M::drift_sds),
      field("min_drift_pa", "least innovation the CUSUM counts [Pa]", &M::min_drift_pa),
      field("cusum_threshold_pa_s", "CUSUM of the innovation that is a persistent inconsistency [Pa s]",
            &M::cusum_threshold_pa_s),
      field("jump_pa", "a settled plate's reading moving this much in one reading is a sensor jump [Pa]", &M::jump_pa),
      field("surprise_m", "a weight-bound correction larger than this shows the gas count wrong [m]", &M::surprise_m),
      field("response_min_pa",
            "a valve pulse counted to move the pressure this much at fixed volume must move it; 0 = off [Pa]",
            &M::response_min_pa),
      field("response_sds", "the response asked of it, in reading sds [-]", &M::response_sds),
      field("response_silent_sum_pa",
            "one valve's judged pulses in a row without a response worth this in all flag it; 0 = off [Pa]",
            &M::response_silent_sum_pa),
      integerField<M>("monitor_response_silent_pulses", "and at least this many of them [-]",
                      [](M& p) -> int& { return p.response_silent_pulses; }),
      field("response_single_pa", "one silent pulse counted worth this flags its valve alone [Pa]",
            &M::response_single_pa),
      field("response_steady_s",
            "readings within monitor_response_steady_sds over this long before a pulse are steady; 0 = off [s]",
            &M::response_steady_s),
      field("response_steady_sds", "that range, in reading sds [-]", &M::response_steady_sds),
      field("response_steady_single_pa",
            "one silent pulse from steady readings counted worth this flags its valve [Pa]",
            &M::response_steady_single_pa),
      field("response_window_s", "the response awaited this long after the counted flow [s]", &M::response_window_s),
      field("response_min_period_s",
            "pulses judged only where the plate's period on its gas spring is at least this; 0 = all [s]",
            &M::response_min_period_s),
      field("max_load_n", "an observer load estimate above this shows the gas count wrong; 0 = off [N]",
            &M::max_load_n),
      field("landed_height_m", "the readings flat under an estimate above this shows gas gone uncounted; 0 = off [m]",
            &M::landed_height_m),
      field("landed_time_s", "the readings flat that long under a lifted estimate is that test [s]", &M::landed_time_s),
      field("progress_inlet_m",
            "failure to reach target: once the inlet's counted gas is worth this in height, the pressure must have "
            "risen; else that gas is the count's doubt; 0 = off [m]",
            &M::progress_inlet_m),
      field("progress_vent_m", "the same for the vent (the pressure must fall); 0 = off [m]", &M::progress_vent_m),
      field("progress_rel", "the least relative pressure move asked of that counted gas [-]", &M::progress_rel),
      field("progress_min_pa", "judged only where that move is at least this [Pa]", &M::progress_min_pa),
      field("progress_window_s", "the valve's gas is summed over at most this long [s]", &M::progress_window_s),
  };
}

}  // namespace

const ParamTable<ConsistencyMonitorParams>& consistencyMonitorParamFields() {
  static const ParamTable<ConsistencyMonitorParams> fields = makeMonitorFields();
  return fields;
}

const ParamTable<CellObserverParams>& observerParamFields() {
  static const ParamTable<CellObserverParams> fields = makeFields();
  return fields;
}

}  // namespace nursing_bed
