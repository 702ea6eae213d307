#include "nursing_bed/core/rig/rig_emulator.h"

#include <modbus/modbus.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sys/select.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <stdexcept>

#include "nursing_bed/core/hardware/thread_priority.h"

namespace nursing_bed {
namespace {

int mappingSize(const TerminalMap& map, bool coils, bool holding) {
  int top = -1;
  for (const CellRegisters& c : map.cells) {
    for (const ValveOutput* v : {&c.inlet, &c.vent}) {
      const bool is_coil = v->kind == ValveOutput::kCoil;
      if ((coils && is_coil) || (holding && !is_coil)) top = std::max(top, v->address);
    }
    if (!coils && !holding)
      for (const AnalogInput* in : {&c.pressure_pa, &c.height_m, &c.inflow_kg_s}) top = std::max(top, in->address);
  }
  if (!coils && !holding) top = std::max(top, map.supply_pressure_pa.address);
  return top + 1;
}

/// Replies go out at once (TCP_NODELAY, which libmodbus sets on its clients' sockets only). With
/// Nagle's algorithm a reply sent while the previous one is unacknowledged waits for the
/// client's next request to carry the acknowledgement: after two replies back to back (one came
/// late) every reply would arrive on the request after its own, a transaction id mismatch each.
int noDelay(int fd) {
  const int on = 1;
  ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &on, sizeof(on));
  return fd;
}

}  // namespace

RigTerminalServer::RigTerminalServer(const TerminalMap& map)
    : map_(map), last_answer_(std::chrono::steady_clock::now()) {
  if (map.host != "127.0.0.1")
    throw std::runtime_error("rig emulator: terminal '" + map.name +
                             "' must listen on 127.0.0.1 (loopback only), not " + map.host);
  ctx_ = modbus_new_tcp("127.0.0.1", map.port);
  mapping_ = modbus_mapping_new(mappingSize(map, true, false), 0, mappingSize(map, false, true),
                                mappingSize(map, false, false));
  if (!ctx_ || !mapping_) throw std::runtime_error("rig emulator: cannot allocate the Modbus server for " + map.name);
  modbus_set_slave(ctx_, map.unit_id);
  listen_fd_ = modbus_tcp_listen(ctx_, 8);
  if (listen_fd_ < 0)
    throw std::runtime_error("rig emulator: terminal '" + map.name + "' cannot listen on " + map.endpoint() + ": " +
                             modbus_strerror(errno));
  coil_on_s_.assign(mapping_->nb_bits, 0.0);
  coil_total_on_s_.assign(mapping_->nb_bits, 0.0);
  coils_since_ = std::chrono::steady_clock::now();
  thread_ = std::thread(&RigTerminalServer::run, this);
  scheduling_ = scheduleRealtime(thread_, map_.realtime_priority);
}

RigTerminalServer::~RigTerminalServer() {
  stop_ = true;
  if (thread_.joinable()) thread_.join();
  for (int fd : clients_) ::close(fd);
  if (listen_fd_ >= 0) ::close(listen_fd_);
  modbus_mapping_free(mapping_);
  modbus_free(ctx_);
}

void RigTerminalServer::run() {
  while (!stop_) {
    fd_set readable;
    FD_ZERO(&readable);
    FD_SET(listen_fd_, &readable);
    int top = listen_fd_;
    for (int fd : clients_) {
      FD_SET(fd, &readable);
      top = std::max(top, fd);
    }
    timeval timeout{0, 10000};
    const int ready_count = ::select(top + 1, &readable, nullptr, nullptr, &timeout);
    checkWatchdog();
    if (ready_count <= 0) continue;
    if (FD_ISSET(listen_fd_, &readable)) {
      const int fd = ::accept(listen_fd_, nullptr, nullptr);
      if (fd >= 0) clients_.push_back(noDelay(fd));
    }
    const std::vector<int> ready = clients_;
    for (int fd : ready)
      if (FD_ISSET(fd, &readable)) serveClient(fd);
  }
}

void RigTerminalServer::checkWatchdog() {
  // In real time: counted in select() timeouts a loaded machine would stretch it, and a filling
  // cell would pass gas the client cannot know of.
  if (std::chrono::steady_clock::now() < watchdogTrip()) return;
  std::lock_guard<std::mutex> lock(mutex_);
  accountCoils();
}

std::chrono::steady_clock::time_point RigTerminalServer::watchdogTrip() const {
  return last_answer_ + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                            std::chrono::duration<double>(map_.watchdog_s));
}

