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

CellTicker::CellTicker(double rate_hz)
    : rate_hz_(rate_hz),
      advance_thread_(&CellTicker::run, this, &Entry::advance, &advance_round_, false),
      publish_thread_(&CellTicker::run, this, &Entry::publish, &publish_round_, true) {}

CellTicker::~CellTicker() {
  stop_ = true;
  if (advance_thread_.joinable()) advance_thread_.join();
  if (publish_thread_.joinable()) publish_thread_.join();
}

int CellTicker::add(Tick advance, Tick publish) {
  std::scoped_lock lock(advance_round_, publish_round_);
  entries_.push_back(Entry{next_handle_, std::move(advance), std::move(publish)});
  return next_handle_++;
}

void CellTicker::remove(int handle) {
  std::scoped_lock lock(advance_round_, publish_round_);  // waits for running rounds to finish
  entries_.erase(
      std::remove_if(entries_.begin(), entries_.end(), [handle](const Entry& e) { return e.handle == handle; }),
      entries_.end());
}

void CellTicker::run(Tick Entry::*which, std::mutex* round, bool reverse) {
  // ros::Rate follows /clock under use_sim_time; before ROS time is valid, wait.
  while (!stop_ && !ros::Time::isValid()) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  // The publishing thread looks twice per period: a cell the simulation had not yet advanced
  // when it looked publishes half a period later, not a period later (each airbag's publish()
  // keeps its own rate).
  ros::Rate rate(reverse ? 2.0 * rate_hz_ : rate_hz_);
  while (!stop_ && ros::ok()) {
    {
      std::lock_guard<std::mutex> lock(*round);
      const ros::Time now = ros::Time::now();
      if (reverse) {
        for (auto e = entries_.rbegin(); e != entries_.rend(); ++e) ((*e).*which)(now);
      } else {
        for (const Entry& e : entries_) (e.*which)(now);
      }
    }
    rate.sleep();
  }
}

}  // namespace nursing_bed
