#include "nursing_bed/ros/bed_manager.h"

#include <diagnostic_msgs/DiagnosticArray.h>
#include <sensor_msgs/JointState.h>
#include <std_msgs/Float64.h>

#include <cmath>
#include <set>
#include <sstream>

#include "nursing_bed/ros/names.h"

namespace nursing_bed {

std::string BedManagerParams::validate() const {
  std::ostringstream err;
  if (!(joint_state_rate_hz > 0.0 && joint_state_rate_hz <= 200.0)) err << "~joint_state_rate_hz must lie in (0, 200]; ";
  if (!(cell_timeout_s > 0.0)) err << "~cell_timeout_s must be positive; ";
  if (!(diagnostics_rate_hz > 0.0 && diagnostics_rate_hz <= 50.0)) err << "~diagnostics_rate_hz must lie in (0, 50]; ";
  if (!(max_height_m > min_height_m)) err << "max height must exceed min height; ";
  std::string s = err.str();
  if (s.size() >= 2) s.resize(s.size() - 2);
  return s;
}

BedManagerParams BedManager::loadParams(const ros::NodeHandle& pnh) {
  BedManagerParams p;
  pnh.param("robot_description_param", p.robot_description, p.robot_description);
  pnh.param("defaults_ns", p.defaults_ns, p.defaults_ns);
  pnh.param("cells_ns", p.cells_ns, p.cells_ns);
  pnh.param("joint_state_rate_hz", p.joint_state_rate_hz, p.joint_state_rate_hz);
  pnh.param("cell_timeout_s", p.cell_timeout_s, p.cell_timeout_s);
  pnh.param("diagnostics_rate_hz", p.diagnostics_rate_hz, p.diagnostics_rate_hz);
  // The cells refuse setpoints outside their controller limits: check the same limits here.
  pnh.param(p.defaults_ns + "/controller/min_height_m", p.min_height_m, p.min_height_m);
  pnh.param(p.defaults_ns + "/controller/max_height_m", p.max_height_m, p.max_height_m);
  return p;
}

BedManager::BedManager(ros::NodeHandle nh, ros::NodeHandle private_nh) : nh_(nh), private_nh_(private_nh) {
  params_ = loadParams(private_nh_);
  const std::string error = params_.validate();
  if (!error.empty()) throw std::runtime_error("bed_manager: " + error);
  std::string urdf;
  if (!nh_.getParam(params_.robot_description, urdf))
    throw std::runtime_error("bed_manager: no bed description on parameter '" +
                             nh_.resolveName(params_.robot_description) + "'");
  layout_ = BedLayout::fromUrdf(urdf);
  const std::size_t n = layout_.cells().size();
  last_state_.resize(n);
  last_seen_.assign(n, ros::Time());
  std::string prefix = params_.cells_ns;
  if (prefix.empty() || prefix.back() != '/') prefix += '/';
  for (const CellLayout& c : layout_.cells()) {
    const std::string cell_ns = prefix + names::airbagName(c.row, c.col) + "/";
    state_subs_.push_back(nh_.subscribe(cell_ns + names::kState, 2, &BedManager::onState, this));
    setpoint_pubs_.push_back(nh_.advertise<std_msgs::Float64>(cell_ns + names::kHeightSetpoint, 2));
  }
  joint_state_pub_ = nh_.advertise<sensor_msgs::JointState>(names::kJointStates, 2);
  set_height_srv_ = private_nh_.advertiseService("set_airbag_height", &BedManager::setHeight, this);
  set_heights_srv_ = private_nh_.advertiseService("set_airbag_heights", &BedManager::setHeights, this);
  joint_state_timer_ =
      nh_.createTimer(ros::Duration(1.0 / params_.joint_state_rate_hz), &BedManager::publishJointStates, this);
  diagnostics_pub_ = nh_.advertise<diagnostic_msgs::DiagnosticArray>("/diagnostics", 2);
  diagnostics_timer_ =
      nh_.createTimer(ros::Duration(1.0 / params_.diagnostics_rate_hz), &BedManager::publishDiagnostics, this);
  ROS_INFO("bed_manager: %s", layout_.describe().c_str());
}

void BedManager::onState(const AirbagState::ConstPtr& msg) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (msg->cell_id >= last_state_.size()) return;
  last_state_[msg->cell_id] = *msg;
  last_seen_[msg->cell_id] = ros::Time::now();
}

void BedManager::publishJointStates(const ros::TimerEvent&) {
  sensor_msgs::JointState js;
  js.header.stamp = ros::Time::now();
  std::lock_guard<std::mutex> lock(mutex_);
  for (const CellLayout& c : layout_.cells()) {
    if (last_seen_[c.id].isZero()) continue;  // unknown height: leave the joint out
    js.name.push_back(c.joint_name);
    const double h = last_state_[c.id].height_m;
    js.position.push_back(std::isfinite(h) ? std::clamp(h, c.min_height_m, c.max_height_m) : 0.0);
  }
  joint_state_pub_.publish(js);
}