void RigTerminalServer::serveClient(int fd) {
  std::uint8_t query[MODBUS_TCP_MAX_ADU_LENGTH];
  modbus_set_socket(ctx_, fd);
  const int length = modbus_receive(ctx_, query);
  if (length > 0) {
    if (withholdReply()) return;
    std::lock_guard<std::mutex> lock(mutex_);
    accountCoils();  // the coils held their state up to this request
    modbus_reply(ctx_, query, length, mapping_);
    ++requests_;
    last_answer_ = std::chrono::steady_clock::now();
  } else if (length < 0) {  // the client went away
    ::close(fd);
    clients_.erase(std::remove(clients_.begin(), clients_.end(), fd), clients_.end());
  }
}

void RigTerminalServer::answerLate(long requests, double delay_s) {
  late_delay_s_ = delay_s;
  late_ = requests;
}

void RigTerminalServer::setReplyFaults(double drop_probability, double delay_probability, double delay_s,
                                       std::uint32_t seed) {
  std::lock_guard<std::mutex> lock(reply_faults_mutex_);
  reply_faults_.drop_probability = drop_probability;
  reply_faults_.delay_probability = delay_probability;
  reply_faults_.delay_s = delay_s;
  reply_faults_.rng.seed(seed);
}

void RigTerminalServer::silenceFor(double seconds) {
  std::lock_guard<std::mutex> lock(reply_faults_mutex_);
  reply_faults_.silent_until =
      std::chrono::steady_clock::now() +
      std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(seconds));
}

bool RigTerminalServer::withholdReply() {
  double delay_s = 0.0;
  {
    std::lock_guard<std::mutex> lock(reply_faults_mutex_);
    ReplyFaults& f = reply_faults_;
    if (std::chrono::steady_clock::now() < f.silent_until) return true;
    std::uniform_real_distribution<double> draw(0.0, 1.0);
    if (f.drop_probability > 0.0 && draw(f.rng) < f.drop_probability) return true;
    if (f.delay_probability > 0.0 && draw(f.rng) < f.delay_probability) delay_s = f.delay_s;
  }
  if (delay_s > 0.0) std::this_thread::sleep_for(std::chrono::duration<double>(delay_s));
  if (unanswered_ > 0) {
    --unanswered_;
    return true;
  }
  if (late_ > 0) {
    --late_;
    std::this_thread::sleep_for(std::chrono::duration<double>(late_delay_s_.load()));
  }
  return false;
}

void RigTerminalServer::accountCoils() {
  // The coils held their state until now, or until the watchdog tripped if that came first:
  // a real terminal's watchdog shuts its outputs on time, while this server's thread, starved
  // on a loaded machine (a bed's start), may only get here hundreds of ms later. Counted up to
  // now, a cell passed gas for the whole stall that the client's driven record (which stops at
  // the watchdog) never counts.
  const auto now = std::chrono::steady_clock::now();
  const auto trip = watchdogTrip();
  const auto held_until = std::min(now, std::max(trip, coils_since_));
  const double held_s = std::chrono::duration<double>(held_until - coils_since_).count();
  for (int i = 0; i < mapping_->nb_bits; ++i) {
    if (!mapping_->tab_bits[i]) continue;
    coil_on_s_[i] += held_s;
    coil_total_on_s_[i] += held_s;
  }
  coils_since_ = now;
  if (now >= trip) {
    std::fill(mapping_->tab_bits, mapping_->tab_bits + mapping_->nb_bits, 0);
    std::fill(mapping_->tab_registers, mapping_->tab_registers + mapping_->nb_registers, 0);
  }
}

std::vector<double> RigTerminalServer::takeCoilDuty(double span_s) {
  // The on-time is passed whole over the periods run: divided by the wall time since the last
  // take, a wake 1 ms late (6 ms of on-time taken, 5 ms run) would pass five sixths of it.
  std::lock_guard<std::mutex> lock(mutex_);
  accountCoils();
  std::vector<double> duty(coil_on_s_.size());
  for (std::size_t i = 0; i < duty.size(); ++i) {
    duty[i] = span_s > 0.0 ? std::min(1.0, coil_on_s_[i] / span_s) : 0.0;
    coil_on_s_[i] -= duty[i] * span_s;
  }
  return duty;
}

double RigTerminalServer::coilOnSeconds(int address) {
  std::lock_guard<std::mutex> lock(mutex_);
  accountCoils();
  return coil_total_on_s_.at(static_cast<std::size_t>(address));
}

