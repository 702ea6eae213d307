// The bed manager: the bed-level entry point. It validates height requests for any cell against
// the bed's layout and the cells' limits and routes them to the cells (all-or-nothing for many
// cells), and publishes the cell heights as joint_states for robot_state_publisher.
// Same class as node and nodelet. Interface: doc/bed_manager.md.
#pragma once

#include <ros/ros.h>

#include <map>
#include <mutex>
#include <string>
#include <vector>

#include "nursing_bed/AirbagState.h"
#include "nursing_bed/SetHeight.h"
#include "nursing_bed/SetHeights.h"
#include "nursing_bed/ros/bed_layout.h"

namespace nursing_bed {

struct BedManagerParams {
  std::string robot_description = "robot_description";  ///< ~robot_description_param
  std::string defaults_ns = "/airbag_defaults";          ///< ~defaults_ns: the cells' shared parameters
  std::string cells_ns = "/";                            ///< ~cells_ns: where the airbag_<r>_<c> nodes live
  double joint_state_rate_hz = 30.0;                     ///< ~joint_state_rate_hz
  double cell_timeout_s = 1.0;                           ///< ~cell_timeout_s: a cell silent this long is dead
  double diagnostics_rate_hz = 2.0;                      ///< ~diagnostics_rate_hz: /diagnostics rate
  double min_height_m = 0.0;                             ///< setpoints below are refused (cells' controller/min_height_m)
  double max_height_m = 0.150;                           ///< and above (cells' controller/max_height_m, URDF limit)
  std::string validate() const;
};

class BedManager {
 public:
  BedManager(ros::NodeHandle nh, ros::NodeHandle private_nh);
  static BedManagerParams loadParams(const ros::NodeHandle& private_nh);

  /// Empty when setting `heights` on `ids` is valid right now (all cells exist, are alive and
  /// connected, values finite and in range, no id twice), else why not. Changes nothing.
  std::string checkRequest(const std::vector<uint32_t>& ids, const std::vector<double>& heights) const;

 private:
  void onState(const AirbagState::ConstPtr& msg);
  void publishJointStates(const ros::TimerEvent&);
  void publishDiagnostics(const ros::TimerEvent&);
  bool setHeight(SetHeight::Request& req, SetHeight::Response& res);
  bool setHeights(SetHeights::Request& req, SetHeights::Response& res);
  /// Validates and sends; the response text says what happened.
  bool apply(const std::vector<uint32_t>& ids, const std::vector<double>& heights, std::string* message);

  ros::NodeHandle nh_, private_nh_;
  BedManagerParams params_;
  BedLayout layout_;
  mutable std::mutex mutex_;
  std::vector<AirbagState> last_state_;        // by cell id
  std::vector<ros::Time> last_seen_;           // by cell id (zero: never)
  std::vector<ros::Subscriber> state_subs_;
  std::vector<ros::Publisher> setpoint_pubs_;  // by cell id
  ros::Publisher joint_state_pub_, diagnostics_pub_;
  ros::ServiceServer set_height_srv_, set_heights_srv_;
  ros::Timer joint_state_timer_, diagnostics_timer_;
};

}  // namespace nursing_bed
