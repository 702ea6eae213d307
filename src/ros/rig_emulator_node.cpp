#include "nursing_bed/ros/rig_emulator_node.h"

#include <chrono>
#include <cmath>
#include <limits>
#include <sstream>

#include "nursing_bed/core/control/airbag_params_io.h"
#include "nursing_bed/core/gap/synth.h"
#include "nursing_bed/core/hardware/thread_priority.h"
#include "nursing_bed/core/io/errors.h"
#include "nursing_bed/ros/names.h"
#include "nursing_bed/ros/ros_params.h"

namespace nursing_bed {

Status RigEmulatorNodeParams::validate() const {
  ErrorList errors;
  errors.addIf(register_map.empty(), "~register_map must name the register map YAML");
  errors.addIf(bed_cells < 0, "~bed_cells must be >= 0");
  errors.addIf(!(period_s > 0.0 && period_s <= 0.02), "~period_s must lie in (0, 0.02] s");
  errors.addIf(!(adc_step_pa >= 0.0), "~adc_step_pa must be >= 0");
  errors.addIf(!(valve_dead_time_s >= 0.0 && valve_dead_time_s <= 1.0), "~valve_dead_time_s must lie in [0, 1] s");
  errors.addIf(!(pressure_noise_pa >= 0.0), "~pressure_noise_pa must be >= 0");
  errors.addIf(!(load_n >= 0.0 && std::isfinite(load_n)), "~load_n must be >= 0");
  errors.addIf(!(initial_height_m >= 0.0 && initial_height_m <= 0.2), "~initial_height_m must lie in [0, 0.2] m");
  errors.addIf(!(truth_rate_hz > 0.0 && truth_rate_hz <= 1000.0), "~truth_rate_hz must lie in (0, 1000]");
  const Status priority = checkRealtimePriority(simulation_realtime_priority);
  if (!priority) errors.add("~simulation_realtime_priority ", simulation_realtime_priority, " ", priority.message());
  try {
    effectsFromText(effects, noise_seed);
  } catch (const std::invalid_argument& e) {
    errors.add("~effects: ", e.what());
  }
  return errors.status();
}

RigEmulatorNodeParams RigEmulatorNode::loadParams(const ros::NodeHandle& pnh) {
  RigEmulatorNodeParams p;
  pnh.param("register_map", p.register_map, p.register_map);
  pnh.param("bed_cells", p.bed_cells, p.bed_cells);
  pnh.param("defaults_ns", p.defaults_ns, p.defaults_ns);
  pnh.param("period_s", p.period_s, p.period_s);
  pnh.param("adc_step_pa", p.adc_step_pa, p.adc_step_pa);
  pnh.param("valve_dead_time_s", p.valve_dead_time_s, p.valve_dead_time_s);
  pnh.param("pressure_noise_pa", p.pressure_noise_pa, p.pressure_noise_pa);
  pnh.param("effects", p.effects, p.effects);
  pnh.param("load_n", p.load_n, p.load_n);
  pnh.param("initial_height_m", p.initial_height_m, p.initial_height_m);
  pnh.param("truth_rate_hz", p.truth_rate_hz, p.truth_rate_hz);
  pnh.param("simulation_realtime_priority", p.simulation_realtime_priority, p.simulation_realtime_priority);
  int seed = static_cast<int>(p.noise_seed);
  pnh.param("noise_seed", seed, seed);
  p.noise_seed = static_cast<std::uint32_t>(seed);
  int fault_seed = static_cast<int>(p.fault_seed);
  pnh.param("fault_seed", fault_seed, fault_seed);
  p.fault_seed = static_cast<std::uint32_t>(fault_seed);
  return p;
}

RigEmulatorNode::RigEmulatorNode(ros::NodeHandle nh, ros::NodeHandle private_nh) : params_(loadParams(private_nh)) {
  const Status valid = params_.validate();
  if (!valid) throw std::runtime_error("rig_emulator: " + valid.message());
  const FlatParams values = layeredRosParams(private_nh, params_.defaults_ns, {"cell"});
  const AirbagCellParams airbag = airbagParamsFrom(values, "rig_emulator cell parameters");
  RigEmulatorOptions options;
  options.period_s = params_.period_s;
  options.realtime_priority = params_.simulation_realtime_priority;
  options.rig.adc_step_pa = params_.adc_step_pa;
  options.rig.valve_dead_time_s = params_.valve_dead_time_s;
  options.cell.cell = airbag.cell;
  options.cell.effects = effectsFromText(params_.effects, params_.noise_seed);
  options.cell.pressure_noise_pa = params_.pressure_noise_pa;
  options.cell.load_n = params_.load_n;
  options.cell.initial_height_m = params_.initial_height_m;
  options.cell.noise_seed = params_.noise_seed;
  options.fault_seed = params_.fault_seed;
  const RegisterMap map = loadRegisterMap(params_.register_map, static_cast<std::uint32_t>(params_.bed_cells));
  emulator_ = std::make_unique<RigEmulator>(map, options);
  loads_sub_ =
      nh.subscribe(names::kCellLoads, 2, &RigEmulatorNode::onCellLoads, this, ros::TransportHints().tcpNoDelay());
  truth_pub_ = private_nh.advertise<RigTruth>("truth", 2);
  truth_timer_ = nh.createTimer(ros::Duration(1.0 / params_.truth_rate_hz), &RigEmulatorNode::publishTruth, this);
  injectStartFaults(private_nh);
  fault_srv_ = private_nh.advertiseService("inject_fault", &RigEmulatorNode::onInjectFault, this);
  ROS_INFO("rig_emulator: %zu terminals on 127.0.0.1 serving %s%s%s", map.terminals.size(),
           params_.register_map.c_str(), params_.effects.empty() ? "" : ", hidden effects: ", params_.effects.c_str());
  if (emulator_->scheduling().refused)
    ROS_WARN("rig_emulator: the simulation runs at %s: on a loaded machine it pauses, and its sensors with it",
             emulator_->scheduling().text.c_str());
  for (const auto& server : emulator_->servers())
    if (server->scheduling().refused)
      ROS_WARN(
          "rig_emulator: terminal '%s' serves at %s: on a loaded machine it answers (and switches its valves) late",
          server->map().name.c_str(), server->scheduling().text.c_str());
}

namespace {

bool isNumber(const XmlRpc::XmlRpcValue& v) {
  return v.getType() == XmlRpc::XmlRpcValue::TypeDouble || v.getType() == XmlRpc::XmlRpcValue::TypeInt;
}

double number(XmlRpc::XmlRpcValue& v) {
  return v.getType() == XmlRpc::XmlRpcValue::TypeInt ? static_cast<int>(v) : static_cast<double>(v);
}

/// The cell ids of a list of non-negative integers; false when it is not one.
bool cellIds(XmlRpc::XmlRpcValue& list, std::vector<std::uint32_t>* ids) {
  if (list.getType() != XmlRpc::XmlRpcValue::TypeArray) return false;
  for (int i = 0; i < list.size(); ++i) {
    if (list[i].getType() != XmlRpc::XmlRpcValue::TypeInt || static_cast<int>(list[i]) < 0) return false;
    ids->push_back(static_cast<std::uint32_t>(static_cast<int>(list[i])));
  }
  return true;
}

}  // namespace

bool rigFaultFromXmlRpc(XmlRpc::XmlRpcValue& entry, RigFaultRequest* request, std::string* error) {
  using V = XmlRpc::XmlRpcValue;
  if (entry.getType() != V::TypeStruct) {
    *error = "must be a dict (fault, cell_ids, random_cells, valve, value, delay_s, keep_gas)";
    return false;
  }
  RigFaultRequest r;
  for (auto& [key, v] : entry) {
    bool ok = true;
    if (key == "fault") ok = v.getType() == V::TypeString && (r.fault = static_cast<std::string>(v), true);
    else if (key == "valve") ok = v.getType() == V::TypeString && (r.valve = static_cast<std::string>(v), true);
    else if (key == "cell_ids") ok = cellIds(v, &r.cell_ids);
    else if (key == "random_cells") ok = v.getType() == V::TypeInt && (r.random_cells = static_cast<int>(v), true);
    else if (key == "value") ok = isNumber(v) && (r.value = number(v), true);
    else if (key == "delay_s") ok = isNumber(v) && (r.delay_s = number(v), true);
    else if (key == "keep_gas") ok = v.getType() == V::TypeBoolean && (r.keep_gas = static_cast<bool>(v), true);
    else {
      *error = "unknown key '" + key + "'";
      return false;
    }
    if (!ok) {
      *error = "'" + key + "' has the wrong type";
      return false;
    }
  }
  *request = r;
  return true;
}

void RigEmulatorNode::injectStartFaults(const ros::NodeHandle& private_nh) {
  XmlRpc::XmlRpcValue faults;
  if (!private_nh.getParam("faults", faults)) return;
  if (faults.getType() != XmlRpc::XmlRpcValue::TypeArray)
    throw std::runtime_error("rig_emulator: ~faults must be a list of dicts");
  for (int i = 0; i < faults.size(); ++i) {
    RigFaultRequest request;
    std::string error, applied;
    if (!rigFaultFromXmlRpc(faults[i], &request, &error))
      throw std::runtime_error("rig_emulator: ~faults[" + std::to_string(i) + "]: " + error);
    const Status s = emulator_->inject(request, &applied);
    if (!s) throw std::runtime_error("rig_emulator: ~faults[" + std::to_string(i) + "]: " + s.message());
    ROS_WARN("rig_emulator: injected %s", applied.c_str());
  }
}

bool RigEmulatorNode::onInjectFault(InjectRigFault::Request& req, InjectRigFault::Response& res) {
  RigFaultRequest request;
  request.fault = req.fault;
  request.cell_ids.assign(req.cell_ids.begin(), req.cell_ids.end());
  request.random_cells = req.random_cells;
  request.valve = req.valve;
  request.value = req.value;
  request.delay_s = req.delay_s;
  request.keep_gas = req.keep_gas;
  std::string applied;
  const Status s = emulator_->inject(request, &applied);
  res.success = s.ok();
  res.message = s.ok() ? "injected " + applied : s.message();
  if (s.ok()) ROS_WARN("rig_emulator: injected %s", applied.c_str());
  return true;
}

void RigEmulatorNode::onCellLoads(const std_msgs::Float64MultiArray::ConstPtr& msg) { emulator_->setLoads(msg->data); }

void RigEmulatorNode::publishTruth(const ros::TimerEvent&) {
  std::chrono::steady_clock::time_point at;
  const std::vector<CellTruth> truth = emulator_->truth(&at);
  RigTruth msg;
  // Stamped with the instant the state describes, not the publish time: the timer runs up to
  // tens of ms late on a loaded machine, and a cell filling from flat rises 130 mm/s.
  msg.header.stamp =
      ros::Time::now() - ros::Duration(std::chrono::duration<double>(std::chrono::steady_clock::now() - at).count());
  std::uint32_t cells = 0;
  for (const CellTruth& t : truth) cells = std::max(cells, t.cell_id + 1);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  msg.height_m.assign(cells, nan);
  msg.gauge_pressure_pa.assign(cells, nan);
  msg.gas_mass_kg.assign(cells, nan);
  msg.load_n.assign(cells, nan);
  for (const CellTruth& t : truth) {
    msg.height_m[t.cell_id] = t.height_m;
    msg.gauge_pressure_pa[t.cell_id] = t.gauge_pressure_pa;
    msg.gas_mass_kg[t.cell_id] = t.gas_mass_kg;
    msg.load_n[t.cell_id] = t.load_n;
  }
  truth_pub_.publish(msg);
  ROS_INFO_THROTTLE(10.0, "rig_emulator: %.3f periods per wake-up, at most %ld", emulator_->periodsPerWake(),
                    emulator_->mostPeriodsPerWake());
  if (emulator_->overruns() > reported_overruns_) {
    reported_overruns_ = emulator_->overruns();
    ROS_WARN(
        "rig_emulator: fell behind real time %ld times, %.3f s given up in all: the rig's cells received "
        "less gas than their valves passed (machine overloaded)",
        reported_overruns_, emulator_->lostSeconds());
  }
}

}  // namespace nursing_bed
