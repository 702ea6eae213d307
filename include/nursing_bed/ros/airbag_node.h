// The airbag node: one cell's plant, controller and safety layer (core AirbagCell) behind ROS
// topics and services. The same class runs as a node (src/nodes/airbag_node.cpp) and as a
// nodelet (nursing_bed/AirbagNodelet). Interface: doc/airbag_node.md.
#pragma once

#include <ros/ros.h>

#include <atomic>
#include <limits>
#include <memory>
#include <mutex>
#include <string>

#include <std_msgs/Bool.h>
#include <std_msgs/Empty.h>
#include <std_msgs/Float64.h>
#include <std_msgs/Float64MultiArray.h>
#include "nursing_bed/AirbagState.h"
#include "nursing_bed/SetHeight.h"
#include "nursing_bed/SetPressure.h"
#include "nursing_bed/core/control/airbag_cell.h"
#include "nursing_bed/core/io/status.h"
#include "nursing_bed/ros/airbag_hardware.h"
#include "nursing_bed/ros/bed_layout.h"

namespace nursing_bed {

class AirbagCellConfig;  // dynamic_reconfigure (cfg/AirbagCell.cfg, ros/reconfigure.h)
template <class Config>
class ReconfigureServer;

/// Everything the airbag node reads from the parameter server, validated in one place.
struct AirbagNodeParams {
  int row = -1;                                         ///< ~row: the cell's row in the bed (required)
  int col = -1;                                         ///< ~col: the cell's column (required)
  std::string defaults_ns = "/airbag_defaults";         ///< ~defaults_ns: shared parameters
  std::string robot_description = "robot_description";  ///< ~robot_description_param
  double update_rate_hz = 50.0;      ///< ~update_rate_hz: how often the simulation catches up with the clock
  double publish_rate_hz = 50.0;     ///< ~publish_rate_hz: AirbagState rate
  double load_n = 0.6;               ///< ~load_n: external load until a load topic says otherwise [N]
  double initial_height_m = 0.0;     ///< ~initial_height_m: start at rest at this height [m]
  double supply_pressure_pa = -1.0;  ///< ~supply_pressure_pa: regulator setting; < 0 keeps cell/supply/pressure_pa
  /// ~effects: effects the simulated cell has and the nominal model leaves out, for sim-to-real
  /// tests of the gap diagnosis: "NAME[:param=value,...][;NAME...]" (core/gap/effects.h; parameters
  /// not given are drawn from the noise seed). Default "": the nominal cell.
  std::string effects;
  /// ~reconfigure (else defaults_ns/reconfigure): serve ~set_parameters (dynamic_reconfigure);
  /// off, the cell starts faster.
  bool reconfigure = true;
  /// ~command_source (else defaults_ns/command_source): the node whose per-cell setpoints, vents
  /// and heartbeats the cell obeys, besides its own process (the bed manager nodelet shares it);
  /// anything else publishing them is refused, named in a warning.
  std::string command_source = "/bed_manager";
  AirbagCellParams airbag;        ///< cell/, controller/, safety/, sensors/ (private over defaults_ns)
  AirbagHardwareParams hardware;  ///< hardware/, observer/ (private over defaults_ns; doc/real_bed.md)

  /// Success, or every problem found.
  Status validate() const;
};

class AirbagNode {
 public:
  /// Reads parameters and the bed layout; throws std::runtime_error with a clear message
  /// when they are wrong (unknown key, cell not in the URDF, bad value, ...).
  AirbagNode(ros::NodeHandle nh, ros::NodeHandle private_nh);
  ~AirbagNode();

  static AirbagNodeParams loadParams(const ros::NodeHandle& private_nh);

