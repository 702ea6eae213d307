// Height from pressure over Modbus TCP in real time (doc/benchmarks.md, doc/real_bed.md): one
// cell without a height sensor, its valves on a terminal of the rig emulator (127.0.0.1), run
// by AirbagCell at 200 Hz (--period) through a programme of fills, holds, a vent to flat and refills under
// 15.6 N (--load). Prints the emulator's truth against the estimate every 0.5 s and the RMS and worst
// height error after the first second.
//
// usage: bench_observer_modbus [options]   (--help lists them: the programme, the plan's
//          moves, the load's sway and landing, the valves, the emulator's noise and timing,
//          the cell's parameter file, the trace)
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "nursing_bed/core/control/airbag_cell.h"
#include "nursing_bed/core/hardware/modbus_tcp_hardware.h"
#include "nursing_bed/core/physics/basic_effects.h"
#include "nursing_bed/core/physics/cell_params_io.h"
#include "nursing_bed/core/rig/rig_emulator.h"
#include "tool_cli.h"

namespace nb = nursing_bed;
using Clock = std::chrono::steady_clock;

namespace {

constexpr double kPlateWeightN = 0.6;  ///< the loading plate's own weight: no load is less [N]

struct Options {
  bool proportional = false;
  bool effects = false;    ///< leak 1e-8 m2 and heat 8 W/(m2 K) in the rig and the observer
  bool alternate = false;  ///< the alternating plan's streamed moves instead of the programme
  double dead_time_s = 0.015;
  double load_n = 15.6;
  double noise_pa = 10.0, adc_pa = 12.2, rig_dead_time_s = 0.01, rig_period_s = 0.005;
  double period_s = 0.005;     ///< the cell's control period [s]
  double seed = -1.0;          ///< < 0: the emulator's default
  double load_guess_n = -1.0;  ///< < 0: the true load (the bed's nodes start from their load_n, 10.6 N)
  double load_swing_n = 0.0;   ///< sd of the load's sway about load_n [N]
  double swing_time_s = 0.1;   ///< its correlation time [s]
  double hold_s = 0.0;         ///< > 0: one fill to 91 mm, held until then [s]
  double land_s = 0.0;         ///< > 0: the rig carries load_guess_n until then [s]
  double rate_m_s = 0.02;      ///< --alternate: the streamed targets' rate limit [m/s]
  double high_m = 0.12;        ///< --alternate: the high target [m]
  double stiffness_n_m = 0.0;  ///< the load grows by this per metre of plate above 0.1 m [N/m]
  double supply_pa = -1.0;     ///< < 0: the cell's default supply pressure [Pa]
  std::string trace_path;
  std::string params_path = nb::defaultCellParamsFile();  ///< the cell's parameter file, rig and cell
};

/// kRun when the bench should run, else its exit code (help printed, or a mistake named).
int parse(int argc, char** argv, Options* o) {
  CLI::App app{
      "usage: bench_observer_modbus [options]\n\n"
      "One cell without a height sensor, its valves on a terminal of the rig emulator (127.0.0.1), run\n"
      "by AirbagCell in real time through a programme of fills, holds, a vent to flat and refills;\n"
      "prints the emulator's truth against the estimate every 0.5 s and the RMS and worst height\n"
      "error after the first second.",
      "bench_observer_modbus"};
  nb::tools::configureApp(app);
  const auto range = [](double lo, double hi) { return CLI::Range(lo, hi); };
  app.add_flag("--proportional", o->proportional, "holding-register valves instead of on/off coils (PWM)");
  app.add_flag("--effects", o->effects,
               "a leak (1e-8 m2) and heat exchange (8 W/(m2 K)) in the emulator's cell, and the observer given them");
  app.add_flag("--alternate", o->alternate,
               "instead of the programme: the alternating plan's moves as the bed manager streams them (0.10 m, "
               "then 0.03 / --high every 20 s, rate-limited, sent at 50 Hz), 100 s");
  app.add_option("--dead-time", o->dead_time_s, "the observer's valve_dead_time_s [s]")->check(range(0.0, 1.0));
  app.add_option("--load", o->load_n, "the plate's load [N] (0.6: the plate alone)")->check(range(0.0, 100.0));
  app.add_option("--noise", o->noise_pa, "the emulator's pressure noise sd [Pa]")->check(range(0.0, 1000.0));
  app.add_option("--adc", o->adc_pa, "the emulator's ADC step [Pa]")->check(range(0.0, 1000.0));
  app.add_option("--rig-dead-time", o->rig_dead_time_s, "the emulator's valve dead time [s]")->check(range(0.0, 1.0));
  app.add_option("--rig-period", o->rig_period_s, "the emulator's simulation step [s]")
      ->check(nb::tools::positiveNumber() & range(0.0, 1.0));
  app.add_option("--seed", o->seed, "the emulator's noise seed (default the emulator's)")->check(range(0.0, 1e9));
  app.add_option("--period", o->period_s, "the cell's control period [s]")
      ->check(nb::tools::positiveNumber() & range(0.0, 1.0));
  app.add_option("--load-guess", o->load_guess_n, "the cell's load guess at reset [N] (default the true load)")
      ->check(range(0.0, 100.0));
  app.add_option("--load-swing", o->load_swing_n, "sd of a random sway of the load about --load [N]")
      ->check(range(0.0, 100.0));
  app.add_option("--swing-time", o->swing_time_s, "the sway's correlation time [s]")
      ->check(nb::tools::positiveNumber() & range(0.0, 10.0));
  app.add_option("--land", o->land_s, "the rig's cell carries --load-guess until then, then --load [s]")
      ->check(range(0.0, 3600.0));
  app.add_option("--hold", o->hold_s, "instead of the programme: fill to 91 mm at 1 s and hold until then [s]")
      ->check(range(0.0, 3600.0));
  app.add_option("--rate", o->rate_m_s, "--alternate: the streamed targets' rate limit [m/s]")->check(range(0.0, 1.0));
  app.add_option("--high", o->high_m, "--alternate: the high target [m] (0.15: a turn's raised side)")
      ->check(range(0.0, 1.0));
  app.add_option("--load-stiffness", o->stiffness_n_m,
                 "the load grows by this per metre the plate stands above 0.1 m, never under 0.6 N [N/m]")
      ->check(range(0.0, 1e4));
  app.add_option("--supply", o->supply_pa, "the supply's gauge pressure, rig and cell [Pa] (real_bed.launch: 30000)")
      ->check(range(0.0, 1e5));
  app.add_option("--params", o->params_path,
                 "the cell's parameter file, rig and cell (default the package's default cell, "
                 "config/airbag_tpu_double_100.yaml)")
      ->check(CLI::ExistingFile);
  app.add_option("--trace", o->trace_path,
                 "every period as CSV: the emulator's gas beside the observer's, the pressure read, the "
                 "controller's predicted rest height, the count's doubt and the height's sd");
  return nb::tools::parseCommandLine(app, argc, argv);
}

std::string writeMap(bool proportional) {
  const std::string path = "/tmp/bench_observer_modbus_map.yaml";
  const std::string valves =
      proportional ? "inlet: {holding_register: 0, full_scale: 1000}, vent: {holding_register: 1, full_scale: 1000}"
                   : "inlet: {coil: 0}, vent: {coil: 1}";
  std::ofstream(path) << "terminals:\n  - {name: bench, host: 127.0.0.1, port: 15790, cycle_s: 0.005,\n"
                         "     supply_pressure: {input_register: 10, scale_pa: 1.0, offset_pa: -10000},\n"
                         "     cells: [{cell: 0, "
                      << valves << ", pressure: {input_register: 0, scale_pa: 1.0, offset_pa: -10000}}]}\n";
  return path;
}

void traceHeader(std::FILE* f) {
  std::fprintf(f,
               "t_s,true_h_m,true_p_pa,true_m_kg,true_t_k,true_in_kg_s,true_vent_kg_s,true_inlet,true_vent,"
               "est_h_m,read_p_pa,est_m_kg,est_t_k,est_in_kg_s,est_vent_kg_s,est_inlet,est_vent,rest_h_m,count_doubt_m,"
               "height_sd_m\n");
}

void traceRow(std::FILE* f, double t, const nb::CellTruth& truth, const nb::AirbagCell& cell) {
  const nb::CellObserver& obs = *cell.observer();
  const nb::CellEstimate e = obs.estimate();
  const nb::CellVariables& v = obs.variables();
  std::fprintf(
      f, "%.4f,%.6f,%.2f,%.8e,%.3f,%.6e,%.6e,%.3f,%.3f,%.6f,%.2f,%.8e,%.3f,%.6e,%.6e,%.3f,%.3f,%.6f,%.6f,%.6f\n", t,
      truth.height_m, truth.gauge_pressure_pa, truth.gas_mass_kg, truth.temperature_k, truth.inflow_kg_s,
      truth.vent_flow_kg_s, truth.inlet_opening, truth.vent_opening, e.height_m, cell.measurement().gauge_pressure_pa,
      e.mass_kg, e.temperature_k, v.inflow_kg_s, v.vent_flow_kg_s, obs.appliedInputs().valves.inlet,
      obs.appliedInputs().valves.vent, cell.controller().restingHeight(), e.count_doubt_m, e.height_sd_m);
}

struct Target {
  double at_s, height_m;  ///< height < 0: vent flat
};

/// The load a patient's part puts on one cell: a sway about the mean (Ornstein-Uhlenbeck).
class LoadSway {
 public:
  LoadSway(double mean_n, double sd_n, double time_s) : mean_n_(mean_n), sd_n_(sd_n), time_s_(time_s), rng_(7) {}
  double next(double dt_s) {
    const double a = std::exp(-dt_s / time_s_);
    sway_n_ = a * sway_n_ + sd_n_ * std::sqrt(1.0 - a * a) * normal_(rng_);
    return std::max(0.0, mean_n_ + sway_n_);
  }

