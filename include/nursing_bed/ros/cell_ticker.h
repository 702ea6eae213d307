// One clock thread per process that advances every airbag in it. roscpp's timer manager
// searches its timers linearly on every expiry, so 180 nodelet timers in one manager spend most
// of their CPU there (measured: 57 %); a single ticker keeps the cost per cell constant.
#pragma once

#include <ros/time.h>

#include <atomic>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace nursing_bed {

class CellTicker {
 public:
  using Tick = std::function<void(const ros::Time& now)>;

  /// The process's ticker, started on first use at `rate_hz` (later callers share it; the
  /// first rate wins, so every airbag in a process should use the same rate).
  static CellTicker& instance(double rate_hz);

  /// Registers a callback; returns a handle for remove(). Thread-safe.
  int add(Tick tick);
  /// Unregisters; when it returns the callback is not running and will not run again.
  void remove(int handle);
  double rateHz() const { return rate_hz_; }

  ~CellTicker();

 private:
  explicit CellTicker(double rate_hz);
  void run();

  double rate_hz_;
  std::mutex mutex_;
  std::vector<std::pair<int, Tick>> ticks_;
  int next_handle_ = 0;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

}  // namespace nursing_bed
