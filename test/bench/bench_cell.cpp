// Cost of one simulated cell-second at the default step (doc/benchmarks.md).
#include <benchmark/benchmark.h>

#include "nursing_bed/core/physics/basic_effects.h"
#include "nursing_bed/core/physics/cell_model.h"

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
  state.counters["wall_s_per_cell_s"] = benchmark::Counter(
      5.5, benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
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
