// Height from pressure across the patient's loads, offline (doc/benchmarks.md, doc/real_bed.md):
// one cell per load, as real_bed.launch runs it, without the bus's real time. The cell starts
// flat with the launch's load guess (10.6 N) under its true load, is ramped to 0.10 m at the
// bed's 0.02 m/s, held, then runs three alternating 1-in-3 cycles (0.12 m high, 0.03 m low, the
// load shifting onto the high cells). Its hardware is a simulated cell without a height sensor,
// with the terminal's imperfections: pressure noise and ADC step, on/off valves pulse-width
// modulated per bus cycle (sigma-delta, as ModbusTerminal does), valve dead time, readings a bus
// cycle old; the terminal reports the pulses it drove (CellReadings::inlet_driven) and the
// supply pressure (the plant's line starts empty, unlike a running bed's; the bed's 30 kPa). Prints per
// load the RMS and worst height error (truth minus estimate) and the final estimates; the last
// line is over every load.
//
// usage: bench_observer_loads [options]   (--help lists them)
// The sensor noise and ADC step (10 Pa, 12.2 Pa) are --noise and --adc.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <string>
#include <vector>

#include "nursing_bed/core/control/airbag_cell.h"
#include "nursing_bed/core/physics/cell_params_io.h"
#include "tool_cli.h"

namespace nb = nursing_bed;

