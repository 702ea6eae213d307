#include "nursing_bed/ros/cell_ticker.h"

#include <ros/ros.h>

#include <algorithm>

namespace nursing_bed {

namespace {

/// Waits until ROS time is valid: ros::Rate follows /clock under use_sim_time.
void waitForRosTime(const std::atomic<bool>& stop) {
  while (!stop && !ros::Time::isValid()) std::this_thread::sleep_for(std::chrono::milliseconds(10));
}

}  // namespace

CellTicker& CellTicker::instance(double rate_hz) {
  static std::once_flag once;
  static std::unique_ptr<CellTicker> ticker;
  std::call_once(once, [rate_hz] { ticker.reset(new CellTicker(rate_hz)); });
  return *ticker;
}

CellTicker::CellTicker(double rate_hz) : rate_hz_(rate_hz) {
  const std::size_t lanes = std::clamp(std::thread::hardware_concurrency(), 1u, kMaxSimulationThreads);
  for (std::size_t lane = 0; lane < lanes; ++lane) advance_rounds_.push_back(std::make_unique<std::mutex>());
  for (std::size_t lane = 0; lane < lanes; ++lane) advance_threads_.emplace_back(&CellTicker::advance, this, lane);
  publish_thread_ = std::thread(&CellTicker::publish, this);
}

CellTicker::~CellTicker() {
  stop_ = true;
  for (std::thread& t : advance_threads_)
    if (t.joinable()) t.join();
  if (publish_thread_.joinable()) publish_thread_.join();
}

std::vector<std::unique_lock<std::mutex>> CellTicker::lockAll() {
  // Always in the same order (simulation rounds, then publishing): no two callers deadlock.
  std::vector<std::unique_lock<std::mutex>> locks;
  for (auto& round : advance_rounds_) locks.emplace_back(*round);
  locks.emplace_back(publish_round_);
  return locks;
}

int CellTicker::add(Tick advance, Tick publish) {
  const auto locks = lockAll();
  entries_.push_back(Entry{next_handle_, std::move(advance), std::move(publish)});
  return next_handle_++;
}

void CellTicker::remove(int handle) {
  const auto locks = lockAll();  // waits for running rounds to finish
  entries_.erase(
      std::remove_if(entries_.begin(), entries_.end(), [handle](const Entry& e) { return e.handle == handle; }),
      entries_.end());
}

void CellTicker::advance(std::size_t lane) {
  waitForRosTime(stop_);
  const std::size_t lanes = advance_rounds_.size();
  ros::Rate rate(rate_hz_);
  while (!stop_ && ros::ok()) {
    {
      std::lock_guard<std::mutex> lock(*advance_rounds_[lane]);
      const ros::Time now = ros::Time::now();
      for (std::size_t i = lane; i < entries_.size(); i += lanes) entries_[i].advance(now);
    }
    rate.sleep();
  }
}

void CellTicker::publish() {
  waitForRosTime(stop_);
  // Twice per period: a cell the simulation had not yet advanced when it looked publishes half a
  // period later, not a period later (each airbag's publish() keeps its own rate).
  ros::Rate rate(2.0 * rate_hz_);
  while (!stop_ && ros::ok()) {
    {
      std::lock_guard<std::mutex> lock(publish_round_);
      const ros::Time now = ros::Time::now();
      for (auto e = entries_.rbegin(); e != entries_.rend(); ++e) e->publish(now);
    }
    rate.sleep();
  }
}

}  // namespace nursing_bed
