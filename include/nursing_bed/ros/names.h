// Topic, service and parameter names of the nursing_bed nodes, in one place.
#pragma once

#include <string>

namespace nursing_bed {
namespace names {

// Per airbag (relative to the airbag node's private namespace, e.g. /airbag_3_4/...).
constexpr const char* kState = "state";                     // nursing_bed/AirbagState
constexpr const char* kPressure = "pressure";               // sensor_msgs/FluidPressure (absolute Pa)
constexpr const char* kSetHeight = "set_height";            // nursing_bed/SetHeight
constexpr const char* kSetPressure = "set_pressure";        // nursing_bed/SetPressure
constexpr const char* kHeightSetpoint = "height_setpoint";  // std_msgs/Float64 [m], streaming setpoints
constexpr const char* kLoad = "load";                       // std_msgs/Float64 [N], external load
constexpr const char* kVent = "vent";                       // std_msgs/Empty: vent fully (CPR)
constexpr const char* kHeartbeat = "heartbeat";             // std_msgs/Empty: command watchdog

// Bed level (absolute).
constexpr const char* kCellLoads = "/airbag_loads";    // std_msgs/Float64MultiArray [N], index = cell id
constexpr const char* kJointStates = "/joint_states";  // sensor_msgs/JointState, cell heights
constexpr const char* kDefaultsNamespace = "/airbag_defaults";
constexpr const char* kCpr = "/cpr";                             // std_msgs/Bool, latched: bed-wide CPR on/off
constexpr const char* kBedHeartbeat = "/bed_manager/heartbeat";  // std_msgs/Empty: the manager is alive
constexpr const char* kResumeParam = "resume";                   // ~resume/...: the bed manager's running plan

/// Node name of the airbag at (row, col): "airbag_<row>_<col>".
inline std::string airbagName(int row, int col) { return "airbag_" + std::to_string(row) + "_" + std::to_string(col); }

}  // namespace names
}  // namespace nursing_bed
