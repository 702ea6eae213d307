// The bed manager: turns a nurse's intent (posture plans, single or many cell heights) into
// setpoints for every cell, safely; watches every cell's heartbeat and health; publishes the
// cell heights as joint_states, its own state and /diagnostics. Same class as node and nodelet.
// Interface: doc/bed_manager.md.
#pragma once

#include <ros/ros.h>
#include <sensor_msgs/JointState.h>
#include <std_msgs/Bool.h>

#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "nursing_bed/AirbagState.h"
#include "nursing_bed/BedHeights.h"
#include "nursing_bed/SetHeight.h"
#include "nursing_bed/SetHeights.h"
#include "nursing_bed/SetPosture.h"
#include "nursing_bed/core/bed/posture_plans.h"
#include "nursing_bed/core/control/rate_limiter.h"
#include "nursing_bed/ros/bed_layout.h"

namespace nursing_bed {

class BedManagerConfig;  // dynamic_reconfigure (cfg/BedManager.cfg, ros/reconfigure.h)
template <class Config>
class ReconfigureServer;

struct BedManagerParams {
  std::string robot_description = "robot_description";  ///< ~robot_description_param
  std::string defaults_ns = "/airbag_defaults";          ///< ~defaults_ns: the cells' shared parameters
  std::string cells_ns = "/";                            ///< ~cells_ns: where the airbag_<r>_<c> nodes live
  double joint_state_rate_hz = 30.0;                     ///< ~joint_state_rate_hz
  double plan_rate_hz = 10.0;                            ///< ~plan_rate_hz: plan evaluation and ~state rate
  double cell_timeout_s = 0.5;                           ///< ~cell_timeout_s: a cell silent this long is dead
  double diagnostics_rate_hz = 5.0;                      ///< ~diagnostics_rate_hz: /diagnostics rate
  double resend_s = 1.0;                                 ///< ~resend_s: setpoints and vents are repeated this often
  double leak_alarm_error_m = 0.01;                      ///< ~leak_alarm_error_m: a cell this far below its target ...
  double leak_alarm_s = 15.0;                            ///< ~leak_alarm_s: ... for this long raises the leak alarm
  /// Fastest change of a cell's target outside CPR [m/s]: the cells' safety/max_height_rate_m_s
  /// (read from ~defaults_ns, one value for the cells and the plans).
  double max_height_rate_m_s = 0.02;
  std::string initial_plan;                              ///< ~initial_plan: plan started at launch ("": none)
  PlanConfig plans;                                      ///< ~plans/...
  BodyFootprint body;                                    ///< ~body/first_row, last_row, center_y_m
  std::string validate() const;
};

class BedManager {
 public:
  BedManager(ros::NodeHandle nh, ros::NodeHandle private_nh);
  ~BedManager();
  static BedManagerParams loadParams(const ros::NodeHandle& private_nh);

 private:
  struct Running {
    std::shared_ptr<PosturePlan> plan;
    ros::Time start;
    PlanRequest request;  ///< what made it (kept on the parameter server to resume it)
  };

  void onState(const AirbagState::ConstPtr& msg);
  /// /joint_states (the URDF's joints) and ~heights (each cell's height at its own stamp).
  void publishHeights(const ros::TimerEvent&);
  sensor_msgs::JointState jointStates(const ros::Time& now) const;  ///< mutex_ held
  BedHeights bedHeights(const ros::Time& now) const;                ///< mutex_ held
  void publishDiagnostics(const ros::TimerEvent&);
  void step(const ros::TimerEvent&);
  bool setHeight(SetHeight::Request& req, SetHeight::Response& res);
  bool setHeights(SetHeights::Request& req, SetHeights::Response& res);
  bool setPosture(SetPosture::Request& req, SetPosture::Response& res);