 private:
  double mean_n_, sd_n_, time_s_, sway_n_ = 0.0;
  std::mt19937 rng_;
  std::normal_distribution<double> normal_{0.0, 1.0};
};

/// The emulator's cell: the bench's cell parameters, load (the guess until the patient lands),
/// noise, ADC, timing and hidden effects.
nb::RigEmulatorOptions rigOptions(const Options& o, const nb::CellParams& cell, double guess_n,
                                  const std::vector<nb::CellEffectPtr>& effects) {
  nb::RigEmulatorOptions rig;
  rig.cell.cell = cell;
  rig.cell.load_n = o.land_s > 0.0 ? guess_n : o.load_n;
  rig.cell.pressure_noise_pa = o.noise_pa;
  rig.rig.adc_step_pa = o.adc_pa;
  rig.rig.valve_dead_time_s = o.rig_dead_time_s;
  rig.period_s = o.rig_period_s;
  rig.cell.effects = effects;
  if (o.seed >= 0.0) rig.cell.noise_seed = static_cast<unsigned>(o.seed);
  return rig;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  if (const int parsed = parse(argc, argv, &o); parsed != nb::tools::kRun) return parsed;
  nb::AirbagCellParams params;
  try {
    params.cell = nb::loadCellParamsYaml(o.params_path);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_observer_modbus: %s\n", e.what());
    return nb::tools::kExitBadArguments;
  }
  if (o.supply_pa >= 0.0) params.cell.supply_pressure_pa = o.supply_pa;
  const std::string map_path = writeMap(o.proportional);
  const double guess_n = o.load_guess_n >= 0.0 ? o.load_guess_n : o.load_n;
  std::vector<nb::CellEffectPtr> effects;
  if (o.effects) effects = {std::make_shared<nb::LeakEffect>(1e-8), std::make_shared<nb::HeatTransferEffect>(8.0)};
  const nb::RigEmulatorOptions rig = rigOptions(o, params.cell, guess_n, effects);
  nb::RigEmulator emulator(nb::loadRegisterMap(map_path, 1), rig);

  nb::HardwareConfig config;
  config.cell_id = 0;
  config.control_period_s = o.period_s;
  config.register_map_path = map_path;
  config.bed_cells = 1;
  auto hardware = std::make_shared<nb::ModbusTcpCellHardware>();
  hardware->configure(config);
  params.control_period_s = config.control_period_s;
  nb::AirbagObserverSetup observer;
  observer.model = params.cell;
  observer.params.valve_dead_time_s = o.dead_time_s;
  observer.effects = effects;
  nb::AirbagCell cell(params, hardware, observer);
  cell.reset(guess_n);
  std::this_thread::sleep_for(std::chrono::milliseconds(300));  // the link comes up
  std::FILE* trace = o.trace_path.empty() ? nullptr : std::fopen(o.trace_path.c_str(), "w");
  if (!o.trace_path.empty() && !trace) {
    std::fprintf(stderr, "bench_observer_modbus: cannot write the trace '%s'\n", o.trace_path.c_str());
    return 2;
  }
  if (trace) traceHeader(trace);

  const std::vector<Target> plan =
      o.hold_s > 0.0 ? std::vector<Target>{{1, 0.091}}
      : o.alternate
          ? std::vector<Target>{{1, 0.10}, {20, 0.03}, {40, o.high_m}, {60, 0.03}, {80, o.high_m}}
          : std::vector<Target>{{1, 0.10}, {6, 0.02}, {11, 0.10}, {16, -1}, {21, 0.10}, {26, 0.05}, {31, 0.12}};
  const double end_s = o.hold_s > 0.0 ? o.hold_s : o.alternate ? 100.0 : 36.0;
  double wanted_m = 0.0, streamed_m = 0.0, next_stream_s = 0.0;  // --alternate: the bed manager's stream
  LoadSway sway(o.load_n, o.load_swing_n, o.swing_time_s);
  double truth_height_m = 0.0;  // the plate's last true height (--load-stiffness)
  double rig_load_n = rig.cell.load_n;
  std::size_t next_target = 0;
  nb::ObserverErrorStats error;
  const Clock::time_point start = Clock::now();
  Clock::time_point tick = start;
  for (long i = 0;; ++i) {
    tick += std::chrono::microseconds(std::lround(1e6 * o.period_s));
    std::this_thread::sleep_until(tick);
    const double now = std::chrono::duration<double>(Clock::now() - start).count();
    if (now > end_s) break;
    // The guess until the patient lands, then the load (swaying where asked); sent on change.
    const double carried = now < o.land_s ? guess_n : o.load_swing_n > 0.0 ? sway.next(o.period_s) : o.load_n;
    const double load =
        o.stiffness_n_m > 0.0 ? std::max(kPlateWeightN, carried + o.stiffness_n_m * (truth_height_m - 0.1)) : carried;
    if (load != rig_load_n) emulator.setLoad(0, rig_load_n = load);
    if (next_target < plan.size() && now >= plan[next_target].at_s) {
      const Target& t = plan[next_target++];
      if (o.alternate) wanted_m = t.height_m;
      else if (t.height_m < 0.0) cell.requestVent(now);
      else cell.requestHeight(t.height_m, now);
    }
    if (o.alternate && now >= next_stream_s && wanted_m > 0.0) {
      next_stream_s = now + 0.02;
      streamed_m += std::clamp(wanted_m - streamed_m, -o.rate_m_s * 0.02, o.rate_m_s * 0.02);
      cell.requestHeight(std::max(streamed_m, 0.02), now);
    }
    cell.advanceTo(now);
    const nb::CellTruth truth = emulator.truth().at(0);
    truth_height_m = truth.height_m;
    const double e = truth.height_m - cell.measurement().height_m;
    if (now > 1.0) error.add(e);
    if (trace && cell.observer()) traceRow(trace, now, truth, cell);
    if (i % std::max(1L, std::lround(0.5 / o.period_s)) == 0)
      std::printf("%6.2f s  truth %6.1f mm  estimate %6.1f mm  error %+6.2f mm  load estimate %5.2f N (true %.1f)\n",
                  now, 1e3 * truth.height_m, 1e3 * cell.measurement().height_m, 1e3 * e, cell.load(), o.load_n);
  }
  if (trace) std::fclose(trace);
  std::printf("%s valves, valve_dead_time_s %g: height error RMS %.2f mm, worst %.2f mm\n",
              o.proportional ? "proportional" : "on/off", o.dead_time_s, 1e3 * error.rmsM(), 1e3 * error.max_abs_m);
  return 0;
}
