// The `modbus_tcp` cell hardware: a valve terminal with analogue pressure inputs on Modbus TCP
// (libmodbus). One connection per terminal, shared by its cells; a bus thread per terminal
// runs one cycle every cycle_s: one batched read of every input register in use (one request
// per run of consecutive addresses) and one batched write of the outputs; on/off valves are
// pulse-width modulated over the control period at the cycle's resolution. A request that
// fails transiently (timeout, bad or mismatched reply: transientModbusError) cuts the cycle
// short; the next cycle flushes any late reply and tries again, the readings keep their stamps.
// The link goes down when no cycle has completed for link_loss_after_s, or at once on any
// other error (the connection closed, reset or refused; a request the terminal refuses): the
// cells see LinkState::kDown, nothing is written while it is down, and the thread reconnects
// every reconnect_interval_s and resumes by itself.
#pragma once

#include <atomic>
#include <chrono>
#include <limits>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

#include "nursing_bed/core/hardware/bus_sample_ring.h"
#include "nursing_bed/core/hardware/cell_hardware.h"
#include "nursing_bed/core/hardware/register_map.h"
#include "nursing_bed/core/hardware/thread_priority.h"

struct _modbus;

namespace nursing_bed {

/// Consecutive addresses handled by one request.
struct AddressRun {
  int first = 0;
  int count = 0;
};

/// Runs of consecutive addresses covering `addresses` (sorted, unique), each at most `max_count` long.
std::vector<AddressRun> addressRuns(std::vector<int> addresses, int max_count);

/// Pulse-width modulation of one on/off valve over frames of `steps` bus cycles: on for the
/// first k cycles of a frame, k = the duty commanded over the previous frame (sampled every
/// cycle) times the frame, the rounding carried to the next. The valve's open time equals the
/// commanded duty's integral, one frame later, whatever the phase of the commands.
class PwmChannel {
 public:
  /// The valve state for this cycle; `phase` counts cycles within the frame (0 starts one).
  bool next(double duty, int phase, int steps);

 private:
  double demand_ = 0.0;  ///< commanded duty summed over the cycles of this frame
  double carry_ = 0.0;
  int on_steps_ = 0;
};

/// True for a libmodbus errno after which the connection is still usable and the same request
/// may succeed next cycle: ETIMEDOUT (no reply within response_timeout_s), a reply that does not
/// match the request or is malformed (EMBBADDATA: transaction id, function, length or count;
/// EMBBADEXC, EMBUNKEXC, EMBBADCRC, EMBBADSLAVE), and the exceptions a terminal or gateway
/// sends to ask for a retry (EMBXSBUSY, EMBXGTAR). False for anything else: the connection
/// gone (ECONNRESET, ECONNREFUSED, EPIPE, EBADF, ENOTCONN, ...) or a request refused for good
/// (illegal function, address or value, server failure).
bool transientModbusError(int error_number);

struct TerminalStats {
  long cycles = 0;            ///< completed bus cycles
  long read_requests = 0;     ///< Modbus read requests sent
  long write_requests = 0;    ///< Modbus write requests sent
  long connects = 0;          ///< successful connections
  long link_losses = 0;       ///< times the link went down
  long failed_exchanges = 0;  ///< cycles cut short by a transient failure and retried
};

// size: one bus thread owns the link, the register image and the valves' on-time record
class ModbusTerminal {
 public:
  /// Starts the bus thread, which connects in the background.
  ModbusTerminal(const TerminalMap& map, double pwm_period_s);
  ~ModbusTerminal();
  ModbusTerminal(const ModbusTerminal&) = delete;
  ModbusTerminal& operator=(const ModbusTerminal&) = delete;

  /// The process's terminal at this map's endpoint, started on first use and shared.
  static std::shared_ptr<ModbusTerminal> shared(const TerminalMap& map, double pwm_period_s);

  void command(std::size_t slot, const ValveOpenings& valves);
  /// Readings of the cell in `slot`, stamped on the caller's clock (`now_s` is now on it).
  CellReadings readings(std::size_t slot, double now_s) const;
  bool linkUp() const;
  TerminalStats stats() const;
  /// How the bus thread is scheduled (scheduleRealtime's answer for the map's realtime_priority).
  const ThreadScheduling& scheduling() const { return scheduling_; }
  const TerminalMap& map() const { return map_; }

