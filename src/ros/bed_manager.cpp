#include "nursing_bed/ros/bed_manager.h"

#include <diagnostic_msgs/DiagnosticArray.h>
#include <std_msgs/Empty.h>
#include <std_msgs/Float64.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <set>
#include <sstream>

#include "nursing_bed/BedState.h"
#include "nursing_bed/core/control/airbag_cell.h"
#include "nursing_bed/ros/names.h"
#include "nursing_bed/ros/reconfigure.h"
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
  if (!(max_height_rate_m_s > 0.0 && std::isfinite(max_height_rate_m_s)))
    err << "the cells' safety/max_height_rate_m_s must be positive; ";
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
  pnh.param(p.defaults_ns + "/safety/max_height_rate_m_s", p.max_height_rate_m_s, p.max_height_rate_m_s);
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
  limited_m_.assign(n, kNaN);
  RateLimits limits;
  limits.max_rate_per_s = params_.max_height_rate_m_s;
  limits.slope_weights = rollSlopeWeights(grid(), params_.body);
  limits.max_angle_rate_rad_s = params_.plans.bed_tilt_rate_fraction * params_.plans.max_tilt_rate_deg_s * M_PI / 180.0;
  limiter_ = std::make_unique<RateLimiter>(limits, n);
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
  started_ = ros::Time::now();
  running_.start = started_;
  if (!resume() && !params_.initial_plan.empty()) {
    std::string why;
    const PlanRequest request{params_.initial_plan, {}, {}};
    auto plan = makePlan(request, params_.plans, grid(), params_.body, &why);
    if (!plan) throw std::runtime_error("bed_manager: ~initial_plan: " + why);
    start(std::shared_ptr<PosturePlan>(std::move(plan)), request, ros::Time::now());
  }
  joint_state_timer_ =
      nh_.createTimer(ros::Duration(1.0 / params_.joint_state_rate_hz), &BedManager::publishHeights, this);
  diagnostics_timer_ =
      nh_.createTimer(ros::Duration(1.0 / params_.diagnostics_rate_hz), &BedManager::publishDiagnostics, this);
  step_timer_ = nh_.createTimer(ros::Duration(1.0 / params_.plan_rate_hz), &BedManager::step, this);
  reconfigure_ = std::make_unique<ReconfigureServer<BedManagerConfig>>(
      private_nh_, bedManagerConfigFrom(params_), [this](BedManagerConfig& config) { onReconfigure(config); });
  ROS_INFO("bed_manager: %s", layout_.describe().c_str());
}

BedManager::~BedManager() = default;

void BedManager::onReconfigure(BedManagerConfig& config) {
  ReconfiguredKeys changed;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    BedManagerParams p = params_;
    if (!reconfigureRequest(config, &p, &changed, "bed_manager")) return;
    params_ = p;  // read under mutex_ only; plan defaults apply to plans started from now on
  }
  saveReconfigured(private_nh_, changed);
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
  const ros::Time now = ros::Time::now();
  // What the dead-cell timeout has as margin: the longest silence of a live cell.
  if (!last_seen_[msg->cell_id].isZero())
    largest_state_gap_s_ = std::max(largest_state_gap_s_, (now - last_seen_[msg->cell_id]).toSec());
  last_seen_[msg->cell_id] = now;
}

void BedManager::publishHeights(const ros::TimerEvent&) {
  std::lock_guard<std::mutex> lock(mutex_);
  // Taken under the lock: a state stored meanwhile (by onState) is stamped before this.
  const ros::Time now = ros::Time::now();
  joint_state_pub_.publish(jointStates(now));
  heights_pub_.publish(bedHeights(now));
}

sensor_msgs::JointState BedManager::jointStates(const ros::Time& now) const {
  sensor_msgs::JointState js;
  js.header.stamp = now;
  for (const CellLayout& c : layout_.cells()) {
    if (last_seen_[c.id].isZero()) continue;  // unknown height: leave the joint out
    js.name.push_back(c.joint_name);
    const double h = last_state_[c.id].height_m;
    js.position.push_back(std::isfinite(h) ? std::clamp(h, c.min_height_m, c.max_height_m) : 0.0);
  }
  return js;
}

