#include "nursing_bed/core/hardware/modbus_tcp_hardware.h"

#include <modbus/modbus.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <map>
#include <sstream>

#include "nursing_bed/core/hardware/thread_priority.h"

namespace nursing_bed {
namespace {

int maxAddress(const std::vector<int>& addresses) {
  return addresses.empty() ? -1 : *std::max_element(addresses.begin(), addresses.end());
}

}  // namespace

bool transientModbusError(int error_number) {
  switch (error_number) {
    case ETIMEDOUT:   // no reply within response_timeout_s
    case EMBBADDATA:  // a reply that is not this request's (a late one) or malformed
    case EMBBADEXC:
    case EMBUNKEXC:
    case EMBBADCRC:
    case EMBBADSLAVE:
    case EMBXSBUSY:  // the terminal asks for a retry
    case EMBXGTAR:   // a gateway's target did not answer: a timeout behind the gateway
      return true;
    default: return false;
  }
}

std::vector<AddressRun> addressRuns(std::vector<int> addresses, int max_count) {
  std::sort(addresses.begin(), addresses.end());
  addresses.erase(std::unique(addresses.begin(), addresses.end()), addresses.end());
  std::vector<AddressRun> runs;
  for (int a : addresses) {
    if (!runs.empty() && runs.back().first + runs.back().count == a && runs.back().count < max_count) {
      ++runs.back().count;
    } else {
      runs.push_back({a, 1});
    }
  }
  return runs;
}

bool PwmChannel::next(double duty, int phase, int steps) {
  if (phase == 0) {
    const double target = demand_ + carry_;
    on_steps_ = static_cast<int>(std::clamp(std::round(target), 0.0, static_cast<double>(steps)));
    carry_ = std::clamp(target - on_steps_, -1.0, 1.0);
    demand_ = 0.0;
  }
  demand_ += std::clamp(duty, 0.0, 1.0);
  return phase < on_steps_;
}

ModbusTerminal::ModbusTerminal(const TerminalMap& map, double pwm_period_s)
    : map_(map), pwm_steps_(std::max(1, static_cast<int>(std::lround(pwm_period_s / map.cycle_s)))) {
  std::vector<int> inputs, coils, holding;
  if (map_.supply_pressure_pa.present()) inputs.push_back(map_.supply_pressure_pa.address);
  for (const CellRegisters& c : map_.cells) {
    for (const AnalogInput* in : {&c.pressure_pa, &c.height_m, &c.inflow_kg_s})
      if (in->present()) inputs.push_back(in->address);
    for (const ValveOutput* v : {&c.inlet, &c.vent})
      (v->kind == ValveOutput::kCoil ? coils : holding).push_back(v->address);
  }
  inputs_.assign(maxAddress(inputs) + 1, 0);
  coils_.assign(maxAddress(coils) + 1, 0);
  holding_.assign(maxAddress(holding) + 1, 0);
  applied_coils_ = coils_;
  applied_holding_ = holding_;
  input_runs_ = addressRuns(inputs, MODBUS_MAX_READ_REGISTERS);
  coil_runs_ = addressRuns(coils, MODBUS_MAX_WRITE_BITS);
  holding_runs_ = addressRuns(holding, MODBUS_MAX_WRITE_REGISTERS);
  commands_.assign(map_.cells.size(), ValveOpenings{});
  pwm_.assign(2 * map_.cells.size(), PwmChannel{});
  driven_.assign(map_.cells.size(), Driven{});
  // A second of cycles: more than the longest period a cell integrates (AirbagCell: 0.5 s).
  cycles_.assign(map_.cells.size(), BusSampleRing(static_cast<std::size_t>(std::ceil(1.0 / map_.cycle_s)) + 1));
  thread_ = std::thread(&ModbusTerminal::run, this);
  scheduling_ = scheduleRealtime(thread_, map_.realtime_priority);
}

ModbusTerminal::~ModbusTerminal() {
  stop_ = true;
  if (thread_.joinable()) thread_.join();
  if (ctx_) {
    modbus_close(ctx_);
    modbus_free(ctx_);
  }
}

std::shared_ptr<ModbusTerminal> ModbusTerminal::shared(const TerminalMap& map, double pwm_period_s) {
  static std::mutex registry_mutex;
  static std::map<std::string, std::weak_ptr<ModbusTerminal>> registry;
  std::lock_guard<std::mutex> lock(registry_mutex);
  std::shared_ptr<ModbusTerminal> terminal = registry[map.endpoint()].lock();
  if (!terminal) {
    terminal = std::make_shared<ModbusTerminal>(map, pwm_period_s);
    registry[map.endpoint()] = terminal;
  }
  return terminal;
}

void ModbusTerminal::command(std::size_t slot, const ValveOpenings& valves) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (up_) commands_.at(slot) = valves;  // while down the valves stay shut on reconnection
}

