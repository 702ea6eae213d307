// The modbus_tcp hardware against the rig emulator on 127.0.0.1: readings, batched requests,
// PWM'd and proportional valves, link loss and recovery, late and missing replies (the rig's
// fault injection). Waits poll a condition with a generous bound; they assert behaviour, not
// speed (speed: doc/benchmarks.md): when the link went down is counted in retried exchanges.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>
#include <thread>

#include <modbus/modbus.h>

#include "../../test_helpers.h"
#include "nursing_bed/core/hardware/modbus_tcp_hardware.h"
#include "nursing_bed/core/rig/rig_emulator.h"

namespace nb = nursing_bed;

namespace {

// Cells 0, 1 on terminal a (on/off valves, cell 1 with a height input), cells 2, 3 on
// terminal b (proportional valves).
const char* kMap = R"(
terminals:
  - name: a
    host: 127.0.0.1
    port: 15610
    cycle_s: 0.005
    cells:
      - {cell: 0, inlet: {coil: 0}, vent: {coil: 1}, pressure: {input_register: 0, scale_pa: 1.0, offset_pa: -10000}}
      - {cell: 1, inlet: {coil: 2}, vent: {coil: 3}, pressure: {input_register: 1, scale_pa: 1.0, offset_pa: -10000},
         height: {input_register: 2, scale_m: 1.0e-5}}
  - name: b
    host: 127.0.0.1
    port: 15611
    cell_block: {first_cell: 2, count: 2, valves: holding_register, inlet_start: 0, vent_start: 2,
                 pressure_start: 0, pressure_scale_pa: 1.0, pressure_offset_pa: -10000}
)";

bool waitFor(const std::function<bool()>& condition, double timeout_s) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (std::chrono::steady_clock::now() < end) {
    if (condition()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return condition();
}

class ModbusLoopback : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto dir = nb::test::freshTestDir("rig", "loopback");
    map_path_ = nb::test::writeFile(dir / "map.yaml", kMap);
    map_ = nb::loadRegisterMap(map_path_, 4);
    options_.cell.initial_height_m = 0.05;
    options_.cell.load_n = 15.6;
    options_.rig.adc_step_pa = 12.2;
    startEmulator();
    for (std::uint32_t id = 0; id < 4; ++id) {
      nb::HardwareConfig config;
      config.cell_id = id;
      config.control_period_s = 0.02;
      config.register_map_path = map_path_;
      config.bed_cells = 4;
      cells_.push_back(std::make_unique<nb::ModbusTcpCellHardware>());
      cells_.back()->configure(config);
    }
    ASSERT_TRUE(waitFor([this] { return allUp(); }, 3.0));
  }
  void startEmulator() { emulator_ = std::make_unique<nb::RigEmulator>(map_, options_); }
  /// Every cell in [first, end) reads `state`.
  bool cellsRead(nb::LinkState state, std::size_t first = 0, std::size_t end = 4) {
    for (std::size_t i = first; i < end; ++i)
      if (cells_[i]->read(0.0).link != state) return false;
    return true;
  }
  bool allUp() { return cellsRead(nb::LinkState::kOk); }
  bool allDown() { return cellsRead(nb::LinkState::kDown); }
  nb::CellTruth truth(std::uint32_t id) { return emulator_->truth().at(id); }
  /// Terminal a (cells 0 and 1): the client side and the rig's server.
  std::shared_ptr<nb::ModbusTerminal> terminalA() { return nb::ModbusTerminal::shared(map_.terminals[0], 0.02); }
  nb::RigTerminalServer& serverA() { return *emulator_->servers().at(0); }
  /// Reads cell k; its inlet's reported (driven) opening times the time since `*last` is added
  /// to `*on_s` (the driver reports the mean opening since the previous read).
  nb::CellReadings readDriven(int k, std::chrono::steady_clock::time_point* last, double* on_s) {
    const auto now = std::chrono::steady_clock::now();
    const nb::CellReadings r = cells_[k]->read(0.0);
    EXPECT_TRUE(r.inlet_driven.present());
    *on_s += r.inlet_driven.value * std::chrono::duration<double>(now - *last).count();
    *last = now;
    return r;
  }
  /// After `fault` (injected into terminal a's server), at least one cycle fails and is
  /// retried, exchanges go on, and the link never went down.
  void expectRetriedWithoutLinkLoss(const std::function<void()>& fault) {
    auto terminal = terminalA();
    const nb::TerminalStats s0 = terminal->stats();
    fault();
    ASSERT_TRUE(waitFor([&] { return terminal->stats().failed_exchanges > s0.failed_exchanges; }, 2.0))
        << "no failure seen";
    const long cycles = terminal->stats().cycles;
    ASSERT_TRUE(waitFor([&] { return terminal->stats().cycles >= cycles + 20; }, 2.0)) << "exchanges go on";
    const nb::TerminalStats s1 = terminal->stats();
    EXPECT_EQ(s1.link_losses, s0.link_losses) << "the link stayed up";
    EXPECT_EQ(s1.connects, s0.connects) << "no reconnection";
    EXPECT_LE(s1.failed_exchanges - s0.failed_exchanges, 5) << "back in step at once";
    EXPECT_TRUE(allUp());
  }

  std::string map_path_;
  nb::RegisterMap map_;
  nb::RigEmulatorOptions options_;
  std::unique_ptr<nb::RigEmulator> emulator_;
  std::vector<std::unique_ptr<nb::ModbusTcpCellHardware>> cells_;
};

}  // namespace