  /// Empty when setting `heights` on `ids` is valid now, else why not. Call with mutex_ held.
  std::string checkCells(const std::vector<uint32_t>& ids, const std::vector<double>& heights) const;
  /// Manual heights: the current targets with these cells changed, as a custom plan.
  bool applyHeights(const std::vector<uint32_t>& ids, const std::vector<double>& heights, std::string* message);
  /// Starts a plan (mutex_ held); max_inflate keeps the plan it interrupts to revert to. The
  /// request is saved under ~resume so that a restarted manager resumes it.
  void start(std::shared_ptr<PosturePlan> plan, const PlanRequest& request, const ros::Time& now);
  /// The manager's own level plan at `height_m` (safe_level), with its request.
  void startSafeLevel(double height_m, const ros::Time& now);
  /// Saves the running plan's request and start under ~resume (and what max_inflate
  /// interrupted under ~resume/interrupted).
  void saveResume() const;
  void saveRunning(const std::string& ns, const Running& running) const;
  /// A plan saved under `ns` by saveRunning; false (with why, logged) when none or not valid.
  bool loadRunning(const std::string& ns, Running* running, std::string* why) const;
  /// Resumes the plan a previous manager saved under ~resume; false when there is none.
  bool resume();
  /// Height the bed levels at when a cell fails: the mean of the healthy cells' heights, within
  /// the plan limits (the nominal height when none is known).
  double safeLevel() const;
  /// The plan's targets through the rate limiter (every cell rate and the roll under the body).
  std::vector<double> limitTargets(const std::vector<double>& wanted, double dt_s);
  void onCpr(const std_msgs::Bool::ConstPtr& msg);
  /// A dynamic_reconfigure request: new alarm thresholds and plan defaults, or refused whole.
  void onReconfigure(BedManagerConfig& config);
  void publishCpr(bool on);
  /// Cells that stopped reporting or report faults; moves the bed to its safe level (mutex_ held).
  void watchCells(const ros::Time& now);
  /// The leak / low-pressure alarm of one cell (mutex_ held).
  void watchLeak(const CellLayout& c, bool silent, const ros::Time& now);
  void sendTargets(const PlanTargets& targets, const ros::Time& now);
  BedGrid grid() const;

  ros::NodeHandle nh_, private_nh_;
  BedManagerParams params_;
  BedLayout layout_;
  mutable std::mutex mutex_;
  std::vector<AirbagState> last_state_;       // by cell id
  std::vector<ros::Time> last_seen_;          // by cell id (zero: never)
  std::vector<double> sent_height_m_;         // last setpoint sent, by cell id (NaN: none)
  std::vector<ros::Time> sent_at_;            // when it was sent
  std::vector<ros::Time> below_target_since_; // leak watch, by cell id
  std::vector<bool> dead_, faulty_;
  double largest_state_gap_s_ = 0.0;  ///< longest wait between two states of one cell since the plan started [s]
  std::vector<std::string> alarms_;
  Running running_, interrupted_;
  ros::Time started_;
  PlanTargets last_targets_;
  std::unique_ptr<RateLimiter> limiter_;
  std::vector<double> limited_m_;             // rate-limited targets sent, by cell id (NaN: none)
  ros::Time last_step_;
  int cpr_published_ = -1;                    // last /cpr sent (-1: none)
  bool resumed_ = false;                      // this manager resumed a previous one's plan
  std::vector<ros::Subscriber> state_subs_;
  ros::Subscriber cpr_sub_;
  ros::Publisher heartbeat_pub_, cpr_pub_;
  std::vector<ros::Publisher> setpoint_pubs_, vent_pubs_;  // by cell id
  ros::Publisher joint_state_pub_, heights_pub_, diagnostics_pub_, state_pub_;
  ros::ServiceServer set_height_srv_, set_heights_srv_, set_posture_srv_;
  ros::Timer joint_state_timer_, diagnostics_timer_, step_timer_;
  std::unique_ptr<ReconfigureServer<BedManagerConfig>> reconfigure_;  ///< ~set_parameters
};

}  // namespace nursing_bed