double ModbusTerminal::value(const AnalogInput& in) const {
  return in.present() ? in.toValue(inputs_[in.address]) : std::numeric_limits<double>::quiet_NaN();
}

CellReadings ModbusTerminal::readings(std::size_t slot, double now_s) const {
  std::lock_guard<std::mutex> lock(mutex_);
  CellReadings r;
  if (!up_ || !have_read_) {
    r.link = LinkState::kDown;
    r.link_error = map_.name + " (" + map_.endpoint() + "): " + error_;
    takeDriven(slot, now_s, &r);  // the outputs held until the terminal's watchdog
    return r;
  }
  takeDriven(slot, now_s, &r);
  const double age_s = std::chrono::duration<double>(Clock::now() - last_read_).count();
  if (age_s > map_.stale_after_s) return r;  // link up but nothing fresh: every reading NaN
  const double stamp = now_s - age_s;
  const CellRegisters& c = map_.cells.at(slot);
  r.gauge_pressure_pa = {value(c.pressure_pa), stamp};
  if (c.height_m.present()) r.height_m = {value(c.height_m), stamp};
  if (c.inflow_kg_s.present()) r.inflow_kg_s = {value(c.inflow_kg_s), stamp};
  if (map_.supply_pressure_pa.present()) r.supply_pressure_pa = {value(map_.supply_pressure_pa), stamp};
  return r;
}

void ModbusTerminal::takeDriven(std::size_t slot, double now_s, CellReadings* r) const {
  // The valves' on-time since the last call (what the PWM pulses passed, not the duty) as a
  // mean over the caller's interval since then, which is the period its observer integrates
  // the mean over: so every pulse is counted once by construction, whatever time the read
  // waited for the lock (over the real spans, such a read's span runs long by the wait and the
  // next one short). On-time beyond a full opening of the interval is carried to the next read.
  // Over a lost link the terminal holds the outputs last written until its watchdog.
  Driven& d = driven_.at(slot);
  if (!d.started) return;
  const Clock::time_point t = Clock::now();
  const double tail_s = std::max(0.0, std::chrono::duration<double>(std::min(t, outputsHeldUntil()) - d.since).count());
  for (int k = 0; k < 2; ++k) {
    d.integral_s[k] += d.opening[k] * tail_s;
    d.total_s[k] += d.opening[k] * tail_s;
  }
  d.since = t;
  const double span_s = callerSpan(d, now_s, t);
  r->bus_samples = cycles_.at(slot).between(d.from, d.total_at_from_s[0], d.total_at_from_s[1], t, now_s);
  d.from = t;
  d.from_caller_s = now_s;
  std::copy_n(d.total_s, 2, d.total_at_from_s);
  if (!(span_s > 1e-4)) return;  // nothing to average over: kept for the next read
  StampedReading* out[2] = {&r->inlet_driven, &r->vent_driven};
  for (int k = 0; k < 2; ++k) {
    const double mean = std::min(1.0, d.integral_s[k] / span_s);
    *out[k] = {mean, now_s};
    d.integral_s[k] -= mean * span_s;
  }
}

double ModbusTerminal::callerSpan(const Driven& d, double now_s, Clock::time_point t) {
  // A caller whose clock does not advance between reads (a test reading at 0): the real span.
  const double caller_s = now_s - d.from_caller_s;
  return std::isfinite(caller_s) && caller_s > 0.0 ? caller_s : std::chrono::duration<double>(t - d.from).count();
}

ModbusTerminal::Clock::time_point ModbusTerminal::outputsHeldUntil() const {
  return watchdog_fed_ + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(map_.watchdog_s));
}

bool ModbusTerminal::linkUp() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return up_;
}