TEST_F(ModbusLoopback, ReadsEveryCellsPressureAndTheHeightWhereFitted) {
  for (std::uint32_t id = 0; id < 4; ++id) {
    const nb::CellReadings r = cells_[id]->read(10.0);
    ASSERT_TRUE(r.gauge_pressure_pa.present()) << id;
    EXPECT_NEAR(r.gauge_pressure_pa.value, truth(id).gauge_pressure_pa, 20.0) << id;
    EXPECT_LE(r.gauge_pressure_pa.stamp_s, 10.0);
    EXPECT_GT(r.gauge_pressure_pa.stamp_s, 9.5) << "a fresh reading";
    EXPECT_EQ(r.height_m.present(), id == 1) << id;
  }
  EXPECT_NEAR(cells_[1]->read(0.0).height_m.value, truth(1).height_m, 2e-5);
  EXPECT_TRUE(cells_[1]->capabilities().height);
  EXPECT_FALSE(cells_[0]->capabilities().height);
}

TEST_F(ModbusLoopback, OneReadAndOneWriteRequestPerCycleForAllCellsOfATerminal) {
  auto terminal = nb::ModbusTerminal::shared(map_.terminals[1], 0.02);
  const nb::TerminalStats s0 = terminal->stats();
  ASSERT_TRUE(waitFor([&] { return terminal->stats().cycles >= s0.cycles + 20; }, 3.0));
  const nb::TerminalStats s1 = terminal->stats();
  const long cycles = s1.cycles - s0.cycles;
  // Terminal b: its two cells' pressures are one run of input registers, their four
  // proportional valves one run of holding registers.
  EXPECT_NEAR(static_cast<double>(s1.read_requests - s0.read_requests) / cycles, 1.0, 0.1);
  EXPECT_NEAR(static_cast<double>(s1.write_requests - s0.write_requests) / cycles, 1.0, 0.1);
}

