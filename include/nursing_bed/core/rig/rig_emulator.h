// A rig emulator: Modbus TCP servers (one per terminal of a register map, on 127.0.0.1 only)
// backed by simulated cells, serving the same register map the modbus_tcp hardware reads. Its
// cells carry the rig's imperfections (ADC quantisation, valve dead time, optional hidden
// effects); their true state is available for tests (the ROS node publishes it on a separate
// topic). ROS-free: the rig_emulator node and the unit tests wrap it.
#pragma once

#include <atomic>
#include <chrono>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>
#include <vector>

#include "nursing_bed/core/hardware/register_map.h"
#include "nursing_bed/core/hardware/simulated_cell_hardware.h"
#include "nursing_bed/core/hardware/thread_priority.h"
#include "nursing_bed/core/io/status.h"
#include "nursing_bed/core/rig/rig_faults.h"

struct _modbus;
struct _modbus_mapping_t;

namespace nursing_bed {

/// One terminal's Modbus TCP server (several clients at once) over a register image.
/// Size: 19 members are one server's socket, clients, register image, coil timing, injected
/// faults and thread; splitting them would share the one lock the replies are made under
/// across classes.
class RigTerminalServer {
 public:
  /// Throws std::runtime_error when the host is not a loopback address or the port is taken.
  /// Like a real terminal's fieldbus watchdog, it shuts every output when no request has been
  /// answered for the map's watchdog_s (real time).
  explicit RigTerminalServer(const TerminalMap& map);
  ~RigTerminalServer();
  RigTerminalServer(const RigTerminalServer&) = delete;
  RigTerminalServer& operator=(const RigTerminalServer&) = delete;

  /// Runs `f(mapping)` under the lock the server replies under.
  template <typename F>
  void withRegisters(F f) {
    std::lock_guard<std::mutex> lock(mutex_);
    f(mapping_);
  }
  /// Each coil's on-time since the last call as a fraction of `span_s`, the simulated time
  /// that will pass it (a solenoid passes gas while its coil is energised, not at the
  /// instants the simulation samples it; sampled, a PWM train of one bus cycle aliases against
  /// the simulation step). On-time beyond the span (a late wake runs fewer periods than the
  /// wall time it took) is carried into the next call: the cell passes gas for all of it.
  /// Thread-safe.
  std::vector<double> takeCoilDuty(double span_s);
  /// A coil's on-time since the server started [s] (what a client's record of the outputs it
  /// drove is checked against). Thread-safe.
  double coilOnSeconds(int address);
  long requestsServed() const { return requests_; }
  /// How the server thread is scheduled (the map's realtime_priority; scheduleRealtime).
  const ThreadScheduling& scheduling() const { return scheduling_; }
  /// Fault injection: the next `requests` requests are read and never answered, the
  /// connection kept (a silent terminal; 0: answer again).
  void leaveUnanswered(long requests) { unanswered_ = requests; }
  /// Fault injection: the next `requests` requests are answered `delay_s` late (the server
  /// stalls meanwhile, as an overloaded terminal would).
  void answerLate(long requests, double delay_s);
  /// Fault injection: from now on each request goes unanswered with probability
  /// `drop_probability`, else is answered `delay_s` late with probability `delay_probability`,
  /// drawn from a generator seeded with `seed` (0 and 0: every request answered at once).
  void setReplyFaults(double drop_probability, double delay_probability, double delay_s, std::uint32_t seed);
  /// Fault injection: no request is answered for `seconds` (a terminal restarting).
  void silenceFor(double seconds);
  const TerminalMap& map() const { return map_; }

 private:
  void run();
  void serveClient(int fd);
  void checkWatchdog();
  /// Applies the injected faults to the request just read: true when it goes unanswered.
  bool withholdReply();
  /// Adds each energised coil's time since the last account, up to the watchdog's trip, and
  /// shuts every output once it has tripped (called under the lock).
  void accountCoils();
  /// When the watchdog trips (or tripped): watchdog_s after the last answered request.
  std::chrono::steady_clock::time_point watchdogTrip() const;