TerminalStats ModbusTerminal::stats() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return stats_;
}

void ModbusTerminal::run() {
  Clock::time_point next = Clock::now();
  Clock::time_point next_connect = next;
  const auto cycle = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(map_.cycle_s));
  const auto retry =
      std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(map_.reconnect_interval_s));
  while (!stop_) {
    const bool up = linkUp();
    if (up) {
      exchange();
    } else if (Clock::now() >= next_connect) {
      connect();
      next_connect = Clock::now() + retry;
    }
    next += cycle;
    const Clock::time_point now = Clock::now();
    if (next < now) next = now;  // overrun: do not try to catch up
    std::this_thread::sleep_until(next);
  }
}

bool ModbusTerminal::connect() {
  if (ctx_) {
    modbus_close(ctx_);
    modbus_free(ctx_);
  }
  ctx_ = modbus_new_tcp(map_.host.c_str(), map_.port);
  if (!ctx_) {
    dropLink(std::string("cannot create a Modbus context: ") + modbus_strerror(errno));
    return false;
  }
  modbus_set_slave(ctx_, map_.unit_id);
  const double t = map_.response_timeout_s;
  modbus_set_response_timeout(ctx_, static_cast<uint32_t>(t), static_cast<uint32_t>((t - std::floor(t)) * 1e6));
  if (modbus_connect(ctx_) != 0) {
    dropLink(std::string("connect failed: ") + modbus_strerror(errno));
    return false;
  }
  last_exchange_ = Clock::now();  // link_loss_after_s runs from the connection until a cycle completes
  flush_pending_ = false;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    up_ = true;
    have_read_ = false;
    error_ = "connected, no reply yet";
    ++stats_.connects;
    std::fill(commands_.begin(), commands_.end(), ValveOpenings{});
  }
  return exchange();
}

bool ModbusTerminal::exchange() {
  if (flush_pending_) flushLateReplies();
  if (!readInputs() || !writeOutputs()) return false;
  last_exchange_ = Clock::now();
  std::lock_guard<std::mutex> lock(mutex_);
  ++stats_.cycles;
  return true;
}

ModbusTerminal::Clock::time_point ModbusTerminal::midpoint(Clock::time_point sent, Clock::time_point replied) {
  return sent + (replied - sent) / 2;
}

void ModbusTerminal::requestHandled(Clock::time_point t) {
  // Any request the terminal handles restarts its watchdog (reads too: a cycle cut short after
  // its read kept the outputs on); past its trip, the outputs were shut from the trip on.
  const Clock::time_point trip = outputsHeldUntil();
  if (t > trip) {
    advanceDriven(trip, true);
    std::fill(applied_coils_.begin(), applied_coils_.end(), 0);
    std::fill(applied_holding_.begin(), applied_holding_.end(), 0);
  }
  watchdog_fed_ = t;
}

void ModbusTerminal::advanceDriven(Clock::time_point t, bool shut) {
  // Every slot's record runs to t with its openings so far, then holds the outputs written
  // last (or nothing, after a watchdog trip). A record already handed out past t (a cell read
  // while the write was on its way) keeps its time: the new openings act from then.
  for (std::size_t s = 0; s < map_.cells.size(); ++s) {
    const CellRegisters& c = map_.cells[s];
    const ValveOutput* out[2] = {&c.inlet, &c.vent};
    Driven& d = driven_[s];
    if (!d.started) {
      if (shut) continue;
      d.since = d.from = t;
      d.started = true;
    }
    const double held_s = std::max(0.0, std::chrono::duration<double>(t - d.since).count());
    for (int k = 0; k < 2; ++k) {
      d.integral_s[k] += d.opening[k] * held_s;
      d.total_s[k] += d.opening[k] * held_s;
      d.opening[k] = shut ? 0.0
                     : out[k]->kind == ValveOutput::kCoil
                         ? (applied_coils_[out[k]->address] ? 1.0 : 0.0)
                         : static_cast<double>(applied_holding_[out[k]->address]) / out[k]->full_scale;
    }
    d.since = std::max(t, d.since);
  }
}

