// The rig emulator node: Modbus TCP valve terminals on 127.0.0.1 backed by simulated cells
// (core RigEmulator), serving the register map the modbus_tcp hardware reads, so the whole
// real-bed path runs here. Its cells take their loads from /airbag_loads (the patient
// simulator) and publish their ground truth on ~truth, for tests only. Faults are injected
// (tests and benches only) from ~faults at start and by ~inject_fault. Interface: doc/real_bed.md.
#pragma once

#include <ros/ros.h>
#include <std_msgs/Float64MultiArray.h>

#include <memory>
#include <string>

#include "nursing_bed/InjectRigFault.h"
#include "nursing_bed/RigTruth.h"
#include "nursing_bed/core/io/status.h"
#include "nursing_bed/core/rig/rig_emulator.h"

namespace nursing_bed {

struct RigEmulatorNodeParams {
  std::string register_map;                      ///< ~register_map: the map YAML (required)
  int bed_cells = 0;                             ///< ~bed_cells: cells the map must serve (0: not checked)
  std::string defaults_ns = "/airbag_defaults";  ///< ~defaults_ns: cell/ and sensors/ of the airbags
  double period_s = 0.005;                       ///< ~period_s: simulation step [s]
  double adc_step_pa = 12.2;                     ///< ~adc_step_pa: pressure ADC step (12 bits over 50 kPa) [Pa]
  double valve_dead_time_s = 0.01;               ///< ~valve_dead_time_s: command to valve [s]
  double pressure_noise_pa = 10.0;               ///< ~pressure_noise_pa: sd of the pressure sensors [Pa]
  std::string effects;                           ///< ~effects: hidden in every cell ("NAME[:p=v,...][;...]")
  double load_n = 0.6;                           ///< ~load_n: load until /airbag_loads says otherwise [N]
  double initial_height_m = 0.0;                 ///< ~initial_height_m: cells start at rest at this height [m]
  double truth_rate_hz = 50.0;                   ///< ~truth_rate_hz: rate of ~truth
  int simulation_realtime_priority =
      20;  ///< ~simulation_realtime_priority: SCHED_FIFO priority of the simulation thread (0: normal)
  std::uint32_t noise_seed = 1;  ///< ~noise_seed
  std::uint32_t fault_seed = 1;  ///< ~fault_seed: draws of injected faults (random cells, dropped replies)

  /// Success, or every problem found.
  Status validate() const;
};

class RigEmulatorNode {
 public:
  /// Throws std::runtime_error with a clear message (bad map, port taken, bad parameter).
  RigEmulatorNode(ros::NodeHandle nh, ros::NodeHandle private_nh);
  static RigEmulatorNodeParams loadParams(const ros::NodeHandle& private_nh);

 private:
  void onCellLoads(const std_msgs::Float64MultiArray::ConstPtr& msg);
  void publishTruth(const ros::TimerEvent&);
  bool onInjectFault(InjectRigFault::Request& req, InjectRigFault::Response& res);
  /// Injects each fault of ~faults (a list of dicts with the service's fields); throws
  /// std::runtime_error naming the entry and what is wrong.
  void injectStartFaults(const ros::NodeHandle& private_nh);

  RigEmulatorNodeParams params_;
  long reported_overruns_ = 0;
  std::unique_ptr<RigEmulator> emulator_;
  ros::Subscriber loads_sub_;
  ros::Publisher truth_pub_;
  ros::Timer truth_timer_;
  ros::ServiceServer fault_srv_;
};

/// One entry of ~faults (a dict with InjectRigFault's request fields) as a request; false with
/// `*error` naming the key that is wrong.
bool rigFaultFromXmlRpc(XmlRpc::XmlRpcValue& entry, RigFaultRequest* request, std::string* error);

}  // namespace nursing_bed