TEST_F(ModbusLoopback, OnOffValvesArePulseWidthModulatedProportionalOnesScaled) {
  cells_[0]->write({0.5, 0.0, false}, 0.0);
  cells_[2]->write({0.25, 0.0, false}, 0.0);
  ASSERT_TRUE(waitFor([this] { return truth(2).inlet_opening > 0.0; }, 1.0));
  EXPECT_NEAR(truth(2).inlet_opening, 0.25, 1e-3);
  int on = 0, samples = 0;
  for (; samples < 200; ++samples) {
    on += truth(0).inlet_opening > 0.5 ? 1 : 0;
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  EXPECT_GT(on, samples / 5) << "the on/off inlet is open part of the time";
  EXPECT_LT(on, samples * 4 / 5) << "and shut the rest";
  cells_[0]->write({}, 0.0);
  cells_[2]->write({}, 0.0);
}

TEST_F(ModbusLoopback, ReportsTheOpeningsItDroveTimeAveraged) {
  // Every read says what the outputs did since the previous one: the PWM'd coil's pulses
  // average to its duty, the proportional valve reads its scaled opening.
  cells_[0]->write({0.3, 0.0, false}, 0.0);
  cells_[2]->write({0.6, 0.0, false}, 0.0);
  ASSERT_TRUE(waitFor([this] { return truth(2).inlet_opening > 0.0; }, 1.0));
  cells_[0]->read(0.0);
  cells_[2]->read(0.0);
  double on_s = 0.0;
  const auto start = std::chrono::steady_clock::now();
  auto last = start;
  while (std::chrono::steady_clock::now() - start < std::chrono::milliseconds(1000)) {
    std::this_thread::sleep_for(std::chrono::milliseconds(7));
    const nb::CellReadings r = readDriven(0, &last, &on_s);
    EXPECT_NEAR(r.vent_driven.value, 0.0, 1e-12);
    const nb::CellReadings p = cells_[2]->read(0.0);
    ASSERT_TRUE(p.inlet_driven.present());
    EXPECT_NEAR(p.inlet_driven.value, 0.6, 1e-3);
  }
  const double total_s = std::chrono::duration<double>(last - start).count();
  EXPECT_NEAR(on_s / total_s, 0.3, 0.05) << "the pulses average to the duty";
  cells_[0]->write({}, 0.0);
  cells_[2]->write({}, 0.0);
}

TEST_F(ModbusLoopback, TheOpeningsReportedAsDrivenAreTheTerminalsCoilOnTime) {
  // The observer counts a cell's gas by what the driver says its valves did; a fill passes
  // 0.2 % of a cell's gas per ms, so each edge must be placed within a bus cycle. Over a second
  // of a cell pulsing its inlet, the driven record's on-time is the terminal's coils'.
  nb::RigTerminalServer& server = serverA();
  const int inlet = map_.terminals[0].cells[0].inlet.address;
  cells_[0]->read(0.0);
  const double on_before_s = server.coilOnSeconds(inlet);
  double driven_s = 0.0;
  auto last = std::chrono::steady_clock::now();
  for (int i = 0; i < 60; ++i) {
    cells_[0]->write({i % 3 == 0 ? 1.0 : 0.0, 0.0, false}, 0.0);
    std::this_thread::sleep_for(std::chrono::milliseconds(17));
    readDriven(0, &last, &driven_s);
  }
  cells_[0]->write({}, 0.0);
  for (int i = 0; i < 10; ++i) {  // past the last PWM frame: shut on both sides
    std::this_thread::sleep_for(std::chrono::milliseconds(15));
    readDriven(0, &last, &driven_s);
  }
  const double on_s = server.coilOnSeconds(inlet) - on_before_s;
  std::printf("[          ] inlet on %.4f s at the terminal, %.4f s in the driven record\n", on_s, driven_s);
  EXPECT_GT(on_s, 0.2) << "the inlet pulsed";
  // An edge misplaced by a bus cycle on each of the 20 pulses would be 20 cycles (~18 %) off;
  // half a cycle per pulse leaves room for both threads' scheduling jitter on a loaded machine
  // (the 40 edges' delays of a few ms each do not cancel) while still catching that.
  const int pulses = 20;
  const double cycle_s = map_.terminals[0].cycle_s;
  EXPECT_NEAR(driven_s, on_s, 0.5 * cycle_s * pulses) << "within a bus cycle per pulse over 20 pulses";
}

TEST_F(ModbusLoopback, ALostTerminalIsReportedAndReconnectedByItself) {
  cells_[3]->write({0.0, 0.0, false}, 0.0);
  const long failed_before = terminalA()->stats().failed_exchanges;
  emulator_.reset();
  ASSERT_TRUE(waitFor([this] { return allDown(); }, 2.0));
  // A closed connection is not waited out (link_loss_after_s is for silence): the link goes
  // down at the first failed request (one request may have been in flight), where silence
  // retries each timeout until link_loss_after_s has passed.
  EXPECT_LE(terminalA()->stats().failed_exchanges - failed_before, 1);
  const nb::CellReadings down = cells_[0]->read(0.0);
  EXPECT_FALSE(down.gauge_pressure_pa.present());
  nb::test::expectContains(down.link_error, {"a (127.0.0.1:15610"});
  // A command while down is dropped: the valves come back shut.
  cells_[3]->write({1.0, 0.0, false}, 0.0);
  startEmulator();
  ASSERT_TRUE(waitFor([this] { return allUp(); }, 3.0));
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  EXPECT_EQ(truth(3).inlet_opening, 0.0);
  cells_[3]->write({1.0, 0.0, false}, 0.0);
  EXPECT_TRUE(waitFor([this] { return truth(3).inlet_opening > 0.99; }, 1.0)) << "commands flow again";
}

TEST_F(ModbusLoopback, AnUnansweredRequestIsRetriedNextCycleTheLinkStaysUp) {
  expectRetriedWithoutLinkLoss([this] { serverA().leaveUnanswered(1); });
}

TEST_F(ModbusLoopback, ALateReplyIsFlushedAndTheLinkStaysUp) {
  // 80 ms late, past the 50 ms response timeout: the late reply lands on the next request
  // (a transaction id mismatch), then is flushed before the cycle after.
  expectRetriedWithoutLinkLoss([this] { serverA().answerLate(1, 0.08); });
}

TEST_F(ModbusLoopback, ASilentTerminalGoesDownAfterLinkLossAfterSAndComesBack) {
  const nb::TerminalMap& a = map_.terminals[0];
  const long failed_before = terminalA()->stats().failed_exchanges;
  serverA().leaveUnanswered(std::numeric_limits<long>::max());  // connected, never answers
  ASSERT_TRUE(waitFor([this] { return cellsRead(nb::LinkState::kDown, 0, 2); }, 2.0));
  // Counted in requests, not timed: each unanswered request is retried until link_loss_after_s
  // has passed (the register map's check keeps that within the 0.5 s fault report), and each
  // retry waited out its response timeout, so no more fit in link_loss_after_s.
  const long retried = terminalA()->stats().failed_exchanges - failed_before;
  std::printf("[          ] the silent terminal went down after %ld retried requests\n", retried);
  EXPECT_GE(retried, 1) << "not at the first timeout";
  EXPECT_LE(retried, static_cast<long>(std::ceil(a.link_loss_after_s / a.response_timeout_s)))
      << "at the first timeout past link_loss_after_s";
  nb::test::expectContains(cells_[0]->read(0.0).link_error, {"a (127.0.0.1:15610"});
  EXPECT_TRUE(cellsRead(nb::LinkState::kOk, 2, 4)) << "terminal b is not affected";
  EXPECT_GE(terminalA()->stats().link_losses, 1);
  serverA().leaveUnanswered(0);
  EXPECT_TRUE(waitFor([this] { return allUp(); }, 3.0)) << "back by itself when the terminal answers again";
}

TEST_F(ModbusLoopback, TheOnTimeIsHandedOutOverTheCallersPeriods) {
  // A cell integrates each read's mean opening over its own period (its now_s less the
  // previous read's), not over the driver's clock: on a loaded bed a read that waited for the
  // terminal's lock has a real span longer than the cell's period, the next one a shorter.
  // Here the caller's clock advances 5 ms per read while about 8 ms pass: averaged over the
  // real spans the on-time would be counted 5/8; over the caller's periods, the excess carried
  // to later reads, it is counted once, as the rig's coil passed it. A full opening has two
  // edges: a PWM'd one's dozens would each add the loaded machine's request latency jitter.
  const int coil = map_.terminals[0].cells[0].inlet.address;
  double caller_s = 1.0, counted_s = 0.0;
  auto readAfter = [&](int reads) {
    for (int k = 0; k < reads; ++k) {
      std::this_thread::sleep_for(std::chrono::milliseconds(8));
      caller_s += 0.005;
      const nb::CellReadings r = cells_[0]->read(caller_s);
      if (r.inlet_driven.present()) counted_s += r.inlet_driven.value * 0.005;
    }
  };
  cells_[0]->read(caller_s);
  const double coil_before_s = serverA().coilOnSeconds(coil);
  cells_[0]->write({1.0, 0.0, false}, 0.0);
  readAfter(60);
  cells_[0]->write({}, 0.0);
  readAfter(140);  // the valve shut a cycle later; the carried on-time handed out (1 s of periods)
  const double coil_s = serverA().coilOnSeconds(coil) - coil_before_s;
  std::printf("[          ] the coil was on %.4f s, the reads' means over the caller's periods give %.4f s\n", coil_s,
              counted_s);
  ASSERT_GT(coil_s, 0.3) << "the inlet was open for the first 60 reads";
  // Counting over the real spans would be 5/8 of the coil's time; the band leaves room for the
  // sleeps' jitter on a loaded machine.
  EXPECT_NEAR(counted_s, coil_s, 0.08 * coil_s) << "the on-time counted once";
}

TEST_F(ModbusLoopback, OverALostLinkTheOutputsHeldUntilTheTerminalsWatchdogAreReported) {
  // A terminal holds its outputs as last written until its watchdog (0.1 s) shuts them: a
  // filling cell's inlet passed gas for that long after the last exchange, and the cell must
  // hear of it (reported as driven) though the link is down, and of nothing after it.
  const double watchdog_s = map_.terminals[0].watchdog_s;
  cells_[0]->write({1.0, 0.0, false}, 0.0);
  ASSERT_TRUE(waitFor([this] { return truth(0).inlet_opening > 0.99; }, 1.0));
  std::this_thread::sleep_for(std::chrono::milliseconds(100));  // past the PWM's first, partial frame
  cells_[0]->read(0.0);
  std::this_thread::sleep_for(std::chrono::milliseconds(30));
  ASSERT_NEAR(cells_[0]->read(0.0).inlet_driven.value, 1.0, 1e-9) << "open throughout";
  const auto silent = std::chrono::steady_clock::now();
  auto last = silent;
  serverA().leaveUnanswered(std::numeric_limits<long>::max());
  double open_s = 0.0;
  bool went_down = false;
  while (std::chrono::steady_clock::now() - silent < std::chrono::milliseconds(900)) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
    const auto now = std::chrono::steady_clock::now();
    const nb::CellReadings r = cells_[0]->read(0.0);
    went_down = went_down || r.link == nb::LinkState::kDown;
    if (r.inlet_driven.present()) open_s += r.inlet_driven.value * std::chrono::duration<double>(now - last).count();
    last = now;
  }
  std::printf("[          ] inlet reported open %.3f s after the terminal fell silent (watchdog %.2f s)\n", open_s,
              watchdog_s);
  EXPECT_TRUE(went_down);
  EXPECT_NEAR(open_s, watchdog_s, 0.03) << "open until the watchdog, shut after";
  EXPECT_EQ(truth(0).inlet_opening, 0.0) << "the emulator's watchdog shut it";
  serverA().leaveUnanswered(0);
  EXPECT_TRUE(waitFor([this] { return allUp(); }, 3.0));
  cells_[0]->write({}, 0.0);
}

