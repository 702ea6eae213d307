// One clock thread per process that advances every airbag in it, and a second one that publishes
// their states. roscpp's timer manager searches its timers linearly on every expiry, so 180
// nodelet timers in one manager spend most of their CPU there; a single ticker
// keeps the cost per cell constant. Publishing has its own thread because simulating the plants
// can take longer than a period for a moment (every cell filling from flat at once after CPR
// costs ~1000 integration sub-steps each): the cells' controllers stay alive meanwhile, and the
// states they publish say so, stamped with the simulated time they describe (doc/safety.md).
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

  /// Registers an airbag: `advance` runs on the simulation thread, `publish` on the publishing
  /// thread, both every period. Returns a handle for remove(). Thread-safe.
  int add(Tick advance, Tick publish);
  /// Unregisters; when it returns neither callback is running or will run again.
  void remove(int handle);
  double rateHz() const { return rate_hz_; }

  ~CellTicker();

 private:
  struct Entry {
    int handle;
    Tick advance, publish;
  };
  explicit CellTicker(double rate_hz);
  /// Calls `which` of every entry at `rate_hz_`, holding `round` during each round; `reverse`
  /// walks the entries backwards (the publishing thread: it meets the simulation thread once
  /// per round instead of following it from cell to cell).
  void run(Tick Entry::*which, std::mutex* round, bool reverse);

  double rate_hz_;
  std::mutex advance_round_, publish_round_;  // the list changes only with both held
  std::vector<Entry> entries_;
  int next_handle_ = 0;
  std::atomic<bool> stop_{false};
  std::thread advance_thread_, publish_thread_;
};

}  // namespace nursing_bed
