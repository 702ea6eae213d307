// Cost of one simulated cell-second at the default step (doc/benchmarks.md).
#include <benchmark/benchmark.h>

#include <cmath>
#include <vector>

#include "nursing_bed/core/physics/basic_effects.h"
#include "nursing_bed/core/physics/cell_model.h"
#include "nursing_bed/core/physics/paper_experiment.h"

namespace nb = nursing_bed;

namespace {

// The paper's inflation, averaged per simulated second: lift-off from a flat cell (the
// stiffest part, with sub-steps), the rise, and the pressurised end of inflation.
void BM_InflationPerCellSecond(benchmark::State& state) {
  const double load = static_cast<double>(state.range(0)) + 0.6;
  nb::CellParams params;
  nb::CellInputs in;
  in.load_n = load;
  in.inlet_opening = 1.0;
  for (auto _ : state) {
    nb::CellModel model(params);
    model.reset(load);
    model.advance(5.5, in);
    benchmark::DoNotOptimize(model.variables().height_m);
  }
  // Seconds of wall time per simulated cell-second.
  state.counters["wall_s_per_cell_s"] =
      benchmark::Counter(5.5, benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
}
BENCHMARK(BM_InflationPerCellSecond)->Arg(0)->Arg(10)->Arg(20)->Unit(benchmark::kMillisecond);

// One simulated second of a pressurised cell holding height with the valves ajar (the state a
// bed spends most of its time in), optionally with effects plugged in.
void runHold(benchmark::State& state, const std::vector<nb::CellEffectPtr>& effects) {
  nb::CellModel model{nb::CellParams{}};
  for (const auto& e : effects) model.addEffect(e);
  model.resetToEquilibrium(0.10, 15.6);
  nb::CellInputs in;
  in.load_n = 15.6;
  in.vent_opening = 0.01;
  in.inlet_opening = 0.02;
  for (auto _ : state) {
    model.advance(1.0, in);
    benchmark::DoNotOptimize(model.variables().height_m);
  }
}

void BM_HoldPerCellSecond(benchmark::State& state) { runHold(state, {}); }
BENCHMARK(BM_HoldPerCellSecond)->Unit(benchmark::kMicrosecond);

// The same with two effects plugged in (heat exchange and a leak).
void BM_HoldWithEffectsPerCellSecond(benchmark::State& state) {
  runHold(state, {std::make_shared<nb::HeatTransferEffect>(10.0), std::make_shared<nb::LeakEffect>(2e-9)});
}
BENCHMARK(BM_HoldWithEffectsPerCellSecond)->Unit(benchmark::kMicrosecond);

// One 75.5 s run replayed with prescribed inflow at 100 Hz samples: what the gap diagnosis
// repeats for each run and candidate (it was a unit test's time bound before; speed is a figure).
void BM_ReplayOfAStandardRun(benchmark::State& state) {
  const nb::TimeSeries inflow = nb::paperShapedInflow(3.4e-3, 1.0, 5.5, 0.01);
  std::vector<double> t, q;
  for (int i = 0; i <= 7550; ++i) {
    t.push_back(i * 0.01);
    q.push_back(inflow.at(i * 0.01) + (i > 6550 ? -5e-4 * std::exp(-(i - 6550) * 0.01) : 0.0));
  }
  const nb::TimeSeries replay(t, q);
  nb::CellModel model{nb::CellParams{}};
  nb::CellInputs in;
  in.load_n = 15.6;
  in.prescribed_inflow = &replay;
  for (auto _ : state) {
    model.reset(15.6);
    for (int i = 1; i <= 7550; ++i) model.advance(i * 0.01 - model.time(), in);
    benchmark::DoNotOptimize(model.variables().height_m);
  }
}
BENCHMARK(BM_ReplayOfAStandardRun)->Unit(benchmark::kMillisecond);

// One right-hand-side evaluation: the unit of cost of the integrator.
void BM_RateEvaluation(benchmark::State& state) {
  nb::CellParams params;
  nb::CellModel model(params);
  model.resetToEquilibrium(0.10, 15.6);
  nb::CellInputs in;
  in.load_n = 15.6;
  in.inlet_opening = 1.0;
  nb::CellModel::StateVector x = model.state();
  for (auto _ : state) {
    x[nb::CellModel::kHeight] += 1e-15;
    benchmark::DoNotOptimize(model.rate(0.0, x, in));
  }
}
BENCHMARK(BM_RateEvaluation);

}  // namespace

BENCHMARK_MAIN();