TEST_F(ModbusLoopback, TheRigsSimulationRunsAtTheRealtimePriorityAskedFor) {
  // Left on the normal scheduler (the fixture's default) it says so; asked for SCHED_FIFO it
  // runs there or names the refusal, and it runs either way.
  EXPECT_EQ(emulator_->scheduling().text, "normal");
  emulator_.reset();
  options_.realtime_priority = 15;
  startEmulator();
  const nb::ThreadScheduling& s = emulator_->scheduling();
  if (s.refused) EXPECT_EQ(s.text.rfind("normal (SCHED_FIFO 15 refused: ", 0), 0u) << s.text;
  else EXPECT_EQ(s.text, "SCHED_FIFO 15");
  // Whether it keeps the wall clock's pace is a benchmark's figure (bench_modbus_latency).
  EXPECT_TRUE(waitFor([this] { return emulator_->mostPeriodsPerWake() >= 1; }, 2.0)) << "the simulation runs";
}

TEST_F(ModbusLoopback, TheRigTakesEveryCellsLoadAtOnceAndIgnoresBadOnes) {
  // One vector by cell id (the patient simulator's /airbag_loads): NaN, negative loads and ids
  // beyond the rig's cells leave those cells' loads as they were.
  const double nan = std::numeric_limits<double>::quiet_NaN();
  emulator_->setLoads({20.6, nan, -3.0, 0.6, 99.0, 99.0});
  EXPECT_DOUBLE_EQ(truth(0).load_n, 20.6);
  EXPECT_DOUBLE_EQ(truth(1).load_n, 15.6) << "NaN ignored";
  EXPECT_DOUBLE_EQ(truth(2).load_n, 15.6) << "a negative load ignored";
  EXPECT_DOUBLE_EQ(truth(3).load_n, 0.6);
  EXPECT_EQ(emulator_->truth().size(), 4u);
  emulator_->setLoads({});
  EXPECT_DOUBLE_EQ(truth(0).load_n, 20.6) << "an empty vector changes nothing";
}