  const TerminalMap map_;
  std::chrono::steady_clock::time_point last_answer_;  ///< the watchdog runs from here
  _modbus* ctx_ = nullptr;
  _modbus_mapping_t* mapping_ = nullptr;
  int listen_fd_ = -1;
  std::vector<int> clients_;
  std::vector<double> coil_on_s_;        ///< per coil, since the last take and carried
  std::vector<double> coil_total_on_s_;  ///< per coil, since the start
  std::chrono::steady_clock::time_point coils_since_;
  std::mutex mutex_;
  std::atomic<long> requests_{0};
  std::atomic<long> unanswered_{0}, late_{0};
  std::atomic<double> late_delay_s_{0.0};
  /// Injected reply faults (setReplyFaults, silenceFor), drawn on the server's thread.
  struct ReplyFaults {
    double drop_probability = 0.0, delay_probability = 0.0, delay_s = 0.0;
    std::chrono::steady_clock::time_point silent_until{};
    std::mt19937 rng;
  };
  ReplyFaults reply_faults_;
  std::mutex reply_faults_mutex_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
  ThreadScheduling scheduling_;
};

struct RigEmulatorOptions {
  HardwareConfig cell;          ///< plant parameters, hidden effects, noise of every cell
  RigImperfections rig;         ///< ADC step, valve dead time (height sensor: from the map)
  double period_s = 0.005;      ///< simulation step [s]
  double max_catch_up_s = 0.5;  ///< a lag up to this is run through, beyond it given up [s]
  /// SCHED_FIFO priority of the simulation thread (1-99; 0: the normal scheduler). A rig's
  /// physics does not pause: a simulation starved for tens of ms serves the same pressure
  /// while its valves (on the servers' real-time threads) pass gas, which no real sensor does.
  int realtime_priority = 0;
  std::uint32_t fault_seed = 1;  ///< draws of the injected faults (random cells, dropped replies)
};

/// What a test may know and a controller may not.
struct CellTruth {
  std::uint32_t cell_id = 0;
  double height_m = 0.0, gauge_pressure_pa = 0.0, gas_mass_kg = 0.0, load_n = 0.0;
  double temperature_k = 0.0;                      ///< the gas's
  double inlet_opening = 0.0, vent_opening = 0.0;  ///< valves acting now
  double inflow_kg_s = 0.0, vent_flow_kg_s = 0.0;  ///< at the end of the last step
};

class RigEmulator {
 public:
  /// Opens a server per terminal and starts the simulation in real time.
  RigEmulator(const RegisterMap& map, const RigEmulatorOptions& options);
  ~RigEmulator();

  /// Sets the load of a cell (from the patient simulator) [N]; unknown ids are ignored.
  void setLoad(std::uint32_t cell_id, double load_n);
  /// Sets every cell's load from a vector by cell id [N] under one lock (the simulation thread
  /// waits for it); ids beyond the cells, and loads not finite or negative, are ignored.
  void setLoads(const std::vector<double>& load_n_by_id);
  /// The cells' true state; with `at`, also the instant it describes (the wall-clock tick the
  /// simulation has run to, taken under the same lock: the state and its time belong together).
  std::vector<CellTruth> truth(std::chrono::steady_clock::time_point* at = nullptr) const;
  /// Times the simulation fell more than max_catch_up_s behind the wall clock and gave that
  /// time up (real time not kept), and the time given up [s].
  long overruns() const { return overruns_; }
  double lostSeconds() const { return lost_s_; }
  /// Simulation periods run per wake-up on average (1: the thread kept the pace).
  double periodsPerWake() const { return wakes_ > 0 ? static_cast<double>(steps_) / wakes_ : 0.0; }
  /// The most periods one wake-up had to run (1: never late by a period) since the start.
  long mostPeriodsPerWake() const { return most_periods_; }
  /// How the simulation thread is scheduled (options' realtime_priority; scheduleRealtime).
  const ThreadScheduling& scheduling() const { return scheduling_; }
  const std::vector<std::unique_ptr<RigTerminalServer>>& servers() const { return servers_; }
  /// Injects a fault (test and bench use only): success naming the cells it applies to, or an
  /// error naming what is wrong in `request` (nothing changes then).
  Status inject(const RigFaultRequest& request, std::string* applied = nullptr);
  /// The faults acting on a cell (none for an id not served).
  CellFaults faults(std::uint32_t cell_id) const;

 private:
  struct Cell {
    std::size_t terminal = 0;
    CellRegisters registers;
    std::unique_ptr<SimulatedCellHardware> hardware;
    CellFaults faults;  ///< injected
    /// A restart's emptying, due halfway through its silence (the link is down by then).
    std::optional<std::chrono::steady_clock::time_point> empty_at;
  };
  std::vector<std::uint32_t> servedIds() const;
  /// The terminals' part of a checked request (replies, silence) for the cells `ids`.
  void injectIntoTerminals(RigFaultKind kind, const RigFaultRequest& request, const std::vector<std::uint32_t>& ids);
  void run();
  void applyOutputs(RigTerminalServer& server, const std::vector<double>& coil_duty, Cell& cell);
  void publishInputs(RigTerminalServer& server, const Cell& cell);
  /// Runs `periods` simulation periods with the valves the terminals' outputs held since the
  /// last call, up to the wall-clock tick `until`.
  void stepAll(int periods, std::chrono::steady_clock::time_point until);

  RigEmulatorOptions options_;
  std::vector<std::unique_ptr<RigTerminalServer>> servers_;
  std::vector<Cell> cells_;
  mutable std::mutex mutex_;                               // guards the cells' simulation and simulated_until_
  std::chrono::steady_clock::time_point simulated_until_;  ///< the tick the cells' state describes
  std::atomic<long> overruns_{0};
  std::atomic<double> lost_s_{0.0};
  std::atomic<long> steps_{0}, wakes_{0}, most_periods_{0};
  std::atomic<bool> stop_{false};
  std::thread thread_;
  ThreadScheduling scheduling_;
  std::mt19937 fault_rng_;  ///< random cells of injected faults (fault_seed)
  long injections_ = 0;     ///< faults injected, for the terminals' seeds
};

}  // namespace nursing_bed