bool ModbusTerminal::readInputs() {
  // Each answered request restarts the terminal's watchdog, also in a cycle cut short after it.
  std::vector<std::uint16_t> buffer(inputs_.size());
  Clock::time_point replied = Clock::now();
  for (const AddressRun& run : input_runs_) {
    const Clock::time_point sent = Clock::now();
    if (modbus_read_input_registers(ctx_, run.first, run.count, buffer.data() + run.first) != run.count)
      return requestFailed(errno, "reading input registers", run);
    replied = Clock::now();
    std::lock_guard<std::mutex> lock(mutex_);
    ++stats_.read_requests;
    requestHandled(midpoint(sent, replied));
  }
  std::lock_guard<std::mutex> lock(mutex_);
  inputs_.swap(buffer);
  last_read_ = replied;
  have_read_ = true;
  keepCycle(replied);
  return true;
}

void ModbusTerminal::keepCycle(Clock::time_point t) {
  const Clock::time_point held_until = std::min(t, outputsHeldUntil());
  for (std::size_t s = 0; s < map_.cells.size(); ++s) {
    const Driven& d = driven_[s];
    const double p = value(map_.cells[s].pressure_pa);
    if (!d.started || !std::isfinite(p)) continue;
    const double held_s = std::max(0.0, std::chrono::duration<double>(held_until - d.since).count());
    cycles_[s].push(t, p, d.total_s[0] + d.opening[0] * held_s, d.total_s[1] + d.opening[1] * held_s);
  }
}

void ModbusTerminal::fillOutputs() {
  const int phase = static_cast<int>(cycle_index_++ % pwm_steps_);
  for (std::size_t s = 0; s < map_.cells.size(); ++s) {
    const CellRegisters& c = map_.cells[s];
    const double duty[2] = {commands_[s].inlet, commands_[s].vent};
    const ValveOutput* out[2] = {&c.inlet, &c.vent};
    for (int k = 0; k < 2; ++k) {
      if (out[k]->kind == ValveOutput::kCoil) {
        coils_[out[k]->address] = pwm_[2 * s + k].next(duty[k], phase, pwm_steps_) ? 1 : 0;
      } else {
        holding_[out[k]->address] =
            static_cast<std::uint16_t>(std::lround(std::clamp(duty[k], 0.0, 1.0) * out[k]->full_scale));
      }
    }
  }
}

bool ModbusTerminal::writeOutputs() {
  std::vector<std::uint8_t> coils;
  std::vector<std::uint16_t> holding;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    fillOutputs();
    coils = coils_;
    holding = holding_;
  }
  // The outputs act when the terminal handles the write: between sending and its reply, taken
  // at the middle (at the reply every edge would be late by a loaded thread's wait).
  // One answered too late counts from the next write's: a terminal slow to answer is as slow
  // to act (timeouts come from its side; a client that woke late still finds the reply).
  // Each run acts when answered, whatever becomes of the runs after it.
  for (const AddressRun& run : coil_runs_) {
    const Clock::time_point sent = Clock::now();
    if (modbus_write_bits(ctx_, run.first, run.count, coils.data() + run.first) != run.count)
      return requestFailed(errno, "writing coils", run);
    outputsApplied(run, coils, &applied_coils_, sent);
  }
  for (const AddressRun& run : holding_runs_) {
    const Clock::time_point sent = Clock::now();
    if (modbus_write_registers(ctx_, run.first, run.count, holding.data() + run.first) != run.count)
      return requestFailed(errno, "writing holding registers", run);
    outputsApplied(run, holding, &applied_holding_, sent);
  }
  return true;
}

template <typename Word>
void ModbusTerminal::outputsApplied(const AddressRun& run, const std::vector<Word>& written, std::vector<Word>* applied,
                                    Clock::time_point sent) {
  const Clock::time_point replied = Clock::now();
  std::lock_guard<std::mutex> lock(mutex_);
  const Clock::time_point t = midpoint(sent, replied);
  requestHandled(t);  // a watchdog trip before it shut every output
  std::copy_n(written.begin() + run.first, run.count, applied->begin() + run.first);
  advanceDriven(t, false);
  ++stats_.write_requests;
}