namespace {

/// A terminal of one cell on 127.0.0.1: inlet coil 0, vent coil 1, pressure input 0.
nb::TerminalMap oneCoilCellTerminal(const std::string& name, int port) {
  nb::TerminalMap t;
  t.name = name;
  t.host = "127.0.0.1";
  t.port = port;
  nb::CellRegisters c;
  c.cell_id = 0;
  c.inlet = {nb::ValveOutput::kCoil, 0};
  c.vent = {nb::ValveOutput::kCoil, 1};
  c.pressure_pa.address = 0;
  c.pressure_pa.scale = 1.0;
  t.cells = {c};
  t.watchdog_s = 10.0;
  return t;
}

/// A rig server of that terminal, its coils' on-time taken so far, and a client connected.
struct OneCellServer {
  OneCellServer(const std::string& name, int port)
      : server(oneCoilCellTerminal(name, port)), client(modbus_new_tcp("127.0.0.1", port)) {
    connected = modbus_connect(client) == 0;
    server.takeCoilDuty(1.0);
  }
  ~OneCellServer() {
    modbus_close(client);
    modbus_free(client);
  }
  nb::RigTerminalServer server;
  modbus_t* client;
  bool connected = false;
};

}  // namespace

TEST(RigEmulator, AValvePassesItsCoilsOnTimeNotTheSampledState) {
  // A client pulses coil 0 (on 4 ms, off 8 ms, not in step with anything): the valve is open
  // for the time the coil was on between two takes, whatever its state at the take.
  OneCellServer rig("pulsed", 15613);
  ASSERT_TRUE(rig.connected);
  nb::RigTerminalServer& server = rig.server;
  modbus_t* client = rig.client;
  using Clock = std::chrono::steady_clock;
  auto seconds = [](Clock::duration d) { return std::chrono::duration<double>(d).count(); };
  // Each edge acts somewhere between its request leaving and its reply arriving, so the
  // server's on-time of a pulse lies between these two client-side bounds.
  double on_min_s = 0.0;
  double on_max_s = 0.0;
  const auto start = Clock::now();
  for (int k = 0; k < 40; ++k) {
    const auto on_sent = Clock::now();
    ASSERT_EQ(modbus_write_bit(client, 0, 1), 1);
    const auto on_acked = Clock::now();
    std::this_thread::sleep_for(std::chrono::milliseconds(4));
    const auto off_sent = Clock::now();
    ASSERT_EQ(modbus_write_bit(client, 0, 0), 1);
    const auto off_acked = Clock::now();
    on_min_s += seconds(off_sent - on_acked);
    on_max_s += seconds(off_acked - on_sent);
    std::this_thread::sleep_for(std::chrono::milliseconds(8));
  }
  const double total_s = seconds(Clock::now() - start);
  const std::vector<double> duty = server.takeCoilDuty(total_s);
  ASSERT_EQ(duty.size(), 2u);
  const double served_on_s = duty[0] * total_s;
  EXPECT_GE(served_on_s, on_min_s - 1e-6) << "of " << total_s << " s";
  EXPECT_LE(served_on_s, on_max_s + 1e-6) << "of " << total_s << " s";
  // Far from the sampled state's share: the coil is on about a third of the time.
  EXPECT_GT(served_on_s, 0.2 * total_s);
  EXPECT_EQ(duty[1], 0.0);
}

