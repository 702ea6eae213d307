// Command-to-valve latency over Modbus TCP (doc/benchmarks.md): a cell's write() until the
// rig emulator's valve acts on it (emulator dead time 0), for on/off (coil, PWM) and
// proportional (holding register) valves, 60 cells per terminal. Prints median and worst, and
// whether the emulator's simulation kept the wall clock's pace meanwhile.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <thread>
#include <vector>

#include "nursing_bed/core/hardware/modbus_tcp_hardware.h"
#include "nursing_bed/core/rig/rig_emulator.h"

namespace nb = nursing_bed;
using Clock = std::chrono::steady_clock;

namespace {

nb::TerminalMap terminal(int port, nb::ValveOutput::Kind kind) {
  nb::TerminalMap t;
  t.name = kind == nb::ValveOutput::kCoil ? "coils" : "registers";
  t.port = port;
  for (int k = 0; k < 60; ++k) {
    nb::CellRegisters c;
    c.cell_id = static_cast<std::uint32_t>(k);
    c.inlet = {kind, k, 1000.0};
    c.vent = {kind, 100 + k, 1000.0};
    c.pressure_pa = {k, 1.0, -10000.0};
    t.cells.push_back(c);
  }
  return t;
}

void measure(nb::ValveOutput::Kind kind, int port) {
  nb::RegisterMap map;
  map.terminals.push_back(terminal(port, kind));
  nb::RigEmulatorOptions options;
  options.cell.load_n = 15.6;
  nb::RigEmulator rig(map, options);
  auto term = nb::ModbusTerminal::shared(map.terminals[0], 0.005);
  while (!term->linkUp()) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  std::vector<double> latencies_ms;
  for (int i = 0; i < 40; ++i) {
    const std::size_t slot = static_cast<std::size_t>(i % 60);
    const auto t0 = Clock::now();
    term->command(slot, {1.0, 0.0, false});
    while (rig.truth()[slot].inlet_opening < 0.5) std::this_thread::sleep_for(std::chrono::microseconds(200));
    latencies_ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
    term->command(slot, {});
    while (rig.truth()[slot].inlet_opening > 0.5) std::this_thread::sleep_for(std::chrono::microseconds(200));
    std::this_thread::sleep_for(std::chrono::milliseconds(7));
  }
  std::sort(latencies_ms.begin(), latencies_ms.end());
  const nb::TerminalStats s = term->stats();
  std::printf(
      "%-9s command to valve: median %.1f ms, worst %.1f ms (%zu commands); %.2f read and %.2f write requests per "
      "cycle\n",
      map.terminals[0].name.c_str(), latencies_ms[latencies_ms.size() / 2], latencies_ms.back(), latencies_ms.size(),
      static_cast<double>(s.read_requests) / s.cycles, static_cast<double>(s.write_requests) / s.cycles);
  std::printf("%-9s rig simulation: %.2f periods per wake-up (1: it kept the wall clock's pace), at most %ld\n",
              map.terminals[0].name.c_str(), rig.periodsPerWake(), rig.mostPeriodsPerWake());
}

}  // namespace

int main() {
  measure(nb::ValveOutput::kCoil, 15650);
  measure(nb::ValveOutput::kHoldingRegister, 15651);
  return 0;
}