BedHeights BedManager::bedHeights(const ros::Time& now) const {
  // The heights as the cells reported them (not clamped for the URDF), each at its own stamp.
  BedHeights out;
  out.header.stamp = now;
  const std::size_t n = layout_.cells().size();
  out.stamps.assign(n, ros::Time());
  out.height_m.assign(n, kNaN);
  out.height_sd_m.assign(n, kNaN);
  out.height_source.assign(n, AirbagState::HEIGHT_MEASURED);
  for (const CellLayout& c : layout_.cells()) {
    if (last_seen_[c.id].isZero()) continue;
    const AirbagState& s = last_state_[c.id];
    out.stamps[c.id] = s.header.stamp;
    out.height_m[c.id] = s.height_m;
    out.height_sd_m[c.id] = s.height_sd_m;
    out.height_source[c.id] = s.height_source;
  }
  return out;
}

void BedManager::start(std::shared_ptr<PosturePlan> plan, const PlanRequest& request, const ros::Time& now) {
  if (plan->name() == "max_inflate" && running_.plan && running_.plan->name() != "max_inflate") interrupted_ = running_;
  else if (plan->name() != "max_inflate") interrupted_ = Running{};
  running_ = Running{std::move(plan), now, request};
  largest_state_gap_s_ = 0.0;
  std::fill(sent_at_.begin(), sent_at_.end(), ros::Time());  // send every target at once
  if (running_.plan->name() == "cpr") publishCpr(true);
  else if (cpr_published_ == 1) publishCpr(false);
  saveResume();
  ROS_INFO("bed_manager: plan %s %s", running_.plan->name().c_str(), running_.plan->describe().c_str());
}

void BedManager::startSafeLevel(double height_m, const ros::Time& now) {
  start(makeSafeLevelPlan(grid(), height_m), PlanRequest{"safe_level", {}, {height_m}}, now);
}

void BedManager::saveResume() const {
  const std::string ns = std::string(names::kResumeParam) + "/";
  saveRunning(ns, running_);
  // What max_inflate interrupted, so a restarted manager still goes back to it.
  if (interrupted_.plan) saveRunning(ns + "interrupted/", interrupted_);
  else private_nh_.deleteParam(ns + "interrupted");
}

void BedManager::saveRunning(const std::string& ns, const Running& running) const {
  const PlanRequest& r = running.request;
  std::vector<std::string> keys, values;
  for (const auto& kv : r.args) {
    keys.push_back(kv.first);
    values.push_back(kv.second);
  }
  private_nh_.setParam(ns + "plan", r.plan);
  private_nh_.setParam(ns + "keys", keys);
  private_nh_.setParam(ns + "values", values);
  private_nh_.setParam(ns + "heights_m", r.heights_m);
  private_nh_.setParam(ns + "start_s", running.start.toSec());
}

bool BedManager::loadRunning(const std::string& ns, Running* running, std::string* why) const {
  PlanRequest request;
  std::vector<std::string> keys, values;
  double start_s = 0.0;
  if (!private_nh_.getParam(ns + "plan", request.plan)) return false;
  private_nh_.getParam(ns + "keys", keys);
  private_nh_.getParam(ns + "values", values);
  private_nh_.getParam(ns + "heights_m", request.heights_m);
  private_nh_.getParam(ns + "start_s", start_s);
  for (std::size_t i = 0; i < keys.size() && i < values.size(); ++i) request.args[keys[i]] = values[i];
  std::unique_ptr<PosturePlan> plan;
  if (request.plan == "safe_level" && request.heights_m.size() == 1)
    plan = makeSafeLevelPlan(grid(), request.heights_m[0]);
  else
    plan = makePlan(request, params_.plans, grid(), params_.body, why);
  if (plan && (!(start_s > 0.0) || start_s > ros::Time::now().toSec())) {
    *why = "bad start time " + std::to_string(start_s);
    plan.reset();
  }
  if (!plan) {
    ROS_ERROR("bed_manager: restarted, but the saved plan '%s' cannot be resumed (%s)", request.plan.c_str(),
              why->c_str());
    return false;
  }
  *running = Running{std::shared_ptr<PosturePlan>(std::move(plan)), ros::Time(start_s), request};
  return true;
}