TEST(RigEmulator, ACoilsOnTimeIsPassedWholeWhateverTheSpansItIsTakenOver) {
  // The emulator's wakes run whole periods while the wall time between them varies: a coil on
  // through a 30 ms window taken over a 10 ms span is open for all of that span and passes the
  // rest over the next spans, so that the gas follows the coil's real on-time.
  OneCellServer rig("carried", 15614);
  ASSERT_TRUE(rig.connected);
  nb::RigTerminalServer& server = rig.server;
  modbus_t* client = rig.client;
  const double on_before_s = server.coilOnSeconds(0);
  ASSERT_EQ(modbus_write_bit(client, 0, 1), 1);
  std::this_thread::sleep_for(std::chrono::milliseconds(30));
  ASSERT_EQ(modbus_write_bit(client, 0, 0), 1);
  const double on_s = server.coilOnSeconds(0) - on_before_s;
  const std::vector<double> first = server.takeCoilDuty(0.01);
  EXPECT_EQ(first[0], 1.0) << "open through the whole span";
  double passed_s = first[0] * 0.01;
  // 5 ms spans until the on-time is passed (a loaded machine's 30 ms sleep may last 120 ms).
  for (int k = 0; k < 1000 && passed_s < on_s - 1e-9; ++k) passed_s += server.takeCoilDuty(0.005)[0] * 0.005;
  std::printf("[          ] coil on %.4f s, passed %.4f s\n", on_s, passed_s);
  EXPECT_GT(on_s, 0.029);
  EXPECT_NEAR(passed_s, on_s, 1e-9) << "all of the on-time, none twice";
  EXPECT_LT(server.takeCoilDuty(0.005)[0], 1e-12) << "and nothing after (rounding aside)";
}

TEST(RigEmulator, ListensOnLoopbackOnly) {
  nb::TerminalMap t;
  t.name = "outside";
  t.host = "192.168.1.5";
  t.port = 15612;
  try {
    nb::RigTerminalServer server(t);
    FAIL() << "accepted";
  } catch (const std::runtime_error& e) {
    nb::test::expectContains(e.what(), {"outside", "127.0.0.1", "192.168.1.5"});
  }
}

namespace {

nb::RigFaultRequest faultRequest(const std::string& fault, std::vector<std::uint32_t> ids, double value = 0.0) {
  nb::RigFaultRequest r;
  r.fault = fault;
  r.cell_ids = std::move(ids);
  r.value = value;
  return r;
}

}  // namespace

TEST_F(ModbusLoopback, AnOffsetOrFrozenSensorShowsInTheReadingsOfItsCellsOnly) {
  std::string applied;
  ASSERT_TRUE(emulator_->inject(faultRequest("sensor_offset", {0}, 2000.0), &applied).ok());
  EXPECT_EQ(applied, "sensor_offset on cells 0");
  ASSERT_TRUE(
      waitFor([&] { return cells_[0]->read(0.0).gauge_pressure_pa.value > truth(0).gauge_pressure_pa + 1900.0; }, 2.0));
  EXPECT_NEAR(cells_[1]->read(0.0).gauge_pressure_pa.value, truth(1).gauge_pressure_pa, 40.0) << "cell 1 untouched";
  ASSERT_TRUE(emulator_->inject(faultRequest("frozen_sensor", {2}), &applied).ok());
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  const double frozen = cells_[2]->read(0.0).gauge_pressure_pa.value;
  emulator_->setLoad(2, 40.0);  // the cell's pressure moves; its reading must not
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  EXPECT_EQ(cells_[2]->read(0.0).gauge_pressure_pa.value, frozen);
  EXPECT_GT(std::fabs(truth(2).gauge_pressure_pa - frozen), 500.0);
  ASSERT_TRUE(emulator_->inject(faultRequest("clear", {0, 2})).ok());
  EXPECT_TRUE(waitFor([&] { return std::fabs(cells_[2]->read(0.0).gauge_pressure_pa.value - frozen) > 500.0; }, 2.0));
  EXPECT_EQ(emulator_->faults(0).offset_pa, 0.0);
}

TEST_F(ModbusLoopback, ARestartSilencesTheTerminalAndEmptiesItsCellsOrKeepsThem) {
  const double kept_before = truth(2).gas_mass_kg;
  nb::RigFaultRequest keep = faultRequest("restart", {2}, 0.5);
  keep.keep_gas = true;
  ASSERT_TRUE(emulator_->inject(keep).ok());
  EXPECT_NEAR(truth(2).gas_mass_kg, kept_before, 1e-3 * kept_before);
  ASSERT_TRUE(emulator_->inject(faultRequest("restart", {0}, 0.5)).ok());
  EXPECT_GT(truth(0).height_m, 0.04) << "emptied only once its terminal is silent";
  ASSERT_TRUE(waitFor([this] { return cellsRead(nb::LinkState::kDown, 0, 2); }, 2.0));
  EXPECT_TRUE(waitFor([this] { return truth(0).height_m < 1e-3; }, 1.0)) << "emptied: flat";
  EXPECT_GT(truth(1).height_m, 0.04) << "a cell not named keeps its gas";
  EXPECT_TRUE(waitFor([this] { return allUp(); }, 3.0)) << "back after the silence";
}

