#include "nursing_bed/ros/airbag_node.h"

#include <sensor_msgs/FluidPressure.h>

#include <algorithm>
#include <boost/make_shared.hpp>
#include <cmath>
#include <sstream>

#include "nursing_bed/core/control/airbag_params_io.h"
#include "nursing_bed/core/control/cell_tuning.h"
#include "nursing_bed/core/control/rate_limiter.h"
#include "nursing_bed/core/gap/synth.h"
#include "nursing_bed/core/io/errors.h"
#include "nursing_bed/ros/bed_topics.h"
#include "nursing_bed/ros/cell_ticker.h"
#include "nursing_bed/ros/names.h"
#include "nursing_bed/ros/reconfigure.h"
#include "nursing_bed/ros/ros_params.h"

namespace nursing_bed {

Status AirbagNodeParams::validate() const {
  ErrorList errors;
  errors.addIf(row < 0 || col < 0, "~row and ~col must be set to the cell's place in the bed (>= 0)");
  errors.addIf(!(update_rate_hz > 0.0 && update_rate_hz <= 1000.0), "~update_rate_hz must lie in (0, 1000]");
  errors.addIf(!(publish_rate_hz > 0.0 && publish_rate_hz <= update_rate_hz),
               "~publish_rate_hz must lie in (0, update_rate_hz]");
  errors.addIf(!(load_n >= 0.0 && std::isfinite(load_n)), "~load_n must be >= 0 N");
  errors.addIf(!(initial_height_m >= 0.0 && initial_height_m <= airbag.controller.max_height_m),
               "~initial_height_m must lie in [0, controller/max_height_m]");
  errors.addIf(!std::isfinite(supply_pressure_pa), "~supply_pressure_pa must be finite");
  errors.addIf(command_source.empty() || command_source.front() != '/',
               "~command_source must be a node's absolute name (e.g. /bed_manager)");
  try {
    effectsFromText(effects, static_cast<std::uint32_t>(airbag.noise_seed));
  } catch (const std::invalid_argument& e) {
    errors.add("~effects: ", e.what());
  }
  errors.addNested(airbag.validate());
  errors.addNested(hardware.validate());
  return errors.status();
}

AirbagNodeParams AirbagNode::loadParams(const ros::NodeHandle& pnh) {
  AirbagNodeParams p;
  pnh.param("row", p.row, p.row);
  pnh.param("col", p.col, p.col);
  pnh.param("defaults_ns", p.defaults_ns, p.defaults_ns);
  pnh.param("robot_description_param", p.robot_description, p.robot_description);
  // The rate may come from the defaults namespace too (real_bed.launch runs the cells faster).
  if (!pnh.getParam("update_rate_hz", p.update_rate_hz))
    pnh.param(p.defaults_ns + "/update_rate_hz", p.update_rate_hz, p.update_rate_hz);
  pnh.param("publish_rate_hz", p.publish_rate_hz, p.publish_rate_hz);
  pnh.param("load_n", p.load_n, p.load_n);
  pnh.param("initial_height_m", p.initial_height_m, p.initial_height_m);
  pnh.param("supply_pressure_pa", p.supply_pressure_pa, p.supply_pressure_pa);
  pnh.param("effects", p.effects, p.effects);
  if (!pnh.getParam("reconfigure", p.reconfigure))
    pnh.param(p.defaults_ns + "/reconfigure", p.reconfigure, p.reconfigure);
  if (!pnh.getParam("command_source", p.command_source))
    pnh.param(p.defaults_ns + "/command_source", p.command_source, p.command_source);
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
  const Status valid = params_.validate();
  if (!valid)
    throw std::runtime_error("airbag " + names::airbagName(params_.row, params_.col) + ": " + valid.message());

  cell_ = makeCell();
  if (!params_.effects.empty())
    ROS_INFO("airbag %s: simulated with hidden effects: %s", names::airbagName(params_.row, params_.col).c_str(),
             params_.effects.c_str());
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
  vent_sub_ = private_nh_.subscribe(names::kVent, 10, &AirbagNode::onVent, this);
  heartbeat_sub_ = private_nh_.subscribe(names::kHeartbeat, 10, &AirbagNode::onHeartbeat, this);
  // The bed-wide loads and heartbeat come through the process's one subscription (BedTopics).
  bed_topics_handle_ = BedTopics::instance().add(
      BedTopics::Handlers{[this](const std_msgs::Float64MultiArray& loads) { onCellLoads(loads); },
                          [this](const std::string& publisher) { onBedHeartbeat(publisher); }});
  cpr_sub_ = nh_.subscribe(names::kCpr, 2, &AirbagNode::onCpr, this);
  start_ = ros::Time::now();
  last_publish_ = start_;
  takeSnapshot();
  CellTicker& ticker = CellTicker::instance(params_.update_rate_hz);
  if (ticker.rateHz() != params_.update_rate_hz)
    ROS_WARN("%s: ~update_rate_hz %g ignored: this process's airbags tick at %g Hz (the first one's rate)",
             layout_.link_name.c_str(), params_.update_rate_hz, ticker.rateHz());
  params_.update_rate_hz = ticker.rateHz();
  ticker_handle_ =
      ticker.add([this](const ros::Time& now) { update(now); }, [this](const ros::Time& now) { publish(now); });
  if (params_.reconfigure)  // each server costs the start-up a few master calls per parameter
    reconfigure_ = std::make_unique<ReconfigureServer<AirbagCellConfig>>(
        private_nh_, airbagConfigFrom(params_), [this](AirbagCellConfig& config) { onReconfigure(config); });
  ROS_DEBUG("airbag %s (cell %u) up: %s", layout_.link_name.c_str(), layout_.id, cell_->hardware().describe().c_str());
  const std::string warning = cell_->hardware().warning();
  if (!warning.empty()) ROS_WARN_ONCE("%s", warning.c_str());  // once per process: a terminal's cells share it
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
  if (bed_topics_handle_ >= 0) BedTopics::instance().remove(bed_topics_handle_);
  if (ticker_handle_ >= 0) CellTicker::instance(params_.update_rate_hz).remove(ticker_handle_);
}

void AirbagNode::update(const ros::Time& now) {
  std::lock_guard<std::timed_mutex> lock(mutex_);
  const double load = pending_load_n_.exchange(kNoLoad);
  if (load != kNoLoad) cell_->setLoad(load);  // checked in applyLoad
  const double heartbeat_s = pending_heartbeat_s_.exchange(kNoHeartbeat);
  if (heartbeat_s != kNoHeartbeat) feedWatchdog(start_ + ros::Duration(heartbeat_s));
  // At most kCatchUpPeriods per round: when simulating the bed costs more than real time for a
  // moment (180 cells lifting off flat at once after CPR), a cell runs late and catches up over
  // the next rounds instead of jumping: its states keep coming, each stamped with the time it
  // describes, never more than kCatchUpPeriods periods apart (doc/safety.md).
  // Real hardware does not wait: its cell always runs to now (the observer integrates the
  // whole time the valves kept their command), and to its own now, read at its turn in the
  // round, not the round's: the driver reports its valves' pulses averaged since the last
  // read(), and the cell integrates that mean over its own period (with the round's time a
  // cell late in the round would count a pulse as pulse x period / span; doc/real_bed.md).
  const double period_s = 1.0 / params_.update_rate_hz;
  const double until_s = params_.hardware.simulated()
                             ? std::min(elapsed(now), cell_->time() + kCatchUpPeriods * period_s)
                             : elapsed(ros::Time::now());
  stepDirectRamp(until_s);
  cell_->advanceTo(until_s);
  reportGasSearch();
  takeSnapshot();
}

void AirbagNode::reportGasSearch() {
  // A bed started flat is found flat within reanchor_time_s (its first commands wait that
  // long, at debug level); a cell that held gas vents for seconds, and that is worth a warning.
  const bool finding = cell_->findingGas();
  if (finding && !finding_gas_) {
    gas_search_start_s_ = cell_->time();
    gas_search_warned_ = false;
    ROS_DEBUG("%s: commanded before its gas was known: venting until found flat", layout_.link_name.c_str());
  }
  if (finding && !gas_search_warned_ && cell_->time() - gas_search_start_s_ > kGasSearchWarnS) {
    gas_search_warned_ = true;
    ROS_WARN(
        "%s: started over a cell holding gas (%.0f Pa now, no height sensor): venting it flat before it is "
        "controlled; its height is unknown until then (height_sd_m inf)",
        layout_.link_name.c_str(), cell_->measurement().gauge_pressure_pa);
  }
  if (!finding && finding_gas_ && gas_search_warned_) {
    ROS_INFO("%s: vented flat in %.1f s, its gas known again: controlled from here", layout_.link_name.c_str(),
             cell_->time() - gas_search_start_s_);
  }
  finding_gas_ = finding;
  // An inconsistency between the readings and the observer is worth a warning with its reason.
  const bool inconsistent = (cell_->faults() & kFaultInconsistent) != 0;
  if (inconsistent && !inconsistent_ && cell_->monitor())
    ROS_WARN("%s: readings inconsistent with the observer (%s): finding its gas again, flagged until then",
             layout_.link_name.c_str(), cell_->monitor()->reason().c_str());
  inconsistent_ = inconsistent;
  if (cell_->monitor() && cell_->monitor()->progress().failures() != doubts_) {
    doubts_ = cell_->monitor()->progress().failures();
    ROS_WARN("%s: %s; its counted gas doubted, the height reported unverified until found flat",
             layout_.link_name.c_str(), cell_->monitor()->progress().lastFailure().c_str());
  }
  const bool anchoring = cell_->anchoringGas();
  if (anchoring != anchoring_gas_) {
    ROS_DEBUG("%s: %s", layout_.link_name.c_str(),
              !anchoring               ? "re-anchoring over"
              : cell_->recountingGas() ? "its counted vent gas doubtful (observer/recount_doubt_m): venting flat to "
                                         "re-anchor its gas"
                                       : "lowered into the low band (observer/reanchor_below_m): venting flat to "
                                         "re-anchor its gas");
  }
  anchoring_gas_ = anchoring;
}

void AirbagNode::stepDirectRamp(double now_s) {
  if (!std::isfinite(direct_target_m_)) return;
  direct_ramp_m_ =
      limitRate(direct_ramp_m_, direct_target_m_, params_.airbag.safety.max_height_rate_m_s, now_s - direct_ramp_at_s_);
  direct_ramp_at_s_ = now_s;
  // A ramp point the cell refuses (CPR started meanwhile) ends the call.
  if (!cell_->requestHeight(direct_ramp_m_, now_s).empty() || direct_ramp_m_ == direct_target_m_)
    direct_target_m_ = std::numeric_limits<double>::quiet_NaN();
}

void AirbagNode::takeSnapshot() {
  const CellVariables& v = cell_->variables();
  CellSnapshot s;
  s.time_s = cell_->time();
  s.measurement = cell_->measurement();
  s.volume_m3 = v.structure.volume_m3;
  s.gas_mass_kg = v.mass_kg;
  s.gas_temperature_k = v.temperature_k;
  s.load_n = cell_->load();
  s.metered_kg = cell_->meteredInletMassKg();
  s.inlet_s = cell_->inletOpeningSeconds();
  s.vent_s = cell_->ventOpeningSeconds();
  s.valves = cell_->valves();
  s.setpoint_m = cell_->setpoint();
  s.pressure_setpoint_pa = cell_->pressureSetpoint();
  s.height_source = static_cast<uint8_t>(cell_->heightSource());
  s.height_sd_m = cell_->heightSd();
  s.height_unverified = cell_->heightUnverified();
  s.mode = static_cast<uint8_t>(cell_->mode());
  s.faults = cell_->faults();
  std::lock_guard<std::mutex> lock(snapshot_mutex_);
  snapshot_ = s;
}

void AirbagNode::publish(const ros::Time& now) {
  // The publishing thread reads the snapshot the simulation thread left after the cell's last
  // period, never the cell itself: it never waits for a cell being advanced (waiting per cell,
  // it would follow a slow round cell by cell and leave gaps after CPR).
  CellSnapshot s;
  {
    std::lock_guard<std::mutex> lock(snapshot_mutex_);
    s = snapshot_;
  }
  const double since_s = (now - last_publish_wall_).toSec();
  if (since_s < 1.0 / params_.publish_rate_hz - 0.5 / params_.update_rate_hz) return;
  // A state is published when the simulation has moved on, and repeated (same stamp) while a
  // slow simulation round holds it back: the cell's controller is alive, its plant is late.
  // Repeats only when late, so a cell that keeps up never publishes a stamp twice.
  const bool advanced = s.time_s != last_published_time_s_;
  const bool late = elapsed(now) - s.time_s > 1.5 / params_.update_rate_hz;
  if (!advanced && !late) return;
  publishState(s, start_ + ros::Duration(s.time_s));
  last_published_time_s_ = s.time_s;
  last_publish_wall_ = now;
}

void AirbagNode::publishState(const CellSnapshot& s, const ros::Time& stamp) {
  const Readings& m = s.measurement;
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
  msg.height_source = s.height_source;
  msg.height_sd_m = s.height_sd_m;
  msg.height_unverified = s.height_unverified;
  msg.volume_m3 = s.volume_m3;
  msg.gas_mass_kg = s.gas_mass_kg;
  msg.gas_temperature_k = s.gas_temperature_k;
  // Mean metered inflow since the previous message (from the totaliser): what a logged flow
  // meter gives, and what a replay of the recording can integrate (doc/airbag_node.md).
  const double interval_s = (stamp - last_publish_).toSec();
  msg.inflow_kg_s = interval_s > 0.0 ? (s.metered_kg - metered_mass_at_publish_kg_) / interval_s : m.inflow_kg_s;
  metered_mass_at_publish_kg_ = s.metered_kg;
  msg.external_load_n = s.load_n;
  // Mean valve openings since the previous message, for the same reason: a 200 Hz valve
  // sampled at 50 Hz would misstate the gas it let through.
  msg.inlet_valve_cmd = interval_s > 0.0 ? (s.inlet_s - inlet_opening_at_publish_s_) / interval_s : s.valves.inlet;
  msg.vent_valve_cmd = interval_s > 0.0 ? (s.vent_s - vent_opening_at_publish_s_) / interval_s : s.valves.vent;
  msg.inlet_valve_cmd = std::clamp(msg.inlet_valve_cmd, 0.0, 1.0);
  msg.vent_valve_cmd = std::clamp(msg.vent_valve_cmd, 0.0, 1.0);
  inlet_opening_at_publish_s_ = s.inlet_s;
  vent_opening_at_publish_s_ = s.vent_s;
  msg.height_setpoint_m = s.setpoint_m;
  msg.pressure_setpoint_pa = s.pressure_setpoint_pa;
  msg.mode = s.mode;
  msg.faults = s.faults;
  last_publish_ = stamp;
  state_pub_.publish(out);
  if (pressure_pub_.getNumSubscribers() > 0) {
    sensor_msgs::FluidPressure p;
    p.header = msg.header;
    p.fluid_pressure = params_.airbag.cell.ambient_pressure_pa + m.gauge_pressure_pa;  // absolute, per the message
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

Status AirbagNode::request(double height_m, const ros::Time& now) {
  return Status::fromMessage(cell_->requestHeight(height_m, elapsed(now)));
}

bool AirbagNode::setHeight(SetHeight::Request& req, SetHeight::Response& res) {
  std::lock_guard<std::timed_mutex> lock(mutex_);
  const ros::Time now = ros::Time::now();
  std::ostringstream msg;
  if (req.cell_id != layout_.id) {
    msg << "cell " << req.cell_id << " is not served here: this is " << layout_.link_name << ", cell " << layout_.id;
  } else if (ownedByManager(now)) {
    msg << "cell " << layout_.id << " (" << layout_.link_name << ") is run by the bed manager, whose setpoints keep "
        << "coming: ask /bed_manager/set_airbag_height, which makes it a custom target";
  } else {
    const std::string error = cell_->checkHeight(req.height_m);
    if (error.empty()) {
      startDirectRamp(req.height_m, elapsed(now));
      msg << "height setpoint " << req.height_m << " m accepted (no bed manager runs this cell), reached at "
          << params_.airbag.safety.max_height_rate_m_s << " m/s at most";
    } else {
      msg << error;
    }
    res.success = error.empty();
  }
  res.message = msg.str();
  return true;
}

void AirbagNode::startDirectRamp(double height_m, double now_s) {
  // From the height the cell is going to (or is at, when it has no target).
  const double from = std::isfinite(cell_->setpoint()) ? cell_->setpoint() : cell_->variables().height_m;
  direct_ramp_m_ = std::isfinite(direct_target_m_) ? direct_ramp_m_ : std::max(from, 0.0);
  direct_target_m_ = height_m;
  direct_ramp_at_s_ = now_s;
}

bool AirbagNode::setPressure(SetPressure::Request& req, SetPressure::Response& res) {
  std::lock_guard<std::timed_mutex> lock(mutex_);
  const ros::Time now = ros::Time::now();
  std::string error;
  if (req.cell_id != layout_.id)
    error = "cell " + std::to_string(req.cell_id) + " is not served here: this is " + layout_.link_name + ", cell " +
            std::to_string(layout_.id);
  else if (ownedByManager(now))
    error = "cell " + std::to_string(layout_.id) + " (" + layout_.link_name +
            ") is run by the bed manager, whose height setpoints keep coming and would replace a pressure setpoint";
  else error = cell_->requestPressure(req.pressure_pa, elapsed(now));
  // A pressure setpoint ends a direct height call's ramp (it would take the cell back to height).
  if (error.empty()) direct_target_m_ = std::numeric_limits<double>::quiet_NaN();
  res.success = error.empty();
  res.message = error.empty() ? "pressure setpoint " + std::to_string(req.pressure_pa) + " Pa accepted" : error;
  return true;
}

bool AirbagNode::commandFromOwner(const std::string& publisher, const char* topic) const {
  // Intra-process messages carry this process's name (the bed manager nodelet's).
  if (publisher == params_.command_source || publisher == ros::this_node::getName()) return true;
  ROS_WARN_THROTTLE(1.0, "%s: %s from %s refused: only %s (or this process) commands the cell",
                    layout_.link_name.c_str(), topic, publisher.c_str(), params_.command_source.c_str());
  return false;
}

void AirbagNode::onSetpoint(const ros::MessageEvent<const std_msgs::Float64>& event) {
  if (!commandFromOwner(event.getPublisherName(), names::kHeightSetpoint)) return;
  const std_msgs::Float64::ConstPtr msg = event.getConstMessage();
  std::lock_guard<std::timed_mutex> lock(mutex_);
  const ros::Time now = ros::Time::now();
  const Status accepted = request(msg->data, now);
  if (!accepted) {
    ROS_WARN_THROTTLE(1.0, "%s: setpoint %g refused: %s", layout_.link_name.c_str(), msg->data,
                      accepted.message().c_str());
    return;
  }
  direct_target_m_ = std::numeric_limits<double>::quiet_NaN();  // the manager owns the cell now
  manager_setpoint_at_ = now;
  feedWatchdog(now);
}

void AirbagNode::feedWatchdog(const ros::Time& now) {
  cell_->heartbeat(elapsed(now));
  if (!watchdog_armed_) cell_->setCommandTimeout(params_.airbag.safety.command_timeout_s);
  watchdog_armed_ = true;
}

void AirbagNode::applyLoad(double load_n, const char* source) {
  // Loads arrive for every cell at the simulator's rate: the callback only checks and buffers
  // (checkLoad reads the fixed parameters), the simulation thread applies it. A worker thread
  // never waits for a cell that is being advanced.
  const std::string error = cell_->checkLoad(load_n);
  if (!error.empty()) {
    ROS_ERROR_THROTTLE(1.0, "%s: %s from %s", layout_.link_name.c_str(), error.c_str(), source);
    return;
  }
  pending_load_n_ = load_n;
}

void AirbagNode::onLoad(const std_msgs::Float64::ConstPtr& msg) { applyLoad(msg->data, "its load topic"); }

void AirbagNode::onCellLoads(const std_msgs::Float64MultiArray& msg) {
  if (msg.data.size() != bed_cells_) {
    ROS_ERROR_THROTTLE(1.0, "%s: %s refused: %zu loads for a bed of %zu cells", layout_.link_name.c_str(),
                       names::kCellLoads, msg.data.size(), bed_cells_);
    return;
  }
  applyLoad(msg.data[layout_.id], names::kCellLoads);
}

void AirbagNode::onVent(const ros::MessageEvent<const std_msgs::Empty>& event) {
  if (!commandFromOwner(event.getPublisherName(), names::kVent)) return;
  std::lock_guard<std::timed_mutex> lock(mutex_);
  direct_target_m_ = std::numeric_limits<double>::quiet_NaN();
  cell_->requestVent(elapsed(ros::Time::now()));
  takeSnapshot();
}

void AirbagNode::onCpr(const std_msgs::Bool::ConstPtr& msg) {
  std::lock_guard<std::timed_mutex> lock(mutex_);
  if (msg->data == cell_->cpr()) return;
  direct_target_m_ = std::numeric_limits<double>::quiet_NaN();
  ROS_DEBUG("%s: bed-wide CPR %s", layout_.link_name.c_str(),
            msg->data ? "on: venting, heights refused" : "off: holding");
  cell_->setCpr(msg->data, elapsed(ros::Time::now()));
  takeSnapshot();
}

void AirbagNode::onReconfigure(AirbagCellConfig& config) {
  ReconfiguredKeys changed;
  {
    std::lock_guard<std::timed_mutex> lock(mutex_);
    AirbagNodeParams p = params_;
    if (!reconfigureRequest(config, &p, &changed, names::airbagName(params_.row, params_.col))) return;
    const std::string error = applyTuning(*cell_, p.airbag.controller, p.airbag.safety);
    if (!error.empty()) {  // the cell's own checks (e.g. load_filter_time_s on a running controller)
      ROS_ERROR("%s: dynamic_reconfigure refused: %s (the running values stay)", layout_.link_name.c_str(),
                error.c_str());
      config = airbagConfigFrom(params_);
      return;
    }
    // Only what the cell was tuned with: the publishing thread reads other fields unlocked.
    params_.airbag.controller = p.airbag.controller;
    params_.airbag.safety = p.airbag.safety;
  }
  saveReconfigured(private_nh_, changed);
}

void AirbagNode::onHeartbeat(const ros::MessageEvent<const std_msgs::Empty>& event) {
  onBedHeartbeat(event.getPublisherName());
}

void AirbagNode::onBedHeartbeat(const std::string& publisher) {
  // A stray heartbeat would keep the cell out of SAFE while its manager is dead.
  if (!commandFromOwner(publisher, names::kHeartbeat)) return;
  // Buffered like the loads: the simulation thread feeds the watchdog, so the process's one
  // heartbeat thread never waits for a cell being advanced.
  pending_heartbeat_s_ = elapsed(ros::Time::now());
}

}  // namespace nursing_bed