 private:
  /// Advances the cell to `now` (called by the process's CellTicker on its simulation thread).
  void update(const ros::Time& now);
  /// Publishes the state the cell has reached, stamped with its simulated time (the ticker's
  /// publishing thread, so a slow simulation round never silences the cell).
  void publish(const ros::Time& now);
  /// A height request from the service or the manager's topic (the manager has rate-limited it):
  /// success when accepted, else why not (nothing changes).
  Status request(double height_m, const ros::Time& now);
  bool setHeight(SetHeight::Request& req, SetHeight::Response& res);
  bool setPressure(SetPressure::Request& req, SetPressure::Response& res);
  /// The cell over the hardware plugin of params_.hardware (the simulated cell by default).
  std::unique_ptr<AirbagCell> makeCell();
  void onSetpoint(const ros::MessageEvent<const std_msgs::Float64>& event);
  void onLoad(const std_msgs::Float64::ConstPtr& msg);
  void onCellLoads(const std_msgs::Float64MultiArray& msg);
  void onVent(const ros::MessageEvent<const std_msgs::Empty>& event);
  void onHeartbeat(const ros::MessageEvent<const std_msgs::Empty>& event);
  void onBedHeartbeat(const std::string& publisher);
  /// A per-cell command from `publisher` on `topic` is obeyed (the bed manager's or this
  /// process's); else false, with a throttled warning naming the publisher.
  bool commandFromOwner(const std::string& publisher, const char* topic) const;
  void onCpr(const std_msgs::Bool::ConstPtr& msg);
  /// A dynamic_reconfigure request: new controller tuning and safety thresholds for the cell
  /// (applyTuning), or refused whole (ros/reconfigure.h).
  void onReconfigure(AirbagCellConfig& config);
  /// Applies an external load from a topic, refusing bad ones with a throttled error naming `source`.
  void applyLoad(double load_n, const char* source);
  /// True while the bed manager streams setpoints to this cell (it owns the cell then).
  bool ownedByManager(const ros::Time& now) const;
  /// A streamed command or heartbeat arrived: feed (and on the first one arm) the watchdog.
  void feedWatchdog(const ros::Time& now);
  /// What the publishing thread reads of the cell: its state after its last period.
  struct CellSnapshot {
    double time_s = -1.0;
    Readings measurement{0.0, 0.0, 0.0, 0.0};  ///< zeros until the first period
    double volume_m3 = 0.0, gas_mass_kg = 0.0, gas_temperature_k = 0.0, load_n = 0.0;
    double metered_kg = 0.0, inlet_s = 0.0, vent_s = 0.0;  ///< the flow and valve totalisers
    ValveOpenings valves;
    double setpoint_m = std::numeric_limits<double>::quiet_NaN();
    double pressure_setpoint_pa = std::numeric_limits<double>::quiet_NaN();
    uint8_t height_source = 0;       ///< AirbagState::HEIGHT_* (measured or the observer's estimate)
    double height_sd_m = 0.0;        ///< the reported height's standard deviation [m]
    bool height_unverified = false;  ///< AirbagCell::heightUnverified
    uint8_t mode = 0;
    uint32_t faults = 0;
  };
  /// Copies the cell's state for the publishing thread (mutex_ held).
  void takeSnapshot();
  /// Logs when the cell starts and ends venting to find its gas (AirbagCell::findingGas) or,
  /// at debug level, to re-anchor it (AirbagCell::anchoringGas).
  void reportGasSearch();
  void publishState(const CellSnapshot& snapshot, const ros::Time& stamp);
  /// Moves a direct call's ramp one period on (simulation thread, mutex held).
  void stepDirectRamp(double now_s);
  /// Starts (or retargets) a direct call's ramp to `height_m` (checked; mutex held).
  void startDirectRamp(double height_m, double now_s);
  double elapsed(const ros::Time& now) const { return (now - start_).toSec(); }

  ros::NodeHandle nh_, private_nh_;
  AirbagNodeParams params_;
  CellLayout layout_;
  std::unique_ptr<AirbagCell> cell_;
  std::timed_mutex mutex_;     // callbacks may run on several nodelet worker threads
  std::mutex snapshot_mutex_;  ///< guards snapshot_ only (held for a copy)
  CellSnapshot snapshot_;
  bool finding_gas_ = false;    ///< the cell was venting to find its gas at the last update
  bool inconsistent_ = false;   ///< the cell's FAULT_INCONSISTENT at the last report
  int doubts_ = 0;              ///< the monitor's failures to reach target at the last report
  bool anchoring_gas_ = false;  ///< the cell was venting flat to re-anchor its gas at the last update
  bool gas_search_warned_ = false;
  double gas_search_start_s_ = 0.0;
  static constexpr double kGasSearchWarnS = 1.0;  ///< a search this long is a cell that held gas [s]
  static constexpr double kNoLoad = -1.0;
  static constexpr double kCatchUpPeriods = 2.0;  ///< most update periods a cell advances per round
  std::atomic<double> pending_load_n_{kNoLoad};
  static constexpr double kNoHeartbeat = -1.0;
  std::atomic<double> pending_heartbeat_s_{
      kNoHeartbeat};  ///< a heartbeat's time for the next update [s since start]  ///< a checked load for the next update (kNoLoad: none)
  ros::Time start_, last_publish_, last_publish_wall_;
  double last_published_time_s_ = -1.0;  ///< the cell's simulated time at the last AirbagState
  /// Cells in the bed: the length /airbag_loads must have, and what a register map must serve.
  std::size_t bed_cells_ = 0;
  ros::Time manager_setpoint_at_;  ///< last setpoint on the manager's topic
  /// A direct set_height call's final height and the ramp towards it, moved at
  /// safety/max_height_rate_m_s (NaN: no direct call in progress). The manager's stream is
  /// limited by the manager, so only direct calls ramp here.
  double direct_target_m_ = std::numeric_limits<double>::quiet_NaN();
  double direct_ramp_m_ = std::numeric_limits<double>::quiet_NaN();
  double direct_ramp_at_s_ = 0.0;
  /// The command watchdog is armed by the first streamed command (heartbeat or setpoint topic):
  /// it guards a commander that streams, not a one-off service call.
  bool watchdog_armed_ = false;
  double metered_mass_at_publish_kg_ = 0.0;  ///< the cell's flow totaliser at the last AirbagState
  double inlet_opening_at_publish_s_ = 0.0, vent_opening_at_publish_s_ = 0.0;  ///< valve integrals then
  ros::Publisher state_pub_, pressure_pub_;
  ros::Subscriber setpoint_sub_, load_sub_, vent_sub_, heartbeat_sub_, cpr_sub_;
  ros::ServiceServer set_height_srv_, set_pressure_srv_;
  int ticker_handle_ = -1;
  int bed_topics_handle_ = -1;  ///< registration with the process's BedTopics
  /// ~set_parameters; null when ~reconfigure is off. Last: destroyed first.
  std::unique_ptr<ReconfigureServer<AirbagCellConfig>> reconfigure_;
};

}  // namespace nursing_bed
