#include "nursing_bed/ros/airbag_node.h"

#include <sensor_msgs/FluidPressure.h>

#include <boost/make_shared.hpp>
#include <algorithm>
#include <cmath>
#include <sstream>

#include "nursing_bed/core/control/airbag_params_io.h"
#include "nursing_bed/core/gap/synth.h"
#include "nursing_bed/ros/cell_ticker.h"
#include "nursing_bed/ros/names.h"
#include "nursing_bed/ros/ros_params.h"

namespace nursing_bed {

std::string AirbagNodeParams::validate() const {
  std::ostringstream err;
  if (row < 0 || col < 0) err << "~row and ~col must be set to the cell's place in the bed (>= 0); ";
  if (!(update_rate_hz > 0.0 && update_rate_hz <= 1000.0)) err << "~update_rate_hz must lie in (0, 1000]; ";
  if (!(publish_rate_hz > 0.0 && publish_rate_hz <= update_rate_hz))
    err << "~publish_rate_hz must lie in (0, update_rate_hz]; ";
  if (!(load_n >= 0.0 && std::isfinite(load_n))) err << "~load_n must be >= 0 N; ";
  if (!(initial_height_m >= 0.0 && initial_height_m <= airbag.controller.max_height_m))
    err << "~initial_height_m must lie in [0, controller/max_height_m]; ";
  if (!std::isfinite(supply_pressure_pa)) err << "~supply_pressure_pa must be finite; ";
  try {
    effectsFromText(effects, static_cast<std::uint32_t>(airbag.noise_seed));
  } catch (const std::invalid_argument& e) {
    err << "~effects: " << e.what() << "; ";
  }
  const std::string airbag_error = airbag.validate();
  if (!airbag_error.empty()) err << airbag_error << "; ";
  const std::string hardware_error = hardware.validate();
  if (!hardware_error.empty()) err << hardware_error << "; ";
  std::string s = err.str();
  if (s.size() >= 2) s.resize(s.size() - 2);
  return s;
}

AirbagNodeParams AirbagNode::loadParams(const ros::NodeHandle& pnh) {
  AirbagNodeParams p;
  pnh.param("row", p.row, p.row);
  pnh.param("col", p.col, p.col);
  pnh.param("defaults_ns", p.defaults_ns, p.defaults_ns);
  pnh.param("robot_description_param", p.robot_description, p.robot_description);
  // The rate may come from the defaults namespace too (real_bed.launch runs the cells faster).
  if (!pnh.getParam("update_rate_hz", p.update_rate_hz)) pnh.param(p.defaults_ns + "/update_rate_hz", p.update_rate_hz, p.update_rate_hz);
  pnh.param("publish_rate_hz", p.publish_rate_hz, p.publish_rate_hz);
  pnh.param("load_n", p.load_n, p.load_n);
  pnh.param("initial_height_m", p.initial_height_m, p.initial_height_m);
  pnh.param("supply_pressure_pa", p.supply_pressure_pa, p.supply_pressure_pa);
  pnh.param("effects", p.effects, p.effects);
  const FlatParams values = layeredRosParams(pnh, p.defaults_ns, {"cell", "controller", "safety", "sensors", "cpr"});
  p.airbag = airbagParamsFrom(values, "parameters of " + pnh.getNamespace());
  p.hardware = AirbagHardwareParams::load(pnh, p.defaults_ns);
  return p;
}

AirbagNode::AirbagNode(ros::NodeHandle nh, ros::NodeHandle private_nh) : nh_(nh), private_nh_(private_nh) {
  params_ = loadParams(private_nh_);
  std::string urdf;
  if (!nh_.getParam(params_.robot_description, urdf))
    throw std::runtime_error("airbag: no bed description on parameter '" + nh_.resolveName(params_.robot_description) +
                             "' (load it from scripts/make_bed_urdf.py, as sim.launch does)");
  const BedLayout layout = BedLayout::fromUrdf(urdf);
  const CellLayout* cell = layout.find(params_.row, params_.col);
  if (!cell) {
    std::ostringstream msg;
    msg << "airbag: cell (row " << params_.row << ", col " << params_.col << ") is not in the bed's URDF ("
        << layout.rows() << " x " << layout.cols() << ")";
    throw std::runtime_error(msg.str());
  }
  layout_ = *cell;
  bed_cells_ = layout.cells().size();  // ordered by id: every id below this is a cell
  // The URDF joint limits bound the setpoints too.
  params_.airbag.controller.max_height_m = std::min(params_.airbag.controller.max_height_m, layout_.max_height_m);
  params_.airbag.controller.min_height_m = std::max(params_.airbag.controller.min_height_m, layout_.min_height_m);
  params_.airbag.noise_seed += layout_.id;
  const std::string error = params_.validate();
  if (!error.empty()) throw std::runtime_error("airbag " + names::airbagName(params_.row, params_.col) + ": " + error);

  cell_ = makeCell();
  if (!params_.effects.empty()) ROS_INFO("airbag %s: simulated with hidden effects: %s",
                                         names::airbagName(params_.row, params_.col).c_str(), params_.effects.c_str());
  if (params_.initial_height_m > 0.0) {
    cell_->resetToHeight(params_.initial_height_m, params_.load_n);
  } else {
    cell_->reset(params_.load_n);
  }
  if (params_.supply_pressure_pa >= 0.0) cell_->setSupplyPressure(params_.supply_pressure_pa);
  cell_->setCommandTimeout(0.0);  // armed by the first streamed command (feedWatchdog)

  state_pub_ = private_nh_.advertise<AirbagState>(names::kState, 10);
  pressure_pub_ = private_nh_.advertise<sensor_msgs::FluidPressure>(names::kPressure, 10);
  set_height_srv_ = private_nh_.advertiseService(names::kSetHeight, &AirbagNode::setHeight, this);
  set_pressure_srv_ = private_nh_.advertiseService(names::kSetPressure, &AirbagNode::setPressure, this);
  setpoint_sub_ = private_nh_.subscribe(names::kHeightSetpoint, 10, &AirbagNode::onSetpoint, this);
  load_sub_ = private_nh_.subscribe(names::kLoad, 10, &AirbagNode::onLoad, this);
  cell_loads_sub_ = nh_.subscribe(names::kCellLoads, 2, &AirbagNode::onCellLoads, this,
                                  ros::TransportHints().tcpNoDelay());
  vent_sub_ = private_nh_.subscribe(names::kVent, 10, &AirbagNode::onVent, this);
  heartbeat_sub_ = private_nh_.subscribe(names::kHeartbeat, 10, &AirbagNode::onHeartbeat, this);
  bed_heartbeat_sub_ = nh_.subscribe(names::kBedHeartbeat, 2, &AirbagNode::onHeartbeat, this);
  cpr_sub_ = nh_.subscribe(names::kCpr, 2, &AirbagNode::onCpr, this);
  start_ = ros::Time::now();
  last_publish_ = start_;
  CellTicker& ticker = CellTicker::instance(params_.update_rate_hz);
  if (ticker.rateHz() != params_.update_rate_hz)
    ROS_WARN("%s: ~update_rate_hz %g ignored: this process's airbags tick at %g Hz (the first one's rate)",
             layout_.link_name.c_str(), params_.update_rate_hz, ticker.rateHz());
  params_.update_rate_hz = ticker.rateHz();
  ticker_handle_ = ticker.add([this](const ros::Time& now) { update(now); },
                              [this](const ros::Time& now) { publish(now); });
  ROS_DEBUG("airbag %s (cell %u) up: %s", layout_.link_name.c_str(), layout_.id, cell_->hardware().describe().c_str());
}

std::unique_ptr<AirbagCell> AirbagNode::makeCell() {
  const auto seed = static_cast<std::uint32_t>(params_.airbag.noise_seed);
  // Real hardware runs one control period per tick.
  if (!params_.hardware.simulated()) params_.airbag.control_period_s = 1.0 / params_.update_rate_hz;
  HardwareConfig config;
  config.cell_id = layout_.id;
  config.control_period_s = params_.airbag.control_period_s;
  config.cell = params_.airbag.cell;
  config.effects = effectsFromText(params_.effects, seed);
  config.load_n = params_.load_n;
  config.initial_height_m = params_.initial_height_m;
  config.cpr_vacuum_pa = params_.airbag.cpr_vacuum_pa;
  config.pressure_noise_pa = params_.airbag.pressure_noise_pa;
  config.height_noise_m = params_.airbag.height_noise_m;
  config.noise_seed = seed;
  config.register_map_path = params_.hardware.register_map;
  config.bed_cells = static_cast<std::uint32_t>(bed_cells_);
  const std::string where = "airbag " + names::airbagName(params_.row, params_.col) + ": ";
  try {
    return std::make_unique<AirbagCell>(params_.airbag, loadCellHardware(params_.hardware, config),
                                        observerSetup(params_.hardware, params_.airbag.cell, seed));
  } catch (const std::exception& e) {
    throw std::runtime_error(where + e.what());
  }
}

AirbagNode::~AirbagNode() {
  if (ticker_handle_ >= 0) CellTicker::instance(params_.update_rate_hz).remove(ticker_handle_);
}

void AirbagNode::update(const ros::Time& now) {
  std::lock_guard<std::mutex> lock(mutex_);
  cell_->advanceTo(elapsed(now));
}

void AirbagNode::publish(const ros::Time& now) {
  // Never wait for the simulation thread: a cell it is advancing now publishes next round
  // (both threads walk the cells in the same order; waiting would pace publishing by it).
  std::unique_lock<std::mutex> lock(mutex_, std::try_to_lock);
  if (!lock.owns_lock()) return;
  const double since_s = (now - last_publish_wall_).toSec();
  if (since_s < 1.0 / params_.publish_rate_hz - 0.5 / params_.update_rate_hz) return;
  // A state is published when the simulation has moved on, and repeated (same stamp) while a
  // slow simulation round holds it back: the cell's controller is alive, its plant is late.
  const bool advanced = cell_->time() != last_published_time_s_;
  if (!advanced && since_s < 2.0 / params_.publish_rate_hz) return;
  publishState(start_ + ros::Duration(cell_->time()));
  last_published_time_s_ = cell_->time();
  last_publish_wall_ = now;
}

void AirbagNode::publishState(const ros::Time& stamp) {
  const CellVariables& v = cell_->variables();
  const Measurement& m = cell_->measurement();
  // Published as a shared pointer: the bed manager nodelet in the same manager gets it without a copy.
  const boost::shared_ptr<AirbagState> out = boost::make_shared<AirbagState>();
  AirbagState& msg = *out;
  msg.header.stamp = stamp;
  msg.header.frame_id = layout_.link_name;
  msg.cell_id = layout_.id;
  msg.row = layout_.row;
  msg.col = layout_.col;
  msg.gauge_pressure_pa = m.gauge_pressure_pa;
  msg.height_m = m.height_m;
  msg.height_source = static_cast<uint8_t>(cell_->heightSource());
  msg.height_sd_m = cell_->heightSd();
  msg.volume_m3 = v.structure.volume_m3;
  msg.gas_mass_kg = v.mass_kg;
  msg.gas_temperature_k = v.temperature_k;
  // Mean metered inflow since the previous message (from the totaliser): what a logged flow
  // meter gives, and what a replay of the recording can integrate (doc/airbag_node.md).
  const double interval_s = (stamp - last_publish_).toSec();
  const double metered_kg = cell_->meteredInletMassKg();
  msg.inflow_kg_s = interval_s > 0.0 ? (metered_kg - metered_mass_at_publish_kg_) / interval_s : m.inflow_kg_s;
  metered_mass_at_publish_kg_ = metered_kg;
  msg.external_load_n = cell_->load();
  // Mean valve openings since the previous message, for the same reason: a 200 Hz valve
  // sampled at 50 Hz would misstate the gas it let through.
  const double inlet_s = cell_->inletOpeningSeconds(), vent_s = cell_->ventOpeningSeconds();
  msg.inlet_valve_cmd = interval_s > 0.0 ? (inlet_s - inlet_opening_at_publish_s_) / interval_s : cell_->valves().inlet;
  msg.vent_valve_cmd = interval_s > 0.0 ? (vent_s - vent_opening_at_publish_s_) / interval_s : cell_->valves().vent;
  msg.inlet_valve_cmd = std::clamp(msg.inlet_valve_cmd, 0.0, 1.0);
  msg.vent_valve_cmd = std::clamp(msg.vent_valve_cmd, 0.0, 1.0);
  inlet_opening_at_publish_s_ = inlet_s;
  vent_opening_at_publish_s_ = vent_s;
  msg.height_setpoint_m = cell_->setpoint();
  msg.pressure_setpoint_pa = cell_->pressureSetpoint();
  msg.mode = static_cast<uint8_t>(cell_->mode());
  msg.faults = cell_->faults();
  last_publish_ = stamp;
  state_pub_.publish(out);
  if (pressure_pub_.getNumSubscribers() > 0) {
    sensor_msgs::FluidPressure p;
    p.header = msg.header;
    p.fluid_pressure = cell_->params().cell.ambient_pressure_pa + m.gauge_pressure_pa;  // absolute, per the message
    pressure_pub_.publish(p);
  }
}

namespace {
// The bed manager re-sends its setpoints every ~resend_s (1 s): it owns a cell this long after one.
constexpr double kManagerOwnsForS = 2.5;
}  // namespace

bool AirbagNode::ownedByManager(const ros::Time& now) const {
  return !manager_setpoint_at_.isZero() && (now - manager_setpoint_at_).toSec() < kManagerOwnsForS;
}

std::string AirbagNode::request(double height_m, const ros::Time& now) {
  return cell_->requestHeight(height_m, elapsed(now));
}

bool AirbagNode::setHeight(SetHeight::Request& req, SetHeight::Response& res) {
  std::lock_guard<std::mutex> lock(mutex_);
  const ros::Time now = ros::Time::now();
  std::ostringstream msg;
  if (req.cell_id != layout_.id) {
    msg << "cell " << req.cell_id << " is not served here: this is " << layout_.link_name << ", cell " << layout_.id;
  } else if (ownedByManager(now)) {
    msg << "cell " << layout_.id << " (" << layout_.link_name << ") is run by the bed manager, whose setpoints keep "
        << "coming: ask /bed_manager/set_airbag_height, which makes it a custom target";
  } else {
    const std::string error = request(req.height_m, now);
    if (error.empty()) msg << "height setpoint " << req.height_m << " m accepted (no bed manager runs this cell)";
    else msg << error;
    res.success = error.empty();
  }
  res.message = msg.str();
  return true;
}

bool AirbagNode::setPressure(SetPressure::Request& req, SetPressure::Response& res) {
  std::lock_guard<std::mutex> lock(mutex_);
  const std::string error = req.cell_id != layout_.id
                                ? "cell " + std::to_string(req.cell_id) + " is not served here: this is " + layout_.link_name +
                                      ", cell " + std::to_string(layout_.id)
                                : cell_->requestPressure(req.pressure_pa, elapsed(ros::Time::now()));
  res.success = error.empty();
  res.message = error.empty() ? "pressure setpoint " + std::to_string(req.pressure_pa) + " Pa accepted" : error;
  return true;
}

void AirbagNode::onSetpoint(const std_msgs::Float64::ConstPtr& msg) {
  std::lock_guard<std::mutex> lock(mutex_);
  const ros::Time now = ros::Time::now();
  const std::string error = request(msg->data, now);
  if (!error.empty()) {
    ROS_WARN_THROTTLE(1.0, "%s: setpoint %g refused: %s", layout_.link_name.c_str(), msg->data, error.c_str());
    return;
  }
  manager_setpoint_at_ = now;
  feedWatchdog(now);
}

void AirbagNode::feedWatchdog(const ros::Time& now) {
  cell_->heartbeat(elapsed(now));
  if (!watchdog_armed_) cell_->setCommandTimeout(params_.airbag.safety.command_timeout_s);
  watchdog_armed_ = true;
}

void AirbagNode::applyLoad(double load_n, const char* source) {
  std::lock_guard<std::mutex> lock(mutex_);
  const std::string error = cell_->setLoad(load_n);
  if (!error.empty()) ROS_ERROR_THROTTLE(1.0, "%s: %s from %s", layout_.link_name.c_str(), error.c_str(), source);
}

void AirbagNode::onLoad(const std_msgs::Float64::ConstPtr& msg) { applyLoad(msg->data, "its load topic"); }

void AirbagNode::onCellLoads(const std_msgs::Float64MultiArray::ConstPtr& msg) {
  if (msg->data.size() != bed_cells_) {
    ROS_ERROR_THROTTLE(1.0, "%s: %s refused: %zu loads for a bed of %zu cells", layout_.link_name.c_str(),
                       names::kCellLoads, msg->data.size(), bed_cells_);
    return;
  }
  applyLoad(msg->data[layout_.id], names::kCellLoads);
}

void AirbagNode::onVent(const std_msgs::Empty::ConstPtr&) {
  std::lock_guard<std::mutex> lock(mutex_);
  cell_->requestVent(elapsed(ros::Time::now()));
}

void AirbagNode::onCpr(const std_msgs::Bool::ConstPtr& msg) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (msg->data == cell_->cpr()) return;
  ROS_DEBUG("%s: bed-wide CPR %s", layout_.link_name.c_str(), msg->data ? "on: venting, heights refused" : "off: holding");
  cell_->setCpr(msg->data, elapsed(ros::Time::now()));
}

void AirbagNode::onHeartbeat(const std_msgs::Empty::ConstPtr&) {
  std::lock_guard<std::mutex> lock(mutex_);
  feedWatchdog(ros::Time::now());
}

}  // namespace nursing_bed
