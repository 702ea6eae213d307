#include "nursing_bed/ros/cell_ticker.h"

#include <ros/ros.h>

#include <algorithm>
#include <memory>

namespace nursing_bed {

CellTicker& CellTicker::instance(double rate_hz) {
  static std::once_flag once;
  static std::unique_ptr<CellTicker> ticker;
  std::call_once(once, [rate_hz] { ticker.reset(new CellTicker(rate_hz)); });
  return *ticker;
}

CellTicker::CellTicker(double rate_hz) : rate_hz_(rate_hz), thread_(&CellTicker::run, this) {}

CellTicker::~CellTicker() {
  stop_ = true;
  if (thread_.joinable()) thread_.join();
}

int CellTicker::add(Tick tick) {
  std::lock_guard<std::mutex> lock(mutex_);
  ticks_.emplace_back(next_handle_, std::move(tick));
  return next_handle_++;
}

void CellTicker::remove(int handle) {
  std::lock_guard<std::mutex> lock(mutex_);  // waits for a running tick round to finish
  ticks_.erase(std::remove_if(ticks_.begin(), ticks_.end(), [handle](const auto& t) { return t.first == handle; }),
               ticks_.end());
}

void CellTicker::run() {
  // ros::Rate follows /clock under use_sim_time; before ROS time is valid, wait.
  while (!stop_ && !ros::Time::isValid()) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  ros::Rate rate(rate_hz_);
  while (!stop_ && ros::ok()) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      const ros::Time now = ros::Time::now();
      for (const auto& t : ticks_) t.second(now);
    }
    rate.sleep();
  }
}

}  // namespace nursing_bed