RigEmulator::RigEmulator(const RegisterMap& map, const RigEmulatorOptions& options)
    : options_(options), fault_rng_(options.fault_seed) {
  for (std::size_t t = 0; t < map.terminals.size(); ++t) {
    servers_.push_back(std::make_unique<RigTerminalServer>(map.terminals[t]));
    for (const CellRegisters& registers : map.terminals[t].cells) {
      Cell cell;
      cell.terminal = t;
      cell.registers = registers;
      RigImperfections rig = options.rig;
      rig.height_sensor = registers.height_m.present();
      HardwareConfig config = options.cell;
      config.cell_id = registers.cell_id;
      config.control_period_s = options.period_s;
      config.noise_seed = options.cell.noise_seed + registers.cell_id;
      cell.hardware = std::make_unique<SimulatedCellHardware>(rig);
      cell.hardware->configure(config);
      cells_.push_back(std::move(cell));
    }
  }
  stepAll(1, std::chrono::steady_clock::now());
  thread_ = std::thread(&RigEmulator::run, this);
  scheduling_ = scheduleRealtime(thread_, options_.realtime_priority);
}

RigEmulator::~RigEmulator() {
  stop_ = true;
  if (thread_.joinable()) thread_.join();
}

void RigEmulator::setLoad(std::uint32_t cell_id, double load_n) {
  std::lock_guard<std::mutex> lock(mutex_);
  for (Cell& c : cells_)
    if (c.registers.cell_id == cell_id) c.hardware->setLoad(load_n);
}

void RigEmulator::setLoads(const std::vector<double>& load_n_by_id) {
  std::lock_guard<std::mutex> lock(mutex_);
  for (Cell& c : cells_) {
    const std::uint32_t id = c.registers.cell_id;
    if (id < load_n_by_id.size() && std::isfinite(load_n_by_id[id]) && load_n_by_id[id] >= 0.0)
      c.hardware->setLoad(load_n_by_id[id]);
  }
}

std::vector<CellTruth> RigEmulator::truth(std::chrono::steady_clock::time_point* at) const {
  std::lock_guard<std::mutex> lock(mutex_);
  if (at) *at = simulated_until_;
  std::vector<CellTruth> out;
  for (const Cell& c : cells_) {
    const CellVariables& v = c.hardware->variables();
    CellTruth t;
    t.cell_id = c.registers.cell_id;
    t.height_m = v.height_m;
    t.gauge_pressure_pa = v.gauge_pressure_pa;
    t.gas_mass_kg = v.mass_kg;
    t.temperature_k = v.temperature_k;
    t.inflow_kg_s = v.inflow_kg_s;
    t.vent_flow_kg_s = v.vent_flow_kg_s;
    t.load_n = c.hardware->load();
    t.inlet_opening = c.hardware->actingValves().inlet;
    t.vent_opening = c.hardware->actingValves().vent;
    out.push_back(t);
  }
  return out;
}

void RigEmulator::applyOutputs(RigTerminalServer& server, const std::vector<double>& coil_duty, Cell& cell) {
  // A coil valve passes its on-time over the last step (the simulated valve takes a fractional
  // opening as a mean); a proportional valve its register's setting.
  server.withRegisters([&](modbus_mapping_t* m) {
    auto opening = [&](const ValveOutput& v) {
      return v.kind == ValveOutput::kCoil ? coil_duty[v.address]
                                          : std::min(1.0, m->tab_registers[v.address] / v.full_scale);
    };
    const ValveOpenings commanded{opening(cell.registers.inlet), opening(cell.registers.vent), false};
    cell.hardware->write(cell.faults.apply(commanded, options_.cell.cell.vent_area_m2), 0.0);
  });
}

void RigEmulator::publishInputs(RigTerminalServer& server, const Cell& cell) {
  const Readings& m = cell.hardware->measurement();
  const CellRegisters& r = cell.registers;
  server.withRegisters([&](modbus_mapping_t* map) {
    if (!cell.faults.frozen)
      map->tab_input_registers[r.pressure_pa.address] =
          r.pressure_pa.toCount(m.gauge_pressure_pa + cell.faults.offset_pa);
    if (r.height_m.present()) map->tab_input_registers[r.height_m.address] = r.height_m.toCount(m.height_m);
    if (r.inflow_kg_s.present()) map->tab_input_registers[r.inflow_kg_s.address] = r.inflow_kg_s.toCount(m.inflow_kg_s);
    const AnalogInput& supply = server.map().supply_pressure_pa;
    if (supply.present())
      map->tab_input_registers[supply.address] = supply.toCount(cell.hardware->variables().regulator_pressure_pa);
  });
}

