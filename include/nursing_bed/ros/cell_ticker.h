// The clock threads of a process that advance every airbag in it, and one that publishes their
// states. roscpp's timer manager searches its timers linearly on every expiry, so 180 nodelet
// timers in one manager spend most of their CPU there; a few tickers keep the cost per cell
// constant. The airbags are independent plants, so they are split across one simulation thread
// per core (at most kMaxSimulationThreads): every cell filling from flat at once after CPR costs
// ~1000 integration sub-steps each, more than one core keeps in real time. Publishing has its own
// thread, so the cells' controllers stay alive while the plants catch up, and the states they
// publish say so, stamped with the simulated time they describe (doc/safety.md).
#pragma once

#include <ros/time.h>

#include <atomic>
#include <functional>
#include <memory>
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

  /// Registers an airbag: `advance` runs on one of the simulation threads (always the same one
  /// while the list does not change), `publish` on the publishing thread, both every period.
  /// Returns a handle for remove(). Thread-safe.
  int add(Tick advance, Tick publish);
  /// Unregisters; when it returns neither callback is running or will run again.
  void remove(int handle);
  double rateHz() const { return rate_hz_; }
  std::size_t simulationThreads() const { return advance_rounds_.size(); }

  static constexpr unsigned kMaxSimulationThreads = 4;

  ~CellTicker();

 private:
  struct Entry {
    int handle;
    Tick advance, publish;
  };
  explicit CellTicker(double rate_hz);
  /// Simulation thread `lane` of `lanes`: advances every entry whose index modulo `lanes` is
  /// `lane`, at `rate_hz_`, holding its round's mutex during each round.
  void advance(std::size_t lane);
  /// The publishing thread: publishes every entry twice per period, walking the list backwards
  /// (it meets the simulation threads once per round instead of following them).
  void publish();
  /// Every round's mutex, held while the list changes.
  std::vector<std::unique_lock<std::mutex>> lockAll();

  double rate_hz_;
  std::vector<std::unique_ptr<std::mutex>> advance_rounds_;  // one per simulation thread
  std::mutex publish_round_;
  std::vector<Entry> entries_;
  int next_handle_ = 0;
  std::atomic<bool> stop_{false};
  std::vector<std::thread> advance_threads_;
  std::thread publish_thread_;
};

}  // namespace nursing_bed