bool BedManager::resume() {
  const std::string ns = std::string(names::kResumeParam) + "/";
  Running saved, interrupted;
  std::string why;
  if (!loadRunning(ns, &saved, &why)) return false;
  const bool has_interrupted = loadRunning(ns + "interrupted/", &interrupted, &why);
  resumed_ = true;
  const ros::Time now = ros::Time::now();
  if (has_interrupted && saved.plan->name() == "max_inflate") running_ = interrupted;  // start() keeps it
  start(saved.plan, saved.request, saved.start);
  ROS_WARN("bed_manager: restarted: resuming plan %s (%s), started %.1f s ago%s", saved.request.plan.c_str(),
           running_.plan->describe().c_str(), (now - saved.start).toSec(),
           interrupted_.plan ? (", then back to " + interrupted_.request.plan).c_str() : "");
  return true;
}

void BedManager::publishCpr(bool on) {
  std_msgs::Bool msg;
  msg.data = on;
  cpr_pub_.publish(msg);
  cpr_published_ = on ? 1 : 0;
}

void BedManager::onCpr(const std_msgs::Bool::ConstPtr& msg) {
  if (!msg->data) return;
  std::lock_guard<std::mutex> lock(mutex_);
  if (running_.plan && running_.plan->name() == "cpr") return;
  ROS_WARN("bed_manager: bed-wide CPR started from outside (%s): following it", names::kCpr);
  std::string why;
  const PlanRequest request{"cpr", {}, {}};
  start(std::shared_ptr<PosturePlan>(makePlan(request, params_.plans, grid(), params_.body, &why)), request,
        ros::Time::now());
}

double BedManager::safeLevel() const {
  double sum = 0.0;
  int n = 0;
  for (const CellLayout& c : layout_.cells()) {
    const double h = last_state_[c.id].height_m;
    if (dead_[c.id] || faulty_[c.id] || last_seen_[c.id].isZero() || !std::isfinite(h)) continue;
    sum += h;
    ++n;
  }
  const double level = n > 0 ? sum / n : params_.plans.nominal_height_m;
  return std::clamp(level, params_.plans.min_height_m, params_.plans.max_height_m);
}

std::vector<double> BedManager::limitTargets(const std::vector<double>& wanted, double dt_s) {
  if (wanted.size() != limited_m_.size()) return wanted;
  for (const CellLayout& c : layout_.cells()) {
    const double h = last_state_[c.id].height_m;
    // Nothing sent yet (start, after CPR): the ramp starts where the cell is.
    if (!std::isfinite(limited_m_[c.id]) && !last_seen_[c.id].isZero() && std::isfinite(h))
      limited_m_[c.id] = std::clamp(h, c.min_height_m, c.max_height_m);
  }
  limited_m_ = limiter_->step(limited_m_, wanted, dt_s);
  return limited_m_;
}

void BedManager::watchCells(const ros::Time& now) {
  const bool past_grace = (now - started_).toSec() > kStartupGraceS;
  alarms_.clear();
  std::vector<std::string> failed;
  for (const CellLayout& c : layout_.cells()) {
    const bool never = last_seen_[c.id].isZero();
    const bool dead = never ? past_grace : (now - last_seen_[c.id]).toSec() > params_.cell_timeout_s;
    const bool faulty = !dead && !never && (last_state_[c.id].faults & (AirbagState::FAULT_SENSOR | kFaultModel));
    if ((dead && !dead_[c.id]) || (faulty && !faulty_[c.id])) {
      const AirbagState& s = last_state_[c.id];
      failed.push_back("cell " + std::to_string(c.id) + " (" + names::airbagName(c.row, c.col) + ") " +
                       (dead ? "stopped reporting"
                             : "reports a sensor or model fault (faults " + std::to_string(s.faults) + ", " +
                                   std::to_string(s.gauge_pressure_pa) + " Pa, " + std::to_string(s.height_m) +
                                   " m, load " + std::to_string(s.external_load_n) + " N)"));
    }
    dead_[c.id] = dead;
    faulty_[c.id] = faulty;
    watchLeak(c, dead || never, now);
  }
  if (failed.empty()) return;
  // Keep the patient level, at the healthy cells' mean height, reached at the limited rates.
  const double h = safeLevel();
  for (const std::string& f : failed) ROS_ERROR("bed_manager: %s; levelling the bed at %.3f m", f.c_str(), h);
  if (!(running_.plan && running_.plan->name() == "cpr")) startSafeLevel(h, now);
}