void RigEmulator::stepAll(int periods, std::chrono::steady_clock::time_point until) {
  std::lock_guard<std::mutex> lock(mutex_);
  // The coils' on-time since the last wake is passed over the periods run now.
  std::vector<std::vector<double>> coil_duty;
  for (auto& server : servers_) coil_duty.push_back(server->takeCoilDuty(periods * options_.period_s));
  for (Cell& c : cells_) applyOutputs(*servers_[c.terminal], coil_duty[c.terminal], c);
  for (Cell& c : cells_)
    if (c.empty_at && until >= *c.empty_at) {
      c.hardware->reset(c.hardware->load());
      c.empty_at.reset();
    }
  for (int k = 0; k < periods; ++k)
    for (Cell& c : cells_) c.hardware->stepPeriod();
  for (const Cell& c : cells_) publishInputs(*servers_[c.terminal], c);
  simulated_until_ = until;
  steps_ += periods;
  ++wakes_;
  if (periods > most_periods_) most_periods_ = periods;
}

std::vector<std::uint32_t> RigEmulator::servedIds() const {
  std::vector<std::uint32_t> ids;
  for (const Cell& c : cells_) ids.push_back(c.registers.cell_id);
  return ids;
}

CellFaults RigEmulator::faults(std::uint32_t cell_id) const {
  std::lock_guard<std::mutex> lock(mutex_);
  for (const Cell& c : cells_)
    if (c.registers.cell_id == cell_id) return c.faults;
  return CellFaults{};
}

Status RigEmulator::inject(const RigFaultRequest& request, std::string* applied) {
  RigFaultKind kind = RigFaultKind::kClear;
  const std::vector<std::uint32_t> served = servedIds();
  const Status valid = checkRigFault(request, served, options_.cell.cell.vent_area_m2, &kind);
  if (!valid) return valid;
  std::vector<std::uint32_t> ids;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    ids = rigFaultCells(request, served, &fault_rng_);
    ++injections_;
    for (Cell& c : cells_) {
      if (std::find(ids.begin(), ids.end(), c.registers.cell_id) == ids.end()) continue;
      applyCellFault(kind, request, &c.faults);
      // A restarted terminal's cells come back flat and empty, as a fresh rig's do: emptied
      // while it is silent, after its clients have lost the link.
      if (kind == RigFaultKind::kRestart && !request.keep_gas)
        c.empty_at = std::chrono::steady_clock::now() + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                                                            std::chrono::duration<double>(0.5 * request.value));
    }
  }
  injectIntoTerminals(kind, request, ids);
  if (applied) {
    *applied = request.fault + " on cells";
    for (const std::uint32_t id : ids) *applied += " " + std::to_string(id);
  }
  return Status::success();
}

void RigEmulator::injectIntoTerminals(RigFaultKind kind, const RigFaultRequest& request,
                                      const std::vector<std::uint32_t>& ids) {
  // Replies are a terminal's: every terminal serving one of the cells takes the request.
  for (std::size_t t = 0; t < servers_.size(); ++t) {
    bool serves = false;
    for (const Cell& c : cells_)
      serves = serves || (c.terminal == t && std::find(ids.begin(), ids.end(), c.registers.cell_id) != ids.end());
    if (!serves) continue;
    const std::uint32_t seed =
        options_.fault_seed + 1000u * static_cast<std::uint32_t>(injections_) + static_cast<std::uint32_t>(t);
    RigTerminalServer& server = *servers_[t];
    if (kind == RigFaultKind::kDropReplies) server.setReplyFaults(request.value, 0.0, 0.0, seed);
    if (kind == RigFaultKind::kDelayReplies) server.setReplyFaults(0.0, request.value, request.delay_s, seed);
    if (kind == RigFaultKind::kClear) server.setReplyFaults(0.0, 0.0, 0.0, seed);
    if (kind == RigFaultKind::kRestart) server.silenceFor(request.value);
  }
}

void RigEmulator::run() {
  // The rig's time is the wall clock's: a late wake-up runs the periods it missed (the valves
  // held their coils meanwhile), so that the gas a cell receives is what its valves passed in
  // real time. Dropped, they would lose gas the controller's side counted, and the cells would
  // fill slower than real valves. Only a lag beyond
  // max_catch_up_s is given up, and counted.
  using Clock = std::chrono::steady_clock;
  const auto period = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(options_.period_s));
  const auto give_up =
      std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(options_.max_catch_up_s));
  Clock::time_point next = Clock::now() + period;
  while (!stop_) {
    std::this_thread::sleep_until(next);
    const Clock::time_point now = Clock::now();
    if (now - next > give_up) {
      ++overruns_;
      lost_s_ = lost_s_ + std::chrono::duration<double>(now - next).count();
      next = now;
    }
    int due = 0;
    for (; next <= now; next += period) ++due;
    if (due > 0) stepAll(due, next - period);
  }
}

}  // namespace nursing_bed