void BedManager::publishDiagnostics(const ros::TimerEvent&) {
  diagnostic_msgs::DiagnosticArray array;
  array.header.stamp = ros::Time::now();
  int dead = 0, faulty = 0;
  std::lock_guard<std::mutex> lock(mutex_);
  for (const CellLayout& c : layout_.cells()) {
    diagnostic_msgs::DiagnosticStatus s;
    s.name = "bed/" + names::airbagName(c.row, c.col);
    s.hardware_id = "cell " + std::to_string(c.id);
    const AirbagState& st = last_state_[c.id];
    const double age = last_seen_[c.id].isZero() ? INFINITY : (array.header.stamp - last_seen_[c.id]).toSec();
    std::ostringstream msg;
    if (age > params_.cell_timeout_s) {
      s.level = diagnostic_msgs::DiagnosticStatus::ERROR;
      msg << (std::isinf(age) ? std::string("no state received") : "no state for " + std::to_string(age) + " s");
      ++dead;
    } else if (st.faults != AirbagState::FAULT_NONE) {
      s.level = diagnostic_msgs::DiagnosticStatus::WARN;
      msg << "faults:" << ((st.faults & AirbagState::FAULT_SENSOR) ? " sensor" : "")
          << ((st.faults & AirbagState::FAULT_OVERPRESSURE) ? " overpressure" : "")
          << ((st.faults & AirbagState::FAULT_COMMAND_TIMEOUT) ? " command-timeout" : "")
          << ((st.faults & AirbagState::FAULT_LOW_PRESSURE) ? " low-pressure" : "");
      ++faulty;
    } else {
      s.level = diagnostic_msgs::DiagnosticStatus::OK;
      msg << "ok";
    }
    s.message = msg.str();
    if (!last_seen_[c.id].isZero()) {
      auto kv = [&s](const std::string& k, double v) {
        diagnostic_msgs::KeyValue pair;
        pair.key = k;
        pair.value = std::to_string(v);
        s.values.push_back(pair);
      };
      kv("height_m", st.height_m);
      kv("gauge_pressure_pa", st.gauge_pressure_pa);
      kv("height_setpoint_m", st.height_setpoint_m);
      kv("external_load_n", st.external_load_n);
      kv("faults", st.faults);
    }
    array.status.push_back(s);
  }
  diagnostic_msgs::DiagnosticStatus bed;
  bed.name = "bed";
  bed.hardware_id = "nursing_bed";
  bed.level = dead ? diagnostic_msgs::DiagnosticStatus::ERROR
                   : (faulty ? diagnostic_msgs::DiagnosticStatus::WARN : diagnostic_msgs::DiagnosticStatus::OK);
  bed.message = std::to_string(layout_.cells().size()) + " cells, " + std::to_string(dead) + " not reporting, " +
                std::to_string(faulty) + " with faults";
  array.status.insert(array.status.begin(), bed);
  diagnostics_pub_.publish(array);
}

std::string BedManager::checkRequest(const std::vector<uint32_t>& ids, const std::vector<double>& heights) const {
  std::ostringstream err;
  if (ids.empty()) return "no cells given";
  if (ids.size() != heights.size()) {
    err << ids.size() << " cell ids but " << heights.size() << " heights";
    return err.str();
  }
  const ros::Time now = ros::Time::now();
  std::set<uint32_t> seen;
  std::lock_guard<std::mutex> lock(mutex_);
  for (std::size_t i = 0; i < ids.size(); ++i) {
    const CellLayout* c = layout_.findId(ids[i]);
    if (!c) {
      err << "cell " << ids[i] << " does not exist (the bed has " << layout_.cells().size() << " cells, ids 0.."
          << layout_.cells().size() - 1 << ")";
      return err.str();
    }
    if (!seen.insert(ids[i]).second) {
      err << "cell " << ids[i] << " is given twice";
      return err.str();
    }
    const double h = heights[i];
    if (!std::isfinite(h)) {
      err << "height for cell " << ids[i] << " is not a finite number";
      return err.str();
    }
    const double lo = std::max(params_.min_height_m, c->min_height_m), hi = std::min(params_.max_height_m, c->max_height_m);
    if (h < lo || h > hi) {
      err << "height " << h << " m for cell " << ids[i] << " (" << c->link_name << ") is outside [" << lo << ", "
          << hi << "] m";
      return err.str();
    }
    if (last_seen_[c->id].isZero() || (now - last_seen_[c->id]).toSec() > params_.cell_timeout_s) {
      err << "cell " << ids[i] << " (" << names::airbagName(c->row, c->col) << ") is not reporting";
      return err.str();
    }
    if (setpoint_pubs_[c->id].getNumSubscribers() == 0) {
      err << "cell " << ids[i] << " (" << names::airbagName(c->row, c->col) << ") is not connected yet";
      return err.str();
    }
  }
  return "";
}

bool BedManager::apply(const std::vector<uint32_t>& ids, const std::vector<double>& heights, std::string* message) {
  const std::string error = checkRequest(ids, heights);
  if (!error.empty()) {
    *message = error;
    return false;
  }
  for (std::size_t i = 0; i < ids.size(); ++i) {
    std_msgs::Float64 m;
    m.data = heights[i];
    setpoint_pubs_[ids[i]].publish(m);
  }
  *message = "set " + std::to_string(ids.size()) + (ids.size() == 1 ? " cell" : " cells");
  return true;
}

bool BedManager::setHeight(SetHeight::Request& req, SetHeight::Response& res) {
  res.success = apply({req.cell_id}, {req.height_m}, &res.message);
  return true;
}

bool BedManager::setHeights(SetHeights::Request& req, SetHeights::Response& res) {
  res.success = apply(req.cell_ids, req.heights_m, &res.message);
  return true;
}

}  // namespace nursing_bed
