#include "nursing_bed/ros/bed_manager.h"

#include <std_msgs/Empty.h>
#include <std_msgs/Float64.h>

#include "nursing_bed/ros/bed_manager_msgs.h"
#include "nursing_bed/ros/names.h"
#include "nursing_bed/ros/reconfigure.h"

namespace nursing_bed {

BedManager::BedManager(ros::NodeHandle nh, ros::NodeHandle private_nh) : nh_(nh), private_nh_(private_nh) {
  params_ = loadParams(private_nh_);
  const std::string error = params_.validate();
  if (!error.empty()) throw std::runtime_error("bed_manager: " + error);
  std::string urdf;
  if (!nh_.getParam(params_.robot_description, urdf))
    throw std::runtime_error("bed_manager: no bed description on parameter '" +
                             nh_.resolveName(params_.robot_description) + "'");
  layout_ = BedLayout::fromUrdf(urdf);
  supervisor_ =
      std::make_unique<BedSupervisor>(params_.bed, bedGrid(layout_), bedCells(layout_), ros::Time::now().toSec());
  last_state_.resize(layout_.cells().size());
  std::string prefix = params_.cells_ns;
  if (prefix.empty() || prefix.back() != '/') prefix += '/';
  for (const CellLayout& c : layout_.cells()) {
    const std::string cell_ns = prefix + names::airbagName(c.row, c.col) + "/";
    state_subs_.push_back(nh_.subscribe(cell_ns + names::kState, 2, &BedManager::onState, this));
    setpoint_pubs_.push_back(nh_.advertise<std_msgs::Float64>(cell_ns + names::kHeightSetpoint, 2));
    vent_pubs_.push_back(nh_.advertise<std_msgs::Empty>(cell_ns + names::kVent, 2));
  }
  heartbeat_pub_ = nh_.advertise<std_msgs::Empty>(names::kBedHeartbeat, 2);
  cpr_pub_ = nh_.advertise<std_msgs::Bool>(names::kCpr, 1, true);
  cpr_sub_ = nh_.subscribe(names::kCpr, 2, &BedManager::onCpr, this);
  joint_state_pub_ = nh_.advertise<sensor_msgs::JointState>(names::kJointStates, 2);
  heights_pub_ = private_nh_.advertise<BedHeights>("heights", 2);
  diagnostics_pub_ = nh_.advertise<diagnostic_msgs::DiagnosticArray>("/diagnostics", 2);
  state_pub_ = private_nh_.advertise<BedState>("state", 2);
  set_height_srv_ = private_nh_.advertiseService("set_airbag_height", &BedManager::setHeight, this);
  set_heights_srv_ = private_nh_.advertiseService("set_airbag_heights", &BedManager::setHeights, this);
  set_posture_srv_ = private_nh_.advertiseService("set_posture", &BedManager::setPosture, this);
  {
    std::lock_guard<std::mutex> lock(mutex_);
    const double now_s = ros::Time::now().toSec();
    if (!supervisor_->resume(loadResume(), now_s).ok && !params_.initial_plan.empty()) {
      const RequestResult r = supervisor_->setPosture(params_.initial_plan, {}, {}, {}, now_s);
      if (!r.ok) throw std::runtime_error("bed_manager: ~initial_plan: " + r.message);
    }
    carryOut(supervisor_->takeOutput());
  }
  joint_state_timer_ =
      nh_.createTimer(ros::Duration(1.0 / params_.joint_state_rate_hz), &BedManager::publishHeights, this);
  diagnostics_timer_ =
      nh_.createTimer(ros::Duration(1.0 / params_.diagnostics_rate_hz), &BedManager::publishDiagnostics, this);
  step_timer_ = nh_.createTimer(ros::Duration(1.0 / params_.plan_rate_hz), &BedManager::step, this);
  watch_timer_ = nh_.createTimer(ros::Duration(1.0 / kWatchRateHz), &BedManager::watchCells, this);
  reconfigure_ = std::make_unique<ReconfigureServer<BedManagerConfig>>(
      private_nh_, bedManagerConfigFrom(params_), [this](BedManagerConfig& config) { onReconfigure(config); });
  ROS_INFO("bed_manager: %s", layout_.describe().c_str());
}

BedManager::~BedManager() = default;

void BedManager::carryOut(SupervisorOutput out) {
  if (out.heartbeat) heartbeat_pub_.publish(std_msgs::Empty());
  for (const CellCommand& c : out.commands) {
    if (c.vent) {
      vent_pubs_[c.id].publish(std_msgs::Empty());
    } else {
      std_msgs::Float64 m;
      m.data = c.height_m;
      setpoint_pubs_[c.id].publish(m);
    }
  }
  if (out.cpr) {
    std_msgs::Bool m;
    m.data = *out.cpr;
    cpr_pub_.publish(m);
  }
  if (out.resume_record) saveResume(*out.resume_record);
  for (const BedEvent& e : out.events) {
    if (e.severity == Severity::kError) ROS_ERROR("bed_manager: %s", e.text.c_str());
    else if (e.severity == Severity::kWarn) ROS_WARN("bed_manager: %s", e.text.c_str());
    else ROS_INFO("bed_manager: %s", e.text.c_str());
  }
}

void BedManager::saveResume(const ResumeRecord& record) const {
  const std::string ns = std::string(names::kResumeParam) + "/";
  saveSaved(ns, record.running);
  // What max_inflate interrupted, so a restarted manager still goes back to it.
  if (record.interrupted) saveSaved(ns + "interrupted/", *record.interrupted);
  else private_nh_.deleteParam(ns + "interrupted");
}

void BedManager::saveSaved(const std::string& ns, const SavedPlan& saved) const {
  std::vector<std::string> keys, values;
  for (const auto& kv : saved.request.args) {
    keys.push_back(kv.first);
    values.push_back(kv.second);
  }
  private_nh_.setParam(ns + "plan", saved.request.plan);
  private_nh_.setParam(ns + "keys", keys);
  private_nh_.setParam(ns + "values", values);
  private_nh_.setParam(ns + "heights_m", saved.request.heights_m);
  private_nh_.setParam(ns + "start_s", saved.start_s);
}

std::optional<SavedPlan> BedManager::loadSaved(const std::string& ns) const {
  SavedPlan saved;
  std::vector<std::string> keys, values;
  if (!private_nh_.getParam(ns + "plan", saved.request.plan)) return std::nullopt;
  private_nh_.getParam(ns + "keys", keys);
  private_nh_.getParam(ns + "values", values);
  private_nh_.getParam(ns + "heights_m", saved.request.heights_m);
  private_nh_.getParam(ns + "start_s", saved.start_s);
  for (std::size_t i = 0; i < keys.size() && i < values.size(); ++i) saved.request.args[keys[i]] = values[i];
  return saved;
}

std::optional<ResumeRecord> BedManager::loadResume() const {
  const std::string ns = std::string(names::kResumeParam) + "/";
  std::optional<SavedPlan> running = loadSaved(ns);
  if (!running) return std::nullopt;
  return ResumeRecord{*running, loadSaved(ns + "interrupted/")};
}

void BedManager::onState(const AirbagState::ConstPtr& msg) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (supervisor_->onCellState(cellSnapshot(*msg, ros::Time::now().toSec()))) last_state_[msg->cell_id] = *msg;
}