 private:
  using Clock = std::chrono::steady_clock;
  void run();
  bool connect();
  bool exchange();
  bool readInputs();
  bool writeOutputs();
  void fillOutputs();
  /// The middle of a request's wait: when the terminal most likely handled it.
  static Clock::time_point midpoint(Clock::time_point sent, Clock::time_point replied);
  /// The terminal handled a request at t: its watchdog restarts there (past its trip, the
  /// outputs were shut from the trip). Called with mutex_ held.
  void requestHandled(Clock::time_point t);
  /// One write run, sent at `sent`, was answered now: its outputs act from the request's
  /// middle on (the others keep what the terminal held). Takes mutex_.
  template <typename Word>
  void outputsApplied(const AddressRun& run, const std::vector<Word>& written, std::vector<Word>* applied,
                      Clock::time_point sent);
  /// Every slot's record run to t, then the outputs last written (or shut) held.
  void advanceDriven(Clock::time_point t, bool shut);
  /// Hands the cell in `slot` the outputs' on-time since its previous read as a mean opening
  /// over its own clock's interval (`now_s` less the previous read's), up or down.
  void takeDriven(std::size_t slot, double now_s, CellReadings* r) const;
  /// Until when the outputs hold: the terminal's watchdog shuts them after that.
  Clock::time_point outputsHeldUntil() const;
  /// A request failed with `error_number` (errno): retry next cycle or take the link down.
  /// Returns false, for the caller to return.
  bool requestFailed(int error_number, const char* what, const AddressRun& run);
  /// A transient failure: counted, the link kept, late replies flushed before the next cycle.
  void retryNextCycle(const std::string& why);
  /// Discards replies that came after their request had timed out.
  void flushLateReplies();
  void dropLink(const std::string& why);
  double value(const AnalogInput& in) const;

  const TerminalMap map_;
  const int pwm_steps_;
  _modbus* ctx_ = nullptr;
  std::vector<AddressRun> input_runs_, coil_runs_, holding_runs_;
  // Bus thread only:
  Clock::time_point watchdog_fed_{};    // the terminal's last handled request (guarded by mutex_)
  Clock::time_point last_exchange_;     // the last completed cycle, or the connection
  bool flush_pending_ = false;          // a request failed: flush before the next one
  mutable std::mutex mutex_;            // guards everything below
  std::vector<std::uint16_t> inputs_;   // by address
  std::vector<std::uint8_t> coils_;     // by address: the outputs to write
  std::vector<std::uint16_t> holding_;  // by address
  // By address, the outputs the terminal holds: a cycle's write runs land one by one, and one
  // that failed after another succeeded left the terminal with part of the cycle's outputs.
  std::vector<std::uint8_t> applied_coils_;
  std::vector<std::uint16_t> applied_holding_;
  std::vector<ValveOpenings> commands_;  // by slot
  std::vector<PwmChannel> pwm_;          // 2 per slot: inlet, vent
  /// What the outputs drove, per slot: the openings written last, since when, and their
  /// time integral since the slot's last readings() (mutable: readings() hands it out).
  struct Driven {
    double opening[2] = {0.0, 0.0};
    double integral_s[2] = {0.0, 0.0};       ///< on-time not yet handed out [s]
    double total_s[2] = {0.0, 0.0};          ///< on-time since the record started, up to `since` [s]
    double total_at_from_s[2] = {0.0, 0.0};  ///< total_s at the last read [s]
    Clock::time_point since, from;
    double from_caller_s = std::numeric_limits<double>::quiet_NaN();  ///< the last read's now_s
    bool started = false;
  };
  /// The interval a read's mean is over: the caller's since its previous read, else (a clock
  /// that did not advance, or the first read) the real time since then.
  static double callerSpan(const Driven& d, double now_s, Clock::time_point t);
  mutable std::vector<Driven> driven_;
  std::vector<BusSampleRing> cycles_;  ///< by slot: each bus cycle's pressure and on-time totals
  /// Each slot's cycle read at t (the just-read inputs) into cycles_. Called with mutex_ held.
  void keepCycle(Clock::time_point t);
  Clock::time_point last_read_;
  bool have_read_ = false;
  bool up_ = false;
  std::string error_ = "not connected yet";
  long cycle_index_ = 0;
  TerminalStats stats_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
  ThreadScheduling scheduling_;
};

class ModbusTcpCellHardware : public CellHardware {
 public:
  /// Loads the register map (HardwareConfig::register_map_path, checked against bed_cells)
  /// and joins the terminal that serves the cell.
  void configure(const HardwareConfig& config) override;
  HardwareCapabilities capabilities() const override;
  CellReadings read(double now_s) override;
  void write(const ValveOpenings& valves, double now_s) override;
  std::string describe() const override;
  std::string warning() const override;

 private:
  std::shared_ptr<ModbusTerminal> terminal_;
  std::size_t slot_ = 0;
  CellRegisters registers_;
};

}  // namespace nursing_bed
