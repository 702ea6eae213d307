#include "nursing_bed/ros/reconfigure.h"

#include <dynamic_reconfigure/Config.h>

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include "nursing_bed/core/bed/posture_plans.h"
#include "nursing_bed/core/control/airbag_params_io.h"
#include "nursing_bed/core/io/status.h"

namespace nursing_bed {
namespace {

using Values = std::map<std::string, double>;

/// Sections whose YAML keys are "section/name" (the cfg writes each '/' as '_'), the deepest
/// first: plans_adaptive_x is plans/adaptive/x, not plans/adaptive_x.
const char* const kSections[] = {"plans/adaptive/tolerance", "plans/adaptive", "controller", "safety", "plans"};

/// Every key the airbag node's parameters have (its AirbagCellParams' table).
const ParamTable<AirbagNodeParams>& airbagNodeFields() {
  static const ParamTable<AirbagNodeParams> fields = [] {
    ParamTable<AirbagNodeParams> t;
    appendNested(&t, airbagParamFields(), "", [](AirbagNodeParams& p) -> AirbagCellParams& { return p.airbag; });
    return t;
  }();
  return fields;
}

/// The bed manager's alarm thresholds and its plan configuration ("plans/...").
const ParamTable<BedManagerParams>& bedManagerFields() {
  using P = BedManagerParams;
  static const ParamTable<P> fields = [] {
    ParamTable<P> t = {
        realField<P>("cell_timeout_s", "a cell silent this long is dead [s]",
                     [](P& p) -> double& { return p.bed.cell_timeout_s; }),
        realField<P>("leak_alarm_error_m", "leak alarm: this far below the target [m]",
                     [](P& p) -> double& { return p.bed.leak_alarm_error_m; }),
        realField<P>("leak_alarm_s", "leak alarm: for this long [s]",
                     [](P& p) -> double& { return p.bed.leak_alarm_s; }),
    };
    appendNested(&t, planConfigFields(), "plans/", [](P& p) -> PlanConfig& { return p.bed.plans; });
    return t;
  }();
  return fields;
}

template <class Params>
const ParamField<Params>& fieldOf(const ParamTable<Params>& table, const std::string& name) {
  const std::string key = reconfigureYamlKey(name);
  for (const auto& f : table)
    if (f.key == key) return f;
  throw std::logic_error("reconfigure parameter '" + name + "' has no parameter key '" + key + "'");
}

/// A configuration's values by name (every cfg parameter is a double or an int).
template <class Config>
Values valuesOf(const Config& config) {
  dynamic_reconfigure::Config msg;
  config.__toMessage__(msg);
  Values out;
  for (const auto& d : msg.doubles) out[d.name] = d.value;
  for (const auto& i : msg.ints) out[i.name] = i.value;
  return out;
}

/// A validate()'s problems as text (empty when valid), whether it returns a Status or a string.
inline std::string problemsOf(const Status& status) { return status.message(); }
inline std::string problemsOf(const std::string& problems) { return problems; }

template <class Config, class Params>
Config configFrom(const Params& params, const ParamTable<Params>& table) {
  Config config = Config::__getDefault__();
  dynamic_reconfigure::Config msg;
  config.__toMessage__(msg);
  for (auto& d : msg.doubles) d.value = fieldOf(table, d.name).get(params);
  for (auto& i : msg.ints) i.value = static_cast<int>(std::lround(fieldOf(table, i.name).get(params)));
  config.__fromMessage__(msg);
  return config;
}

template <class Config, class Params>
std::string reconfigureWith(const Config& config, Params* params, ReconfiguredKeys* changed,
                            const ParamTable<Params>& table) {
  Params next = *params;
  ReconfiguredKeys differs;
  std::ostringstream requested;
  for (const auto& [name, value] : valuesOf(config)) {
    const ParamField<Params>& f = fieldOf(table, name);
    if (f.get(*params) == value) continue;
    f.set(next, value);
    differs[f.key] = value;
    requested << (differs.size() > 1 ? ", " : "") << name << " = " << value;
  }
  const std::string error = problemsOf(next.validate());
  if (!error.empty()) return "refused " + requested.str() + ": " + error + " (the running values stay)";
  *params = next;
  *changed = differs;
  return "";
}

template <class Config, class Params>
bool requestWith(Config& config, Params* params, ReconfiguredKeys* changed, const std::string& who,
                 const ParamTable<Params>& table) {
  ReconfiguredKeys differs;
  const std::string error = reconfigureWith(config, params, &differs, table);
  if (!error.empty()) {
    ROS_ERROR("%s: dynamic_reconfigure %s", who.c_str(), error.c_str());
    config = configFrom<Config>(*params, table);
    return false;
  }
  for (const auto& [key, value] : differs)
    ROS_INFO("%s: dynamic_reconfigure set %s = %g", who.c_str(), key.c_str(), value);
  *changed = differs;
  return !differs.empty();
}

}  // namespace

std::string reconfigureYamlKey(const std::string& name) {
  for (const std::string section : kSections) {
    std::string prefix = section + "_";
    std::replace(prefix.begin(), prefix.end(), '/', '_');
    if (name.compare(0, prefix.size(), prefix) == 0) return section + "/" + name.substr(prefix.size());
  }
  return name;
}

AirbagCellConfig airbagConfigFrom(const AirbagNodeParams& params) {
  return configFrom<AirbagCellConfig>(params, airbagNodeFields());
}

BedManagerConfig bedManagerConfigFrom(const BedManagerParams& params) {
  return configFrom<BedManagerConfig>(params, bedManagerFields());
}

std::string reconfigureParams(const AirbagCellConfig& config, AirbagNodeParams* params, ReconfiguredKeys* changed) {
  return reconfigureWith(config, params, changed, airbagNodeFields());
}

std::string reconfigureParams(const BedManagerConfig& config, BedManagerParams* params, ReconfiguredKeys* changed) {
  return reconfigureWith(config, params, changed, bedManagerFields());
}

bool reconfigureRequest(AirbagCellConfig& config, AirbagNodeParams* params, ReconfiguredKeys* changed,
                        const std::string& who) {
  return requestWith(config, params, changed, who, airbagNodeFields());
}

bool reconfigureRequest(BedManagerConfig& config, BedManagerParams* params, ReconfiguredKeys* changed,
                        const std::string& who) {
  return requestWith(config, params, changed, who, bedManagerFields());
}

void saveReconfigured(const ros::NodeHandle& private_nh, const ReconfiguredKeys& changed) {
  // As doubles: the parameter tables take a whole double for an integer key.
  for (const auto& [key, value] : changed) private_nh.setParam(key, value);
}

}  // namespace nursing_bed