bool ModbusTerminal::requestFailed(int error_number, const char* what, const AddressRun& run) {
  const std::string why = std::string(what) + " " + std::to_string(run.first) + "+" + std::to_string(run.count) +
                          " failed: " + modbus_strerror(error_number);
  const double silent_s = std::chrono::duration<double>(Clock::now() - last_exchange_).count();
  if (!transientModbusError(error_number)) {
    dropLink(why);
  } else if (silent_s >= map_.link_loss_after_s) {
    std::ostringstream s;
    s << "no bus cycle completed for " << std::lround(silent_s * 1000.0) << " ms (link_loss_after_s "
      << map_.link_loss_after_s << "), last: " << why;
    dropLink(s.str());
  } else {
    retryNextCycle(why);
  }
  return false;
}

void ModbusTerminal::retryNextCycle(const std::string& why) {
  flush_pending_ = true;
  std::lock_guard<std::mutex> lock(mutex_);
  ++stats_.failed_exchanges;
  error_ = why;  // what cells see while no reading has come since the connection
}

void ModbusTerminal::flushLateReplies() {
  // Not at the failure itself: a reply late by more than the response timeout is still on its
  // way then; a cycle later it has come (or the next request reports the mismatch).
  modbus_flush(ctx_);
  flush_pending_ = false;
}

void ModbusTerminal::dropLink(const std::string& why) {
  if (ctx_) modbus_close(ctx_);
  std::lock_guard<std::mutex> lock(mutex_);
  if (up_) ++stats_.link_losses;
  up_ = false;
  have_read_ = false;
  error_ = why;
  std::fill(commands_.begin(), commands_.end(), ValveOpenings{});
  // The driven record runs on: the outputs hold until the terminal's watchdog (takeDriven).
}

// --- the cell's view ------------------------------------------------------------------------

namespace {

/// Maps are parsed once per file and process (every cell of a bed reads the same one).
RegisterMap cachedMap(const std::string& path, std::uint32_t bed_cells) {
  static std::mutex mutex;
  static std::map<std::pair<std::string, std::uint32_t>, RegisterMap> cache;
  std::lock_guard<std::mutex> lock(mutex);
  const auto key = std::make_pair(path, bed_cells);
  auto it = cache.find(key);
  if (it == cache.end()) it = cache.emplace(key, loadRegisterMap(path, bed_cells)).first;
  return it->second;
}

}  // namespace

void ModbusTcpCellHardware::configure(const HardwareConfig& config) {
  if (config.register_map_path.empty()) throw std::runtime_error("modbus_tcp hardware: no register map given");
  const RegisterMap map = cachedMap(config.register_map_path, config.bed_cells);
  std::size_t terminal = 0;
  if (!map.find(config.cell_id, &terminal, &slot_))
    throw std::runtime_error("modbus_tcp hardware: cell " + std::to_string(config.cell_id) +
                             " is not in the register map " + config.register_map_path);
  registers_ = map.terminals[terminal].cells[slot_];
  terminal_ = ModbusTerminal::shared(map.terminals[terminal], config.control_period_s);
}

HardwareCapabilities ModbusTcpCellHardware::capabilities() const {
  HardwareCapabilities c;
  c.height = registers_.height_m.present();
  c.inflow = registers_.inflow_kg_s.present();
  c.supply_pressure = terminal_ && terminal_->map().supply_pressure_pa.present();
  return c;
}

CellReadings ModbusTcpCellHardware::read(double now_s) { return terminal_->readings(slot_, now_s); }

void ModbusTcpCellHardware::write(const ValveOpenings& valves, double /*now_s*/) { terminal_->command(slot_, valves); }

std::string ModbusTcpCellHardware::describe() const {
  std::ostringstream s;
  s << "modbus_tcp " << terminal_->map().name << " (" << terminal_->map().endpoint() << "), cell " << registers_.cell_id
    << ": inlet " << (registers_.inlet.kind == ValveOutput::kCoil ? "coil " : "register ") << registers_.inlet.address
    << ", vent " << (registers_.vent.kind == ValveOutput::kCoil ? "coil " : "register ") << registers_.vent.address
    << ", pressure input " << registers_.pressure_pa.address << "; bus thread " << terminal_->scheduling().text;
  return s.str();
}

std::string ModbusTcpCellHardware::warning() const {
  if (!terminal_->scheduling().refused) return {};
  return "modbus_tcp " + terminal_->map().name + ": bus thread at " + terminal_->scheduling().text +
         ": on a loaded machine the valves' edges are stamped less exactly and the observer's gas count scatters more";
}

}  // namespace nursing_bed