namespace {

struct Options {
  double cycle_s = 200.0;  ///< one alternating cycle (three groups) [s]
  int group = 0;           ///< the cell's group (0..2): which third of the cycle it is low
  bool pwm = true;
  bool read_delay = true;                 ///< readings one bus cycle old
  bool sensor_noise = true;               ///< pressure noise (10 Pa) and ADC step (12.2 Pa)
  bool report_driven = true;              ///< the terminal reports the pulses it drove
  bool weight_bound = true;               ///< the observer's weight bound (weight_bound_window_s)
  double observer_dead_time_s = 0.015;    ///< the observer's valve_dead_time_s (config/observer.yaml)
  double rig_dead_time_s = 0.01;          ///< the rig's valve dead time (the emulator's default)
  double trace_s = 0.0;                   ///< > 0: print truth and estimate at this interval [s]
  double noise_pa = 10.0, adc_pa = 12.2;  ///< the terminal's pressure noise sd and ADC step [Pa]
  std::vector<double> loads{0.6, 2.0, 5.0, 10.6, 15.6, 20.6, 26.0, 31.0, 37.0};
  nb::CellParams cell;  ///< the cell's parameters (--params)
};

/// kRun when the bench should run, else its exit code (help printed, or a mistake named).
int parse(int argc, char** argv, Options* o) {
  CLI::App app{
      "usage: bench_observer_loads [options]\n\n"
      "Height from pressure across the patient's loads, offline: one cell per load ramped to 0.10 m,\n"
      "held, then three alternating 1-in-3 cycles; prints per load the RMS and worst height error.",
      "bench_observer_loads"};
  nb::tools::configureApp(app);
  bool no_pwm = false, duty_only = false, no_weight_bound = false, no_noise = false, no_read_delay = false;
  std::string params_path = nb::defaultCellParamsFile();
  app.add_flag("--no-pwm", no_pwm, "valve openings as they are, not pulse-width modulated per bus cycle");
  app.add_flag("--duty-only", duty_only, "the terminal does not report its pulses (the observer takes the duty)");
  app.add_flag("--no-weight-bound", no_weight_bound, "the observer without the plate's weight bound");
  app.add_flag("--no-noise", no_noise, "no pressure noise and no ADC step");
  app.add_flag("--no-read-delay", no_read_delay, "readings of this period, not a bus cycle old");
  app.add_option("--observer-dead-time", o->observer_dead_time_s, "the observer's valve_dead_time_s [s]")
      ->check(CLI::Range(0.0, 1.0));
  app.add_option("--rig-dead-time", o->rig_dead_time_s, "the rig's valve dead time [s]")->check(CLI::Range(0.0, 1.0));
  app.add_option("--cycle-s", o->cycle_s, "one alternating cycle (three groups) [s]")
      ->check(nb::tools::positiveNumber() & CLI::Range(0.0, 1e4));
  app.add_option("--trace", o->trace_s, "print truth and estimate every S seconds")->check(CLI::Range(0.0, 1e4));
  app.add_option("--group", o->group, "the cell's group: which third of the cycle it is low")->check(CLI::Range(0, 2));
  app.add_option("--loads", o->loads, "the loads, one run each [N]")
      ->delimiter(',')
      ->check(CLI::Range(0.0, 100.0))
      ->multi_option_policy(CLI::MultiOptionPolicy::TakeLast);
  app.add_option("--noise", o->noise_pa, "the terminal's pressure noise sd [Pa]")->check(CLI::Range(0.0, 1000.0));
  app.add_option("--adc", o->adc_pa, "the terminal's ADC step [Pa]")->check(CLI::Range(0.0, 1000.0));
  double supply_pa = 30000.0;
  app.add_option("--supply", supply_pa, "the bed's supply pressure, gauge [Pa] (real_bed.launch: 30000)")
      ->check(CLI::Range(1000.0, 100000.0));
  app.add_option("--params", params_path,
                 "the cell's parameter file (default the package's default cell, config/airbag_tpu_double_100.yaml)")
      ->check(CLI::ExistingFile);
  const int parsed = nb::tools::parseCommandLine(app, argc, argv);
  if (parsed != nb::tools::kRun) return parsed;
  o->pwm = !no_pwm;
  o->report_driven = !duty_only;
  o->weight_bound = !no_weight_bound;
  o->sensor_noise = !no_noise;
  o->read_delay = !no_read_delay;
  try {
    o->cell = nb::loadCellParamsYaml(params_path);
    o->cell.supply_pressure_pa = supply_pa;
  } catch (const std::exception& e) {
    return nb::tools::reportMistake(app, app.get_name(), e.what());
  }
  return nb::tools::kRun;
}

/// The terminal between the control side and the cell: valves on/off per bus cycle with the
/// duty's remainder carried (ModbusTerminal's PWM), readings one bus cycle old.
class TerminalLikeHardware : public nb::CellHardware {
 public:
  TerminalLikeHardware(std::shared_ptr<nb::SimulatedCellHardware> plant, bool pwm, bool read_delay, bool report_driven)
      : plant_(std::move(plant)), pwm_(pwm), read_delay_(read_delay), report_driven_(report_driven) {}
  void configure(const nb::HardwareConfig&) override {}
  nb::HardwareCapabilities capabilities() const override { return {}; }
  nb::CellReadings read(double now_s) override {
    nb::CellReadings r = plant_->read(now_s);
    if (r.inflow_kg_s.present()) true_inflow_kg += r.inflow_kg_s.value * 0.005;
    r.height_m = {};
    r.inflow_kg_s = {};
    r.gas_temperature_k = {};  // the supply pressure stays: the plant's line starts empty
    old_.push_back(r);
    if (old_.size() > (read_delay_ ? 2u : 1u)) old_.pop_front();
    nb::CellReadings out = old_.front();
    if (pwm_ && report_driven_) {  // what the terminal drove over the last period
      out.inlet_driven = {driven_.inlet, now_s};
      out.vent_driven = {driven_.vent, now_s};
    }
    return out;
  }
  void write(const nb::ValveOpenings& v, double now_s) override {
    nb::ValveOpenings out = v;
    if (pwm_) {
      out.inlet = onOff(v.inlet, &carry_[0]);
      out.vent = onOff(v.vent, &carry_[1]);
    }
    driven_ = out;
    plant_->write(out, now_s);
  }
  std::string describe() const override { return "terminal-like"; }
  double true_inflow_kg = 0.0;  ///< the meter's count (for the trace)

