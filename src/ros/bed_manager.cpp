#include "nursing_bed/ros/bed_manager.h"

#include <diagnostic_msgs/DiagnosticArray.h>
#include <sensor_msgs/JointState.h>
#include <std_msgs/Empty.h>
#include <std_msgs/Float64.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <set>
#include <sstream>

#include "nursing_bed/BedState.h"
#include "nursing_bed/ros/names.h"
#include "nursing_bed/ros/ros_params.h"

namespace nursing_bed {
namespace {
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
// Cells that have never reported are only counted dead after this start-up grace [s].
constexpr double kStartupGraceS = 10.0;
}  // namespace

std::string BedManagerParams::validate() const {
  std::ostringstream err;
  if (!(joint_state_rate_hz > 0.0 && joint_state_rate_hz <= 200.0)) err << "~joint_state_rate_hz must lie in (0, 200]; ";
  if (!(plan_rate_hz > 0.0 && plan_rate_hz <= 100.0)) err << "~plan_rate_hz must lie in (0, 100]; ";
  if (!(cell_timeout_s > 0.0)) err << "~cell_timeout_s must be positive; ";
  if (!(diagnostics_rate_hz > 0.0 && diagnostics_rate_hz <= 50.0)) err << "~diagnostics_rate_hz must lie in (0, 50]; ";
  if (!(resend_s > 0.0)) err << "~resend_s must be positive; ";
  if (!(leak_alarm_error_m > 0.0 && leak_alarm_s > 0.0)) err << "~leak_alarm_error_m and ~leak_alarm_s must be positive; ";
  if (body.first_row < 0 || body.last_row < body.first_row) err << "~body rows must satisfy 0 <= first_row <= last_row; ";
  const std::string plan_error = plans.validate();
  if (!plan_error.empty()) err << "~plans: " << plan_error << "; ";
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
  pnh.param("plan_rate_hz", p.plan_rate_hz, p.plan_rate_hz);
  pnh.param("cell_timeout_s", p.cell_timeout_s, p.cell_timeout_s);
  pnh.param("diagnostics_rate_hz", p.diagnostics_rate_hz, p.diagnostics_rate_hz);
  pnh.param("resend_s", p.resend_s, p.resend_s);
  pnh.param("leak_alarm_error_m", p.leak_alarm_error_m, p.leak_alarm_error_m);
  pnh.param("leak_alarm_s", p.leak_alarm_s, p.leak_alarm_s);
  pnh.param("initial_plan", p.initial_plan, p.initial_plan);
  applyFlatParams(flattenRosParams(pnh, "plans"), "parameters " + pnh.resolveName("plans"), planConfigFields(), &p.plans);
  pnh.param("body/first_row", p.body.first_row, p.body.first_row);
  pnh.param("body/last_row", p.body.last_row, p.body.last_row);
  pnh.param("body/center_y_m", p.body.center_y_m, p.body.center_y_m);
  // Plans must stay inside what the cells accept.
  double cell_max = p.plans.max_height_m;
  pnh.param(p.defaults_ns + "/controller/max_height_m", cell_max, cell_max);
  if (p.plans.max_height_m > cell_max) {
    std::ostringstream m;
    m << "bed_manager: ~plans/max_height_m " << p.plans.max_height_m << " m exceeds the cells' controller/max_height_m "
      << cell_max << " m";
    throw std::runtime_error(m.str());
  }
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
  params_.plans.max_height_m = std::min(params_.plans.max_height_m, layout_.cells().front().max_height_m);
  params_.body.last_row = std::min(params_.body.last_row, layout_.rows() - 1);
  params_.body.first_row = std::min(params_.body.first_row, params_.body.last_row);
  const std::size_t n = layout_.cells().size();
  last_state_.resize(n);
  last_seen_.assign(n, ros::Time());
  sent_height_m_.assign(n, kNaN);
  sent_at_.assign(n, ros::Time());
  below_target_since_.assign(n, ros::Time());
  dead_.assign(n, false);
  faulty_.assign(n, false);
  std::string prefix = params_.cells_ns;
  if (prefix.empty() || prefix.back() != '/') prefix += '/';
  for (const CellLayout& c : layout_.cells()) {
    const std::string cell_ns = prefix + names::airbagName(c.row, c.col) + "/";
    state_subs_.push_back(nh_.subscribe(cell_ns + names::kState, 2, &BedManager::onState, this));
    setpoint_pubs_.push_back(nh_.advertise<std_msgs::Float64>(cell_ns + names::kHeightSetpoint, 2));
    vent_pubs_.push_back(nh_.advertise<std_msgs::Empty>(cell_ns + names::kVent, 2));
  }
  joint_state_pub_ = nh_.advertise<sensor_msgs::JointState>(names::kJointStates, 2);
  diagnostics_pub_ = nh_.advertise<diagnostic_msgs::DiagnosticArray>("/diagnostics", 2);
  state_pub_ = private_nh_.advertise<BedState>("state", 2);
  set_height_srv_ = private_nh_.advertiseService("set_airbag_height", &BedManager::setHeight, this);
  set_heights_srv_ = private_nh_.advertiseService("set_airbag_heights", &BedManager::setHeights, this);
  set_posture_srv_ = private_nh_.advertiseService("set_posture", &BedManager::setPosture, this);
  started_ = ros::Time::now();
  running_.start = started_;
  if (!params_.initial_plan.empty()) {
    std::string why;
    auto plan = makePlan(PlanRequest{params_.initial_plan, {}, {}}, params_.plans, grid(), params_.body, &why);
    if (!plan) throw std::runtime_error("bed_manager: ~initial_plan: " + why);
    start(std::shared_ptr<PosturePlan>(std::move(plan)), ros::Time::now());
  }
  joint_state_timer_ =
      nh_.createTimer(ros::Duration(1.0 / params_.joint_state_rate_hz), &BedManager::publishJointStates, this);
  diagnostics_timer_ =
      nh_.createTimer(ros::Duration(1.0 / params_.diagnostics_rate_hz), &BedManager::publishDiagnostics, this);
  step_timer_ = nh_.createTimer(ros::Duration(1.0 / params_.plan_rate_hz), &BedManager::step, this);
  ROS_INFO("bed_manager: %s", layout_.describe().c_str());
}

BedGrid BedManager::grid() const {
  BedGrid g;
  g.rows = layout_.rows();
  g.cols = layout_.cols();
  g.pitch_m = layout_.pitchM();
  g.min_height_m = layout_.cells().front().min_height_m;
  g.max_height_m = layout_.cells().front().max_height_m;
  return g;
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

void BedManager::start(std::shared_ptr<PosturePlan> plan, const ros::Time& now) {
  if (plan->name() == "max_inflate" && running_.plan && running_.plan->name() != "max_inflate") interrupted_ = running_;
  else if (plan->name() != "max_inflate") interrupted_ = Running{};
  running_ = Running{std::move(plan), now};
  std::fill(sent_at_.begin(), sent_at_.end(), ros::Time());  // send every target at once
  ROS_INFO("bed_manager: plan %s %s", running_.plan->name().c_str(), running_.plan->describe().c_str());
}

void BedManager::watchCells(const ros::Time& now) {
  const bool past_grace = (now - started_).toSec() > kStartupGraceS;
  alarms_.clear();
  for (const CellLayout& c : layout_.cells()) {
    const bool never = last_seen_[c.id].isZero();
    const bool dead = never ? past_grace : (now - last_seen_[c.id]).toSec() > params_.cell_timeout_s;
    const bool faulty = !dead && !never && (last_state_[c.id].faults & AirbagState::FAULT_SENSOR);
    if ((dead && !dead_[c.id]) || (faulty && !faulty_[c.id])) {
      // Keep the patient level: every cell to the failed cell's last height.
      const double h = never ? params_.plans.nominal_height_m
                             : std::clamp(last_state_[c.id].height_m, params_.plans.min_height_m, params_.plans.max_height_m);
      ROS_ERROR("bed_manager: cell %u (%s) %s; holding the bed level at %.3f m", c.id,
                names::airbagName(c.row, c.col).c_str(), dead ? "stopped reporting" : "reports a sensor fault", h);
      if (!(running_.plan && running_.plan->name() == "cpr")) start(makeSafeLevelPlan(grid(), h), now);
    }
    dead_[c.id] = dead;
    faulty_[c.id] = faulty;
    // Leak / low pressure: a cell held well below its target for long.
    const double target = sent_height_m_[c.id];
    if (!dead && !never && std::isfinite(target) && last_state_[c.id].height_m < target - params_.leak_alarm_error_m) {
      if (below_target_since_[c.id].isZero()) below_target_since_[c.id] = now;
      if ((now - below_target_since_[c.id]).toSec() > params_.leak_alarm_s) {
        std::ostringstream a;
        a << "cell " << c.id << " (" << names::airbagName(c.row, c.col) << ") low pressure or leak: "
          << 1e3 * (target - last_state_[c.id].height_m) << " mm below its target for "
          << (now - below_target_since_[c.id]).toSec() << " s";
        alarms_.push_back(a.str());
      }
    } else {
      below_target_since_[c.id] = ros::Time();
    }
  }
}

void BedManager::sendTargets(const PlanTargets& targets, const ros::Time& now) {
  for (const CellLayout& c : layout_.cells()) {
    const bool due = sent_at_[c.id].isZero() || (now - sent_at_[c.id]).toSec() >= params_.resend_s;
    if (targets.vent_all) {
      if (due || std::isfinite(sent_height_m_[c.id])) {
        vent_pubs_[c.id].publish(std_msgs::Empty());
        sent_height_m_[c.id] = kNaN;
        sent_at_[c.id] = now;
      }
      continue;
    }
    if (c.id >= targets.heights_m.size() || !std::isfinite(targets.heights_m[c.id])) continue;
    const double h = targets.heights_m[c.id];
    if (due || !(std::fabs(h - sent_height_m_[c.id]) < 2e-4)) {
      std_msgs::Float64 m;
      m.data = h;
      setpoint_pubs_[c.id].publish(m);
      sent_height_m_[c.id] = h;
      sent_at_[c.id] = now;
    }
  }
}

void BedManager::step(const ros::TimerEvent&) {
  const ros::Time now = ros::Time::now();
  std::lock_guard<std::mutex> lock(mutex_);
  watchCells(now);
  BedState state;
  state.header.stamp = now;
  if (running_.plan) {
    PlanTargets t = running_.plan->targets((now - running_.start).toSec());
    if (t.finished && running_.plan->name() == "max_inflate") {
      // Back to what max_inflate interrupted, where it left off.
      const double paused = (now - running_.start).toSec();
      if (interrupted_.plan) {
        running_ = Running{interrupted_.plan, interrupted_.start + ros::Duration(paused)};
      } else {
        running_ = Running{makeSafeLevelPlan(grid(), params_.plans.nominal_height_m), now};
      }
      interrupted_ = Running{};
      std::fill(sent_at_.begin(), sent_at_.end(), ros::Time());
      ROS_INFO("bed_manager: max_inflate timed out, back to %s", running_.plan->name().c_str());
      t = running_.plan->targets((now - running_.start).toSec());
    }
    sendTargets(t, now);
    last_targets_ = t;
    state.plan = running_.plan->name();
    state.parameters = running_.plan->describe();
    state.elapsed_s = (now - running_.start).toSec();
  }
  state.phase = last_targets_.phase;
  state.tilt_deg = last_targets_.tilt_deg;
  state.target_heights_m = last_targets_.vent_all ? std::vector<double>(layout_.cells().size(), kNaN)
                                                  : last_targets_.heights_m;
  for (const CellLayout& c : layout_.cells()) {
    if (dead_[c.id]) state.dead_cells.push_back(c.id);
    if (faulty_[c.id]) state.faulty_cells.push_back(c.id);
  }
  state.alarms = alarms_;
  state_pub_.publish(state);
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
                   : ((faulty || !alarms_.empty()) ? diagnostic_msgs::DiagnosticStatus::WARN
                                                   : diagnostic_msgs::DiagnosticStatus::OK);
  bed.message = std::to_string(layout_.cells().size()) + " cells, " + std::to_string(dead) + " not reporting, " +
                std::to_string(faulty) + " with faults" + (alarms_.empty() ? "" : "; " + alarms_.front());
  for (const std::string& a : alarms_) {
    diagnostic_msgs::KeyValue pair;
    pair.key = "alarm";
    pair.value = a;
    bed.values.push_back(pair);
  }
  if (running_.plan) {
    diagnostic_msgs::KeyValue pair;
    pair.key = "plan";
    pair.value = running_.plan->name() + " (" + last_targets_.phase + ")";
    bed.values.push_back(pair);
  }
  array.status.insert(array.status.begin(), bed);
  diagnostics_pub_.publish(array);
}

std::string BedManager::checkCells(const std::vector<uint32_t>& ids, const std::vector<double>& heights) const {
  std::ostringstream err;
  if (ids.empty()) return "no cells given";
  if (ids.size() != heights.size()) {
    err << ids.size() << " cell ids but " << heights.size() << " heights";
    return err.str();
  }
  const ros::Time now = ros::Time::now();
  std::set<uint32_t> seen;
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
    const double lo = c->min_height_m, hi = std::min(params_.plans.max_height_m, c->max_height_m);
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

bool BedManager::applyHeights(const std::vector<uint32_t>& ids, const std::vector<double>& heights,
                              std::string* message) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (running_.plan && running_.plan->name() == "cpr") {
    *message = "CPR is running: start a plan (e.g. flat) to end it before setting heights";
    return false;
  }
  const std::string error = checkCells(ids, heights);
  if (!error.empty()) {
    *message = error;
    return false;
  }
  // The other cells keep what they have now: their current setpoint, else their height.
  std::vector<double> target(layout_.cells().size());
  for (const CellLayout& c : layout_.cells()) {
    const double sent = sent_height_m_[c.id];
    const double measured = std::clamp(last_state_[c.id].height_m, c.min_height_m, c.max_height_m);
    target[c.id] = std::isfinite(sent) ? sent : (std::isfinite(measured) && !last_seen_[c.id].isZero() ? measured : kNaN);
  }
  for (std::size_t i = 0; i < ids.size(); ++i) target[ids[i]] = heights[i];
  const ros::Time now = ros::Time::now();
  start(makeCustomPlan(target), now);
  const PlanTargets t = running_.plan->targets(0.0);
  sendTargets(t, now);
  last_targets_ = t;
  *message = "set " + std::to_string(ids.size()) + (ids.size() == 1 ? " cell" : " cells");
  return true;
}

bool BedManager::setHeight(SetHeight::Request& req, SetHeight::Response& res) {
  res.success = applyHeights({req.cell_id}, {req.height_m}, &res.message);
  return true;
}

bool BedManager::setHeights(SetHeights::Request& req, SetHeights::Response& res) {
  res.success = applyHeights(req.cell_ids, req.heights_m, &res.message);
  return true;
}

bool BedManager::setPosture(SetPosture::Request& req, SetPosture::Response& res) {
  PlanRequest request{req.plan, {}, req.heights_m};
  if (req.keys.size() != req.values.size()) {
    res.success = false;
    res.message = std::to_string(req.keys.size()) + " keys but " + std::to_string(req.values.size()) + " values";
    return true;
  }
  for (std::size_t i = 0; i < req.keys.size(); ++i) {
    if (!request.args.emplace(req.keys[i], req.values[i]).second) {
      res.success = false;
      res.message = "argument '" + req.keys[i] + "' is given twice";
      return true;
    }
  }
  std::string why;
  std::lock_guard<std::mutex> lock(mutex_);
  auto plan = makePlan(request, params_.plans, grid(), params_.body, &why);
  if (!plan) {
    res.success = false;
    res.message = why;
    return true;
  }
  const std::string description = plan->name() + " " + plan->describe();
  start(std::shared_ptr<PosturePlan>(std::move(plan)), ros::Time::now());
  res.success = true;
  res.message = "started " + description;
  return true;
}

}  // namespace nursing_bed