TEST_F(ModbusLoopback, ABadFaultRequestIsRefusedNamingWhatIsWrongAndChangesNothing) {
  const struct {
    nb::RigFaultRequest request;
    const char* says;
  } bad[] = {
      {faultRequest("melt", {0}), "unknown fault 'melt' (one of clear,"},
      {faultRequest("sensor_offset", {9}, 100.0), "cell 9 is not served"},
      {faultRequest("sensor_offset", {0}, 1e9), "sensor_offset value"},
      {faultRequest("sensor_offset", {0}, std::nan("")), "sensor_offset value"},
      {faultRequest("leak", {0}, -1e-8), "leak value must be an area"},
      {faultRequest("stuck_open", {0}), "valve must be inlet or vent"},
      {faultRequest("drop_replies", {0}, 1.5), "probability in [0, 1]"},
      {faultRequest("delay_replies", {0}, 0.5), "delay_s must lie in"},
      {faultRequest("restart", {0}, 1e6), "restart value"},
  };
  for (const auto& b : bad) {
    const nb::Status s = emulator_->inject(b.request);
    EXPECT_FALSE(s.ok()) << b.says;
    EXPECT_NE(s.message().find(b.says), std::string::npos) << s.message();
  }
  nb::RigFaultRequest both = faultRequest("leak", {0}, 5e-8);
  both.random_cells = 2;
  EXPECT_NE(emulator_->inject(both).message().find("not both"), std::string::npos);
  const nb::CellFaults f = emulator_->faults(0);
  EXPECT_EQ(f.stuck_inlet + f.stuck_vent, -2);
  EXPECT_FALSE(f.frozen);
  EXPECT_EQ(f.offset_pa + f.leak_area_m2, 0.0);
  EXPECT_TRUE(allUp());
}

TEST(ModbusLossyLink, WriteRunsThatLandBeforeOneIsDroppedAreInTheDrivenRecord) {
  // Inlets and vents in separate coil blocks (two write runs a cycle), inputs in two read runs.
  // With a fifth of the requests dropped (the link stays up) a cycle often lands its inlet run
  // and loses its vent run: the terminal then drives the new inlet while the cycle failed. The
  // driven record must follow what landed, run by run (taken as the cycle's failure, it missed
  // 18 % of the inlet's on-time).
  const auto dir = nb::test::freshTestDir("rig", "lossy_runs");
  const std::string map_path = nb::test::writeFile(dir / "map.yaml", R"(
terminals:
  - name: runs
    host: 127.0.0.1
    port: 15616
    cycle_s: 0.005
    supply_pressure: {input_register: 100, scale_pa: 1.0, offset_pa: -10000.0}
    cell_block: {first_cell: 0, count: 2, valves: coil, inlet_start: 0, vent_start: 100,
                 pressure_start: 0, pressure_scale_pa: 1.0, pressure_offset_pa: -10000}
)");
  const nb::RegisterMap map = nb::loadRegisterMap(map_path, 2);
  nb::RigEmulatorOptions options;
  options.cell.initial_height_m = 0.05;
  options.cell.load_n = 15.6;
  nb::RigEmulator emulator(map, options);
  nb::HardwareConfig config;
  config.cell_id = 0;
  config.control_period_s = 0.02;
  config.register_map_path = map_path;
  config.bed_cells = 2;
  nb::ModbusTcpCellHardware cell;
  cell.configure(config);
  ASSERT_TRUE(waitFor([&] { return cell.read(0.0).link == nb::LinkState::kOk; }, 3.0));
  nb::RigTerminalServer& server = *emulator.servers().at(0);
  const double on_before_s = server.coilOnSeconds(0);
  double driven_s = 0.0;
  auto last = std::chrono::steady_clock::now();
  // Every read goes through here: a read hands out the on-time since the one before, as a mean
  // over that span.
  nb::LinkState link = nb::LinkState::kDown;
  auto read = [&] {
    const auto now = std::chrono::steady_clock::now();
    const nb::CellReadings r = cell.read(0.0);
    if (r.inlet_driven.present()) driven_s += r.inlet_driven.value * std::chrono::duration<double>(now - last).count();
    last = now;
    link = r.link;
  };
  server.setReplyFaults(0.2, 0.0, 0.0, 11);
  // The inlet on for three writes in six: each command stays current longer than a dropped
  // request's timeout, so a driver busy with a retry still sends some (one write in three could
  // fall between its cycles every time and the inlet never open).
  for (int i = 0; i < 150; ++i) {
    cell.write({i % 6 < 3 ? 1.0 : 0.0, 0.0, false}, 0.0);
    std::this_thread::sleep_for(std::chrono::milliseconds(17));
    read();
  }
  server.setReplyFaults(0.0, 0.0, 0.0, 11);
  ASSERT_TRUE(waitFor(
      [&] {
        read();
        return link == nb::LinkState::kOk;
      },
      3.0));
  cell.write({}, 0.0);
  for (int i = 0; i < 20; ++i) {  // shut on both sides
    std::this_thread::sleep_for(std::chrono::milliseconds(15));
    read();
  }
  const double on_s = server.coilOnSeconds(0) - on_before_s;
  std::printf(
      "[          ] a fifth of the requests dropped: inlet on %.4f s at the terminal, %.4f s in the driven "
      "record\n",
      on_s, driven_s);
  EXPECT_GT(on_s, 0.1) << "the inlet pulsed";
  EXPECT_NEAR(driven_s, on_s, std::max(0.01, 0.05 * on_s));
}

