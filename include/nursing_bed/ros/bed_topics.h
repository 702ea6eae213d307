// One subscription per process to the bed-wide topics every airbag listens to (/airbag_loads,
// the bed manager's heartbeat), fanned out to the airbags of the process. With one subscription
// per airbag nodelet, every message would become 180 callbacks, each queued and woken on a worker
// thread (10800 callbacks/s at 50 Hz of loads and 10 Hz of heartbeats), and their thread
// switches would cost a large share of the cells' process (doc/safety.md). Handlers run on this class's
// own spinner thread, so a busy nodelet worker never delays them.
#pragma once

#include <ros/callback_queue.h>
#include <ros/ros.h>
#include <ros/spinner.h>
#include <std_msgs/Empty.h>
#include <std_msgs/Float64MultiArray.h>

#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

namespace nursing_bed {

class BedTopics {
 public:
  struct Handlers {
    std::function<void(const std_msgs::Float64MultiArray&)> loads;  ///< every /airbag_loads message
    /// every heartbeat on the bed manager's topic, with its publisher's node name
    std::function<void(const std::string&)> heartbeat;
  };

  /// The process's fan-out, subscribing on first use.
  static BedTopics& instance();

  /// Registers an airbag's handlers; returns a handle for remove(). Thread-safe.
  int add(Handlers handlers);
  /// Unregisters; when it returns, the handlers are not running and will not run again.
  void remove(int handle);

  ~BedTopics();

 private:
  BedTopics();
  void onLoads(const std_msgs::Float64MultiArray::ConstPtr& msg);
  void onHeartbeat(const ros::MessageEvent<const std_msgs::Empty>& event);

  std::mutex mutex_;  // held while handlers run and while the list changes
  std::vector<std::pair<int, Handlers>> entries_;
  int next_handle_ = 0;
  ros::CallbackQueue queue_;
  std::unique_ptr<ros::NodeHandle> nh_;
  ros::Subscriber loads_sub_, heartbeat_sub_;
  std::unique_ptr<ros::AsyncSpinner> spinner_;
};

}  // namespace nursing_bed
