#include "nursing_bed/core/control/airbag_params_io.h"

#include <filesystem>
#include <stdexcept>

#include "nursing_bed/core/io/package_path.h"
#include "nursing_bed/core/observer/observer_params_io.h"
#include "nursing_bed/core/physics/cell_params_io.h"

namespace nursing_bed {
namespace {

using P = AirbagCellParams;
#define NB_FIELD(key, desc, expr) realField<P>(key, desc, [](P& p) -> double& { return expr; })

ParamTable<P> makeFields() {
  ParamTable<P> t = {
      NB_FIELD("controller/period_s", "controller and safety period [s]", p.control_period_s),
      NB_FIELD("controller/min_height_m", "lowest height setpoint accepted [m]", p.controller.min_height_m),
      NB_FIELD("controller/max_height_m", "highest height setpoint accepted (also capped by the URDF joint limit) [m]",
               p.controller.max_height_m),
      NB_FIELD("controller/height_tolerance_m", "deadband around the setpoint [m]", p.controller.height_tolerance_m),
      NB_FIELD("controller/approach_band_m", "predicted error that opens a valve fully near the target [m]",
               p.controller.approach_band_m),
      NB_FIELD("controller/max_pressure_pa", "the controller never fills above this gauge pressure [Pa]",
               p.controller.max_pressure_pa),
      NB_FIELD("controller/load_filter_time_s", "time constant of the load estimate [s]",
               p.controller.load_filter_time_s),
      NB_FIELD("controller/settled_speed_m_s", "plate speed under which the cell counts as at rest [m/s]",
               p.controller.settled_speed_m_s),
      NB_FIELD("controller/integral_rate_per_s", "rate at which a resting height error is integrated out [1/s]",
               p.controller.integral_rate_per_s),
      NB_FIELD("controller/integral_limit_m", "bound of that correction [m]", p.controller.integral_limit_m),
      NB_FIELD("controller/move_threshold_m", "predicted error above which a move uses the shaped full-flow law [m]",
               p.controller.move_threshold_m),
      NB_FIELD("controller/damping_band_m", "plate swing about its rest height that opens a valve fully [m]",
               p.controller.damping_band_m),
      NB_FIELD("controller/hold_band_m",
               "once on target, valves shut until the predicted or resting error leaves this [m]",
               p.controller.hold_band_m),
      NB_FIELD("safety/relief_pressure_pa", "gauge pressure never exceeded [Pa]", p.safety.relief_pressure_pa),
      NB_FIELD("safety/relief_margin_pa", "act this far below the relief pressure [Pa]", p.safety.relief_margin_pa),
      NB_FIELD("safety/command_timeout_s", "hold and flag when no command or heartbeat for this long; 0 = off [s]",
               p.safety.command_timeout_s),
      NB_FIELD("safety/sensor_pressure_min_pa", "pressure readings below are a sensor fault [Pa]",
               p.safety.sensor_pressure_min_pa),
      NB_FIELD("safety/sensor_pressure_max_pa", "pressure readings above are a sensor fault [Pa]",
               p.safety.sensor_pressure_max_pa),
      NB_FIELD("safety/sensor_height_min_m", "height readings below are a sensor fault [m]",
               p.safety.sensor_height_min_m),
      NB_FIELD("safety/sensor_height_max_m", "height readings above are a sensor fault [m]",
               p.safety.sensor_height_max_m),
      integerField<P>("safety/sensor_fault_periods",
                      "control periods a reading must stay out of range to be a sensor fault [-]",
                      [](P& p) -> int& { return p.safety.sensor_fault_periods; }),
      NB_FIELD("safety/max_load_n", "largest external load a cell accepts; larger ones are refused [N]",
               p.safety.max_load_n),
      NB_FIELD("safety/max_height_rate_m_s", "fastest change of a cell's height target outside CPR [m/s]",
               p.safety.max_height_rate_m_s),
      NB_FIELD("cpr/vacuum_pa", "gauge pressure at the vents while venting for CPR; 0 = ambient [Pa]", p.cpr_vacuum_pa),
      NB_FIELD("sensors/pressure_noise_pa", "standard deviation of the pressure sensor's noise [Pa]",
               p.pressure_noise_pa),
      NB_FIELD("sensors/height_noise_m", "standard deviation of the height sensor's noise [m]", p.height_noise_m),
  };
  ParamField<P> seed;  // an unsigned integer: its own accessors
  seed.key = "sensors/noise_seed";
  seed.description = "seed of the sensor noise [-]";
  seed.integer = true;
  seed.get = [](const P& p) { return static_cast<double>(p.noise_seed); };
  seed.set = [](P& p, double v) { p.noise_seed = static_cast<std::uint32_t>(v); };
  t.push_back(seed);
  appendNested(&t, cellParamFields(), "cell/", [](P& p) -> CellParams& { return p.cell; });
  return t;
}
#undef NB_FIELD

ParamTable<GasVerifierParams> makeGasCheckFields() {
  using G = GasVerifierParams;
  return {
      realField<G>("resume_vent_s",
                   "after a lost link: vent at most this long (until the pressure reads flat), then valves shut for "
                   "the observer's re-anchor test; 0 = off [s]",
                   [](G& p) -> double& { return p.resume_vent_s; }),
      realField<G>("reanchor_below_m",
                   "a height target at or below this, sent while the cell is above it, is reached through a flat cell "
                   "(vented until re-anchored, then filled); 0 = never [m]",
                   [](G& p) -> double& { return p.reanchor_below_m; }),
      realField<G>("recount_doubt_m",
                   "a cell whose counted vent gas may be off by more than this height is re-anchored at its target "
                   "(vented until re-anchored, then filled); 0 = never [m]",
                   [](G& p) -> double& { return p.recount_doubt_m; }),
      realField<G>("flag_doubt_m",
                   "a cell whose counted vent gas may be off by more than this height reports its height unverified "
                   "until found flat; 0 = never [m]",
                   [](G& p) -> double& { return p.flag_doubt_m; }),
      realField<G>("recount_max_load_n",
                   "only a cell whose load estimate is below this is re-anchored for its count's doubt [N]",
                   [](G& p) -> double& { return p.recount_max_load_n; }),
      realField<G>("verify_hold_s",
                   "after a lost link: valves shut this long, then the pressure is compared with the one before the "
                   "loss [s]",
                   [](G& p) -> double& { return p.verify_hold_s; }),
      realField<G>("link_steady_s",
                   "after a lost link: the checks wait, valves shut, until the link has stayed up this long [s]",
                   [](G& p) -> double& { return p.link_steady_s; }),
      realField<G>("verify_tolerance_pa",
                   "that comparison's least tolerance; a larger difference re-finds the gas by venting flat [Pa]",
                   [](G& p) -> double& { return p.verify_tolerance_pa; }),
      realField<G>("verify_tolerance_rel", "that comparison's tolerance as a fraction of the pressure, if larger [-]",
                   [](G& p) -> double& { return p.verify_tolerance_rel; }),
      realField<G>("prove_hold_s",
                   "after an inconsistency the cell, found flat and refilled, stays unverified until a hold at "
                   "height this long keeps its pressure; 0 = found flat proves it [s]",
                   [](G& p) -> double& { return p.prove_hold_s; }),
      realField<G>("prove_settle_s", "that hold counts after the valves have been held this long [s]",
                   [](G& p) -> double& { return p.prove_settle_s; }),
      realField<G>("prove_tolerance_pa",
                   "that hold's least tolerance between the mean pressures of its two halves; a larger change "
                   "re-finds the gas by venting flat [Pa]",
                   [](G& p) -> double& { return p.prove_tolerance_pa; }),
      realField<G>("prove_tolerance_rel", "that tolerance as a fraction of the pressure, if larger [-]",
                   [](G& p) -> double& { return p.prove_tolerance_rel; }),
      realField<G>("prove_min_height_m", "only a hold with the estimate above this proves the gas [m]",
                   [](G& p) -> double& { return p.prove_min_height_m; }),
  };
}

}  // namespace

const ParamTable<GasVerifierParams>& gasVerifierParamFields() {
  static const ParamTable<GasVerifierParams> fields = makeGasCheckFields();
  return fields;
}

void applyObserverParams(const FlatParams& values, const std::string& source, CellObserverParams* observer,
                         GasVerifierParams* gas_check, ConsistencyMonitorParams* monitor, const std::string& prefix) {
  FlatParams observer_values, gas_values, monitor_values;
  for (const auto& [key, value] : values) {
    bool gas_key = false;
    for (const auto& f : gasVerifierParamFields()) gas_key = gas_key || key == prefix + f.key;
    const bool monitor_key = key.rfind(prefix + "monitor_", 0) == 0;
    (gas_key ? gas_values : (monitor_key ? monitor_values : observer_values))[key] = value;
  }
  applyFlatParams(gas_values, source, gasVerifierParamFields(), gas_check, prefix);
  applyFlatParams(monitor_values, source, consistencyMonitorParamFields(), monitor, prefix);
  applyFlatParams(observer_values, source, observerParamFields(), observer, prefix);
}

const ParamTable<AirbagCellParams>& airbagParamFields() {
  static const ParamTable<AirbagCellParams> fields = makeFields();
  return fields;
}

AirbagCellParams airbagParamsFrom(const FlatParams& values, const std::string& source, const AirbagCellParams& base) {
  AirbagCellParams params = base;
  // The structure's text keys (cell/structure/type, cell/structure/table_file) first. Parameters
  // from the server carry no file location: a relative table path is taken from the package's
  // config/ folder, where the shipped cell files live (an absolute path is taken as it is); the
  // package is looked up only then.
  FlatParams numeric = values;
  const auto table = numeric.find("cell/structure/table_file");
  const bool relative_table = table != numeric.end() && std::filesystem::path(table->second.text).is_relative();
  applyStructureSelection(&numeric, relative_table ? findPackageFile("config") : "", &params.cell, "cell/");
  applyFlatParams(numeric, source, airbagParamFields(), &params);
  const std::string error = params.validate();
  if (!error.empty()) throw std::runtime_error(source + ": invalid airbag parameters: " + error);
  return params;
}

}  // namespace nursing_bed
