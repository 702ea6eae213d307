// The bed manager: the ROS face of the bed supervisor (core bed_supervisor.h, which holds the
// policy: plans, safety, requests). It converts the cells' states, the services and /cpr for
// it, carries out what it decides (setpoints, vents, heartbeat, /cpr, logs, the resume record
// under ~resume), and publishes the cell heights as joint_states, its state and /diagnostics.
// Same class as node and nodelet. Interface: doc/bed_manager.md.
#pragma once

#include <ros/ros.h>
#include <std_msgs/Bool.h>

#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "nursing_bed/AirbagState.h"
#include "nursing_bed/SetHeight.h"
#include "nursing_bed/SetHeights.h"
#include "nursing_bed/SetPosture.h"
#include "nursing_bed/core/bed/bed_supervisor.h"
#include "nursing_bed/ros/bed_layout.h"

namespace nursing_bed {

class BedManagerConfig;  // dynamic_reconfigure (cfg/BedManager.cfg, ros/reconfigure.h)
template <class Config>
class ReconfigureServer;

struct BedManagerParams {
  std::string robot_description = "robot_description";  ///< ~robot_description_param
  std::string defaults_ns = "/airbag_defaults";         ///< ~defaults_ns: the cells' shared parameters
  std::string cells_ns = "/";                           ///< ~cells_ns: where the airbag_<r>_<c> nodes live
  double joint_state_rate_hz = 30.0;                    ///< ~joint_state_rate_hz
  double plan_rate_hz = 10.0;                           ///< ~plan_rate_hz: plan evaluation and ~state rate
  double diagnostics_rate_hz = 5.0;                     ///< ~diagnostics_rate_hz: /diagnostics rate
  std::string initial_plan;                             ///< ~initial_plan: plan started at launch ("" or "none": none)
  /// ~cell_timeout_s, ~resend_s, ~leak_alarm_error_m, ~leak_alarm_s, ~plans/..., ~body/..., and
  /// the cells' safety/max_height_rate_m_s (from ~defaults_ns).
  BedSupervisorParams bed;
  /// Empty when valid, else every problem, naming the parameters.
  std::string validate() const;
};

class BedManager {
 public:
  BedManager(ros::NodeHandle nh, ros::NodeHandle private_nh);
  ~BedManager();
  static BedManagerParams loadParams(const ros::NodeHandle& private_nh);

 private:
  void onState(const AirbagState::ConstPtr& msg);
  void onCpr(const std_msgs::Bool::ConstPtr& msg);
  /// A dynamic_reconfigure request: new alarm thresholds, cell timeout and plan defaults for the
  /// supervisor (BedSupervisor::setTunables), or refused whole.
  void onReconfigure(BedManagerConfig& config);
  /// /joint_states (the URDF's joints) and ~heights (each cell's height at its own stamp).
  void publishHeights(const ros::TimerEvent&);
  void publishDiagnostics(const ros::TimerEvent&);
  void publishDiagnosticsLocked(const ros::Time& now);  ///< with mutex_ held
  static constexpr double kWatchRateHz = 50.0;          ///< the dead-cell watch's rate [Hz]
  void step(const ros::TimerEvent&);
  /// Watches the cells between plan steps; a newly failed cell is on /diagnostics at once.
  void watchCells(const ros::TimerEvent&);
  bool setHeight(SetHeight::Request& req, SetHeight::Response& res);
  bool setHeights(SetHeights::Request& req, SetHeights::Response& res);
  bool setPosture(SetPosture::Request& req, SetPosture::Response& res);
  /// Publishes, logs and stores what the supervisor asks for (mutex_ held).
  void carryOut(SupervisorOutput out);
  /// By cell id: something subscribes to the cell's setpoints.
  std::vector<bool> connected() const;
  /// The record under ~resume (what a previous manager saved), if any.
  std::optional<ResumeRecord> loadResume() const;
  std::optional<SavedPlan> loadSaved(const std::string& ns) const;
  void saveResume(const ResumeRecord& record) const;
  void saveSaved(const std::string& ns, const SavedPlan& saved) const;

  ros::NodeHandle nh_, private_nh_;
  BedManagerParams params_;
  BedLayout layout_;
  mutable std::mutex mutex_;
  std::unique_ptr<BedSupervisor> supervisor_;
  std::vector<AirbagState> last_state_;  // by cell id, as published
  std::vector<ros::Subscriber> state_subs_;
  ros::Subscriber cpr_sub_;
  ros::Publisher heartbeat_pub_, cpr_pub_;
  std::vector<ros::Publisher> setpoint_pubs_, vent_pubs_;  // by cell id
  ros::Publisher joint_state_pub_, heights_pub_, diagnostics_pub_, state_pub_;
  ros::ServiceServer set_height_srv_, set_heights_srv_, set_posture_srv_;
  ros::Timer joint_state_timer_, diagnostics_timer_, step_timer_, watch_timer_;
  /// ~set_parameters. Last: destroyed first.
  std::unique_ptr<ReconfigureServer<BedManagerConfig>> reconfigure_;
};

}  // namespace nursing_bed