void BedManager::onCpr(const std_msgs::Bool::ConstPtr& msg) {
  std::lock_guard<std::mutex> lock(mutex_);
  supervisor_->onCpr(msg->data, ros::Time::now().toSec());
  carryOut(supervisor_->takeOutput());
}

void BedManager::onReconfigure(BedManagerConfig& config) {
  ReconfiguredKeys changed;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    BedManagerParams p = params_;
    if (!reconfigureRequest(config, &p, &changed, "bed_manager")) return;
    const std::string error = supervisor_->setTunables(p.bed);
    if (!error.empty()) {  // the supervisor's own checks (e.g. the plan limits narrowed to the cells)
      ROS_ERROR("bed_manager: dynamic_reconfigure refused: %s (the running values stay)", error.c_str());
      config = bedManagerConfigFrom(params_);
      return;
    }
    params_ = p;  // plan defaults apply to plans started from now on
  }
  saveReconfigured(private_nh_, changed);
}

void BedManager::publishHeights(const ros::TimerEvent&) {
  std::lock_guard<std::mutex> lock(mutex_);
  // Taken under the lock: a state stored meanwhile (by onState) is stamped before this.
  const ros::Time now = ros::Time::now();
  joint_state_pub_.publish(jointStatesMsg(layout_, last_state_, supervisor_->health(), now));
  heights_pub_.publish(bedHeightsMsg(layout_, last_state_, supervisor_->health(), now));
}

void BedManager::publishDiagnostics(const ros::TimerEvent&) {
  const ros::Time now = ros::Time::now();
  std::lock_guard<std::mutex> lock(mutex_);
  publishDiagnosticsLocked(now);
}

void BedManager::publishDiagnosticsLocked(const ros::Time& now) {
  const BedReport report = supervisor_->report(now.toSec());
  diagnostics_pub_.publish(diagnosticsMsg(report, layout_, last_state_, supervisor_->health(), now));
}

void BedManager::watchCells(const ros::TimerEvent&) {
  const ros::Time now = ros::Time::now();
  std::lock_guard<std::mutex> lock(mutex_);
  const std::size_t changed = supervisor_->watch(now.toSec());
  carryOut(supervisor_->takeOutput());
  if (changed > 0) publishDiagnosticsLocked(now);
}

void BedManager::step(const ros::TimerEvent&) {
  const ros::Time now = ros::Time::now();
  std::lock_guard<std::mutex> lock(mutex_);
  const BedStatus status = supervisor_->step(now.toSec());
  carryOut(supervisor_->takeOutput());
  state_pub_.publish(bedStateMsg(status, now));
}

std::vector<bool> BedManager::connected() const {
  std::vector<bool> c;
  for (const ros::Publisher& p : setpoint_pubs_) c.push_back(p.getNumSubscribers() > 0);
  return c;
}

bool BedManager::setHeight(SetHeight::Request& req, SetHeight::Response& res) {
  std::lock_guard<std::mutex> lock(mutex_);
  const RequestResult r = supervisor_->setHeights({req.cell_id}, {req.height_m}, connected(), ros::Time::now().toSec());
  carryOut(supervisor_->takeOutput());
  res.success = r.ok;
  res.message = r.message;
  return true;
}

bool BedManager::setHeights(SetHeights::Request& req, SetHeights::Response& res) {
  std::lock_guard<std::mutex> lock(mutex_);
  const RequestResult r = supervisor_->setHeights(req.cell_ids, req.heights_m, connected(), ros::Time::now().toSec());
  carryOut(supervisor_->takeOutput());
  res.success = r.ok;
  res.message = r.message;
  return true;
}

bool BedManager::setPosture(SetPosture::Request& req, SetPosture::Response& res) {
  std::lock_guard<std::mutex> lock(mutex_);
  const RequestResult r =
      supervisor_->setPosture(req.plan, req.keys, req.values, req.heights_m, ros::Time::now().toSec());
  carryOut(supervisor_->takeOutput());
  res.success = r.ok;
  res.message = r.message;
  return true;
}

}  // namespace nursing_bed