TEST(RigFaults, AStuckValveOrALeakChangesWhatTheValvesPass) {
  nb::CellFaults f;
  const nb::ValveOpenings cmd{0.3, 0.0, false};
  EXPECT_EQ(f.apply(cmd, 1.5e-5).inlet, 0.3);
  f.stuck_inlet = 0;
  f.stuck_vent = 1;
  EXPECT_EQ(f.apply(cmd, 1.5e-5).inlet, 0.0);
  EXPECT_EQ(f.apply(cmd, 1.5e-5).vent, 1.0);
  nb::CellFaults leak;
  leak.leak_area_m2 = 5e-8;
  EXPECT_NEAR(leak.apply(cmd, 1.5e-5).vent, 5e-8 / 1.5e-5, 1e-15);
}

TEST(RigFaults, RandomCellsAreDrawnReproduciblyBySeed) {
  const std::vector<std::uint32_t> served{0, 1, 2, 3, 4, 5, 6, 7, 8, 9};
  nb::RigFaultRequest r;
  r.fault = "leak";
  r.value = 5e-8;
  r.random_cells = 5;
  nb::RigFaultKind kind{};
  ASSERT_TRUE(nb::checkRigFault(r, served, 1.5e-5, &kind).ok());
  EXPECT_EQ(kind, nb::RigFaultKind::kLeak);
  std::mt19937 a(42), b(42), c(43);
  const auto first = nb::rigFaultCells(r, served, &a);
  EXPECT_EQ(first.size(), 5u);
  EXPECT_EQ(first, nb::rigFaultCells(r, served, &b));
  EXPECT_NE(first, nb::rigFaultCells(r, served, &c));
  r.random_cells = 0;
  EXPECT_EQ(nb::rigFaultCells(r, served, &a), served) << "no cells named: every cell";
}

TEST_F(ModbusLoopback, ALateReadGetsTheBusCyclesItSpannedWithTheirPressuresAndOnTime) {
  // A read 100 ms after the one before (a starved cell thread) is handed the bus cycles in
  // between: each with its pressure, stamped on the caller's clock, their spans tiling the
  // interval, their on-time the driven record's.
  cells_[0]->write({1.0, 0.0, false}, 0.0);
  ASSERT_TRUE(waitFor([this] { return truth(0).inlet_opening > 0.0; }, 1.0));
  cells_[0]->read(5.0);
  std::this_thread::sleep_for(std::chrono::milliseconds(40));
  cells_[0]->write({}, 0.0);
  std::this_thread::sleep_for(std::chrono::milliseconds(60));
  const nb::CellReadings r = cells_[0]->read(5.1);
  ASSERT_GE(r.bus_samples.size(), 10u) << "a cycle every 5 ms";
  double spans_s = 0.0, inlet_s = 0.0, last_s = 5.0;
  double lowest_pa = 1e9, highest_pa = -1e9;
  for (const nb::BusSample& s : r.bus_samples) {
    EXPECT_GT(s.stamp_s, last_s);
    EXPECT_LE(s.stamp_s, 5.1);
    EXPECT_NEAR(s.stamp_s - s.span_s, last_s, 1e-3) << "the spans tile the interval";
    lowest_pa = std::min(lowest_pa, s.gauge_pressure_pa);
    highest_pa = std::max(highest_pa, s.gauge_pressure_pa);
    spans_s += s.span_s;
    inlet_s += s.inlet * s.span_s;
    last_s = s.stamp_s;
  }
  EXPECT_GT(highest_pa, lowest_pa) << "each cycle its own reading, through the fill";
  EXPECT_GT(spans_s, 0.08);
  EXPECT_NEAR(r.gauge_pressure_pa.value, r.bus_samples.back().gauge_pressure_pa, 1e-9) << "the latest cycle's";
  // The read's mean is over its caller's 100 ms; the cycles' on-time up to the last one.
  EXPECT_NEAR(inlet_s, r.inlet_driven.value * 0.1, 0.01);
  EXPECT_GT(inlet_s, 0.025) << "open for the first 40 ms, and a PWM frame more";
  EXPECT_TRUE(r.bus_samples.back().inlet < 1e-9) << "shut by the end";
}