 private:
  static double onOff(double duty, double* carry) {
    const double target = duty + *carry;
    const double on = target >= 0.5 ? 1.0 : 0.0;
    *carry = std::clamp(target - on, -1.0, 1.0);
    return on;
  }
  std::shared_ptr<nb::SimulatedCellHardware> plant_;
  bool pwm_, read_delay_, report_driven_;
  double carry_[2] = {0.0, 0.0};
  std::deque<nb::CellReadings> old_;
  nb::ValveOpenings driven_;
};

/// Height target and true load of a cell of `group` at time t: ramp to 0.10 m, hold until
/// t_alt, then alternating cycles (each group low for a third of the cycle).
struct Programme {
  double t_alt = 40.0, cycle_s = 200.0, base_load = 10.6;
  int group = 0;
  double low_m = 0.03, high_m = 0.12, rate_m_s = 0.02;
  /// The cell's phase: -1 before alternating, else 1 when its group is low.
  bool low(double t) const {
    if (t < t_alt) return false;
    const double third = cycle_s / 3.0;
    return static_cast<int>(std::floor((t - t_alt) / third)) % 3 == group;
  }
  double wanted(double t) const { return t < t_alt ? 0.10 : (low(t) ? low_m : high_m); }
  /// A low cell carries 40 % of its load; the others take the rest (1.3 times theirs); the
  /// plate's own weight (0.6 N) always. The body shifts over the 4.5 s the heights take to move
  /// (0.09 m at 0.02 m/s), not at once.
  double load(double t) const {
    if (t < t_alt) return base_load;
    const double third = cycle_s / 3.0;
    const double since = std::fmod(t - t_alt, third);
    const double shift = std::min(1.0, since / 4.5);
    const double now = loadIn(low(t)), before = loadIn(low(t - since - 1e-6) && t - since > t_alt);
    return before + (now - before) * shift;
  }
  double loadIn(bool is_low) const { return std::max(0.6, base_load * (is_low ? 0.4 : 1.3)); }
};

struct Result {
  nb::ObserverErrorStats all, hold;
  double final_truth_m = 0.0, final_estimate_m = 0.0, final_load_estimate_n = 0.0;
  double worst_at_s = 0.0;
};

/// A structure's second shape coordinate (a fold table's fold state), NaN where it has none.
template <typename State>
double foldState(const State& x, const nb::CellStructure& structure) {
  return structure.shapeDofs() > 1 ? x[nb::CellModel::kShape + 1] : NAN;
}

Result runOne(double load_n, const Options& o) {
  nb::AirbagCellParams p;
  p.cell = o.cell;
  nb::RigImperfections rig;
  rig.height_sensor = false;
  rig.adc_step_pa = o.sensor_noise ? o.adc_pa : 0.0;
  rig.valve_dead_time_s = o.rig_dead_time_s;
  auto plant = std::make_shared<nb::SimulatedCellHardware>(rig);
  nb::HardwareConfig c;
  c.control_period_s = p.control_period_s;
  c.cell = p.cell;
  c.pressure_noise_pa = o.sensor_noise ? o.noise_pa : 0.0;
  c.load_n = load_n;
  plant->configure(c);
  auto hw = std::make_shared<TerminalLikeHardware>(plant, o.pwm, o.read_delay, o.report_driven);
  nb::AirbagObserverSetup setup;
  setup.model = p.cell;
  setup.params.valve_dead_time_s = o.observer_dead_time_s;
  if (!o.weight_bound) setup.params.weight_bound_window_s = 0.0;
  nb::AirbagCell cell(p, hw, setup);
  cell.reset(10.6);  // the launch's load guess

  Programme prog;
  prog.cycle_s = o.cycle_s;
  prog.group = o.group;
  prog.base_load = load_n;
  const double t_end = prog.t_alt + 3.0 * o.cycle_s;
  double target = 0.0, obs_inflow_kg = 0.0, obs_vent_kg = 0.0, true_vent_kg = 0.0;
  Result r;
  const double dt = p.control_period_s;
  for (double t = dt; t <= t_end + 1e-9; t += dt) {
    plant->setLoad(prog.load(t));
    // The bed manager streams rate-limited targets (50 Hz).
    if (std::fmod(t + 1e-9, 0.02) < dt) {
      const double w = prog.wanted(t);
      target += std::clamp(w - target, -prog.rate_m_s * 0.02, prog.rate_m_s * 0.02);
      cell.requestHeight(std::max(target, 0.02), t);
    }
    cell.advanceTo(t);
    obs_inflow_kg += cell.observer()->variables().inflow_kg_s * dt;
    obs_vent_kg += cell.observer()->variables().vent_flow_kg_s * dt;
    true_vent_kg += plant->variables().vent_flow_kg_s * dt;
    if (o.trace_s > 0.0 && std::fmod(t + 1e-9, o.trace_s) < dt) {
      const nb::CellVariables& tv = plant->variables();
      const nb::CellEstimate e = cell.observer()->estimate();
      std::printf(
          "t %7.2f tgt %5.1f | h %6.1f est %6.1f sd %5.1f | p %7.0f est %7.0f | m %.4e est %.4e | T %5.1f est %5.1f | "
          "W %5.1f est %5.1f ctl %5.1f | in %.2f vent %.2f | cum in %.4e est %.4e | vent %.4e est %.4e p %.1f | "
          "fold %.2f est %.2f\n",
          t, 1e3 * target, 1e3 * tv.height_m, 1e3 * e.height_m, 1e3 * e.height_sd_m, tv.gauge_pressure_pa,
          e.gauge_pressure_pa, plant->model().state()[nb::CellModel::kMass], e.mass_kg, tv.temperature_k,
          e.temperature_k, plant->load(), e.load_n, cell.loadEstimate(), cell.valves().inlet, cell.valves().vent,
          hw->true_inflow_kg, obs_inflow_kg, true_vent_kg, obs_vent_kg, cell.observer()->variables().gauge_pressure_pa,
          foldState(plant->model().state(), plant->model().structure()),
          foldState(cell.observer()->state(), plant->model().structure()));
    }
    if (t < 30.0) continue;  // the bench's settling time
    const double e = plant->variables().height_m - cell.measurement().height_m;
    if (std::fabs(e) > r.all.max_abs_m) r.worst_at_s = t;
    r.all.add(e);
  }
  r.final_truth_m = plant->variables().height_m;
  r.final_estimate_m = cell.measurement().height_m;
  r.final_load_estimate_n = cell.observer()->estimate().load_n;
  return r;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  if (const int parsed = parse(argc, argv, &o); parsed != nb::tools::kRun) return parsed;
  nb::ObserverErrorStats total;
  std::printf("load_N  rms_mm  worst_mm  worst_at_s  final_truth_mm  final_est_mm  load_est_N\n");
  for (double load : o.loads) {
    const Result r = runOne(load, o);
    std::printf("%6.1f  %6.2f  %8.2f  %10.1f  %14.1f  %12.1f  %10.2f\n", load, 1e3 * r.all.rmsM(),
                1e3 * r.all.max_abs_m, r.worst_at_s, 1e3 * r.final_truth_m, 1e3 * r.final_estimate_m,
                r.final_load_estimate_n);
    std::fflush(stdout);
    total.sum_sq_m2 += r.all.sum_sq_m2;
    total.samples += r.all.samples;
    total.max_abs_m = std::max(total.max_abs_m, r.all.max_abs_m);
  }
  std::printf("all loads: RMS %.2f mm, worst %.2f mm\n", 1e3 * total.rmsM(), 1e3 * total.max_abs_m);
  return 0;
}
