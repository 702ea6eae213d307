// Height from pressure over Modbus TCP in real time (doc/benchmarks.md, doc/real_bed.md): one
// cell without a height sensor, its valves on a terminal of the rig emulator (127.0.0.1), run
// by AirbagCell at 200 Hz through a programme of fills, holds, a vent to flat and refills under
// 15.6 N (--load). Prints the emulator's truth against the estimate every 0.5 s and the RMS and worst
// height error after the first second.
//
// usage: bench_observer_modbus [--proportional] [--dead-time S] [--load N]
//   --proportional        holding-register valves instead of on/off coils (PWM)
//   --dead-time S         the observer's valve_dead_time_s (default 0.015); the emulator's is 0.01
//   --load N              the plate's load (default 15.6 N; 0.6 N: the plate alone, the bed's
//                         lightest cells)
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <string>
#include <thread>

#include "nursing_bed/core/control/airbag_cell.h"
#include "nursing_bed/core/hardware/modbus_tcp_hardware.h"
#include "nursing_bed/core/hardware/rig_emulator.h"

namespace nb = nursing_bed;
using Clock = std::chrono::steady_clock;

namespace {

struct Options {
  bool proportional = false;
  double dead_time_s = 0.015;
  double load_n = 15.6;
};

bool parse(int argc, char** argv, Options* o) {
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--proportional") {
      o->proportional = true;
    } else if ((a == "--dead-time" || a == "--load") && i + 1 < argc) {
      char* end = nullptr;
      const double v = std::strtod(argv[++i], &end);
      const bool dead_time = a == "--dead-time";
      if (*end != '\0' || !(dead_time ? (v >= 0.0 && v < 1.0) : (v >= 0.0 && v <= 100.0))) {
        std::fprintf(stderr, "bench_observer_modbus: %s wants %s, got '%s'\n", a.c_str(),
                     dead_time ? "seconds in [0, 1)" : "newtons in [0, 100]", argv[i]);
        return false;
      }
      (dead_time ? o->dead_time_s : o->load_n) = v;
    } else {
      std::fprintf(stderr, "bench_observer_modbus: unknown argument '%s'\n", a.c_str());
      return false;
    }
  }
  return true;
}

std::string writeMap(bool proportional) {
  const std::string path = "/tmp/bench_observer_modbus_map.yaml";
  const std::string valves = proportional
                                 ? "inlet: {holding_register: 0, full_scale: 1000}, vent: {holding_register: 1, full_scale: 1000}"
                                 : "inlet: {coil: 0}, vent: {coil: 1}";
  std::ofstream(path) << "terminals:\n  - {name: bench, host: 127.0.0.1, port: 15790, cycle_s: 0.005,\n"
                         "     supply_pressure: {input_register: 10, scale_pa: 1.0, offset_pa: -10000},\n"
                         "     cells: [{cell: 0, " << valves
                      << ", pressure: {input_register: 0, scale_pa: 1.0, offset_pa: -10000}}]}\n";
  return path;
}

struct Target {
  double at_s, height_m;  ///< height < 0: vent flat
};

}  // namespace

int main(int argc, char** argv) {
  Options o;
  if (!parse(argc, argv, &o)) return 2;
  const std::string map_path = writeMap(o.proportional);
  nb::RigEmulatorOptions rig;
  rig.cell.load_n = o.load_n;
  rig.cell.pressure_noise_pa = 10.0;
  rig.rig.adc_step_pa = 12.2;
  rig.rig.valve_dead_time_s = 0.01;
  nb::RigEmulator emulator(nb::loadRegisterMap(map_path, 1), rig);

  nb::HardwareConfig config;
  config.cell_id = 0;
  config.control_period_s = 0.005;
  config.register_map_path = map_path;
  config.bed_cells = 1;
  auto hardware = std::make_shared<nb::ModbusTcpCellHardware>();
  hardware->configure(config);
  nb::AirbagCellParams params;
  params.control_period_s = config.control_period_s;
  nb::AirbagObserverSetup observer;
  observer.model = params.cell;
  observer.params.valve_dead_time_s = o.dead_time_s;
  nb::AirbagCell cell(params, hardware, observer);
  std::this_thread::sleep_for(std::chrono::milliseconds(300));  // the link comes up

  const Target plan[] = {{1, 0.10}, {6, 0.02}, {11, 0.10}, {16, -1}, {21, 0.10}, {26, 0.05}, {31, 0.12}};
  const double end_s = 36.0;
  std::size_t next_target = 0;
  nb::ObserverErrorStats error;
  const Clock::time_point start = Clock::now();
  Clock::time_point tick = start;
  for (long i = 0;; ++i) {
    tick += std::chrono::microseconds(5000);
    std::this_thread::sleep_until(tick);
    const double now = std::chrono::duration<double>(Clock::now() - start).count();
    if (now > end_s) break;
    if (next_target < std::size(plan) && now >= plan[next_target].at_s) {
      const Target& t = plan[next_target++];
      if (t.height_m < 0.0) cell.requestVent(now);
      else cell.requestHeight(t.height_m, now);
    }
    cell.advanceTo(now);
    const nb::CellTruth truth = emulator.truth().at(0);
    const double e = truth.height_m - cell.measurement().height_m;
    if (now > 1.0) error.add(e);
    if (i % 100 == 0)
      std::printf("%6.2f s  truth %6.1f mm  estimate %6.1f mm  error %+6.2f mm  load estimate %5.2f N (true %.1f)\n", now,
                  1e3 * truth.height_m, 1e3 * cell.measurement().height_m, 1e3 * e, cell.load(), o.load_n);
  }
  std::printf("%s valves, valve_dead_time_s %g: height error RMS %.2f mm, worst %.2f mm\n",
              o.proportional ? "proportional" : "on/off", o.dead_time_s, 1e3 * error.rmsM(),
              1e3 * error.max_abs_m);
  return 0;
}
