#include "nursing_bed/ros/bed_topics.h"

#include <algorithm>

#include "nursing_bed/ros/names.h"

namespace nursing_bed {

BedTopics& BedTopics::instance() {
  // Never destroyed: airbags may unregister during static destruction at exit.
  static BedTopics* topics = new BedTopics();
  return *topics;
}

BedTopics::BedTopics() : nh_(std::make_unique<ros::NodeHandle>()) {
  nh_->setCallbackQueue(&queue_);
  loads_sub_ = nh_->subscribe(names::kCellLoads, 2, &BedTopics::onLoads, this, ros::TransportHints().tcpNoDelay());
  heartbeat_sub_ = nh_->subscribe(names::kBedHeartbeat, 2, &BedTopics::onHeartbeat, this);
  spinner_ = std::make_unique<ros::AsyncSpinner>(1, &queue_);
  spinner_->start();
}

BedTopics::~BedTopics() {
  if (spinner_) spinner_->stop();
}

int BedTopics::add(Handlers handlers) {
  std::lock_guard<std::mutex> lock(mutex_);
  entries_.emplace_back(next_handle_, std::move(handlers));
  return next_handle_++;
}

void BedTopics::remove(int handle) {
  std::lock_guard<std::mutex> lock(mutex_);
  entries_.erase(
      std::remove_if(entries_.begin(), entries_.end(), [handle](const auto& e) { return e.first == handle; }),
      entries_.end());
}

void BedTopics::onLoads(const std_msgs::Float64MultiArray::ConstPtr& msg) {
  std::lock_guard<std::mutex> lock(mutex_);
  for (const auto& e : entries_) e.second.loads(*msg);
}

void BedTopics::onHeartbeat(const ros::MessageEvent<const std_msgs::Empty>& event) {
  const std::string& publisher = event.getPublisherName();
  std::lock_guard<std::mutex> lock(mutex_);
  for (const auto& e : entries_) e.second.heartbeat(publisher);
}

}  // namespace nursing_bed