void BedManager::watchLeak(const CellLayout& c, bool silent, const ros::Time& now) {
  // Leak / low pressure: a cell held well below its target for long.
  const double target = sent_height_m_[c.id];
  if (!silent && std::isfinite(target) && last_state_[c.id].height_m < target - params_.leak_alarm_error_m) {
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
  // The cells' command watchdog: fed while the manager runs the bed (has a plan).
  if (running_.plan) heartbeat_pub_.publish(std_msgs::Empty());
  const double dt_s = last_step_.isZero() ? 0.0 : std::max(0.0, (now - last_step_).toSec());
  last_step_ = now;
  watchCells(now);
  BedState state;
  state.header.stamp = now;
  state.largest_state_gap_s = largest_state_gap_s_;
  if (running_.plan) {
    PlanTargets t = running_.plan->targets((now - running_.start).toSec());
    if (t.finished && running_.plan->name() == "max_inflate") {
      // Back to what max_inflate interrupted, where it left off.
      const double paused = (now - running_.start).toSec();
      if (interrupted_.plan) {
        running_ = Running{interrupted_.plan, interrupted_.start + ros::Duration(paused), interrupted_.request};
      } else {
        const double h = params_.plans.nominal_height_m;
        running_ = Running{makeSafeLevelPlan(grid(), h), now, PlanRequest{"safe_level", {}, {h}}};
      }
      interrupted_ = Running{};
      saveResume();
      std::fill(sent_at_.begin(), sent_at_.end(), ros::Time());
      ROS_INFO("bed_manager: max_inflate timed out, back to %s", running_.plan->name().c_str());
      t = running_.plan->targets((now - running_.start).toSec());
    }
    if (t.vent_all) {
      std::fill(limited_m_.begin(), limited_m_.end(), kNaN);
      sendTargets(t, now);
    } else {
      PlanTargets limited = t;
      limited.heights_m = limitTargets(t.heights_m, dt_s);
      sendTargets(limited, now);
    }
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
          << ((st.faults & AirbagState::FAULT_LOW_PRESSURE) ? " low-pressure" : "")
          << ((st.faults & kFaultModel) ? " model-reset" : "");
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
    pair.value = running_.plan->name() + " (" + last_targets_.phase + ")" +
                 (resumed_ ? ", resumed after a restart of the bed manager" : "");
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
    // One source of limits: what a plan may command.
    const double lo = std::max(params_.plans.min_height_m, c->min_height_m);
    const double hi = std::min(params_.plans.max_height_m, c->max_height_m);
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
  // The other cells keep where they are going: the plan's target, else what was sent, else
  // their height (within the plan limits).
  std::vector<double> target(layout_.cells().size(), kNaN);
  const bool planned = !last_targets_.vent_all && last_targets_.heights_m.size() == target.size();
  for (const CellLayout& c : layout_.cells()) {
    const double measured = last_seen_[c.id].isZero() ? kNaN : last_state_[c.id].height_m;
    double h = planned ? last_targets_.heights_m[c.id] : kNaN;
    if (!std::isfinite(h)) h = std::isfinite(sent_height_m_[c.id]) ? sent_height_m_[c.id] : measured;
    target[c.id] = std::isfinite(h) ? std::clamp(h, params_.plans.min_height_m, params_.plans.max_height_m) : kNaN;
  }
  for (std::size_t i = 0; i < ids.size(); ++i) target[ids[i]] = heights[i];
  PlanRequest request{"custom", {}, target};
  start(makeCustomPlan(target), request, ros::Time::now());
  *message = "set " + std::to_string(ids.size()) + (ids.size() == 1 ? " cell" : " cells") + " as a custom plan, reached at " +
             std::to_string(params_.max_height_rate_m_s) + " m/s at most";
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
  start(std::shared_ptr<PosturePlan>(std::move(plan)), request, ros::Time::now());
  res.success = true;
  res.message = "started " + description;
  return true;
}

}  // namespace nursing_bed
