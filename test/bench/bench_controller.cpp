// Height steps of the airbag cell against the flow-limited minimum time (doc/benchmarks.md).
// Not a speed benchmark: it measures how close the controller gets to the physical bound.
//
// usage: bench_controller [--params CELL.yaml] [--height-noise SD_M [--pressure-noise SD_PA] [--seeds N]]
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <string>

#include "nursing_bed/core/control/airbag_cell.h"
#include "nursing_bed/core/physics/cell_params_io.h"
#include "tool_cli.h"

namespace nb = nursing_bed;

namespace {

struct StepFigures {
  double settle_s = 0.0;     ///< last time outside the settle band
  double overshoot_m = 0.0;  ///< furthest beyond the target in the move's direction
  double final_m = 0.0;      ///< error at the end
};

/// One step from rest at `from_m` to `to_m` under `load_n`, 6 s; settled within `band_m`.
StepFigures step(const nb::AirbagCellParams& params, double load_n, double from_m, double to_m, double band_m) {
  nb::AirbagCell cell{params};
  cell.resetToHeight(from_m, load_n);
  cell.requestHeight(to_m, 0.0);
  StepFigures f;
  const double dir = to_m > from_m ? 1.0 : -1.0;
  for (double t = 0.001; t <= 6.0; t += 0.001) {
    cell.advanceTo(t);
    const double h = cell.variables().height_m;
    if (std::fabs(h - to_m) > band_m) f.settle_s = t;
    f.overshoot_m = std::max(f.overshoot_m, dir * (h - to_m));
  }
  f.final_m = cell.variables().height_m - to_m;
  return f;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "usage: bench_controller [--params CELL.yaml] [--height-noise SD_M [--pressure-noise SD_PA] [--seeds N]]\n\n"
      "Height steps of one cell against the flow-limited minimum time. With noisy readings, the worst of\n"
      "--seeds runs, settled within the larger of 1 mm and three noise sds.",
      "bench_controller"};
  nb::tools::configureApp(app);
  std::string params_path = nb::defaultCellParamsFile();
  double height_noise_m = 0.0, pressure_noise_pa = 20.0;
  int seeds = 3;
  app.add_option("--params", params_path,
                 "the cell's parameter file (default the package's default cell, config/airbag_tpu_double_100.yaml)")
      ->check(CLI::ExistingFile);
  app.add_option("--height-noise", height_noise_m, "sd of the height readings' noise [m] (default 0)")
      ->check(CLI::Range(0.0, 0.01));
  app.add_option("--pressure-noise", pressure_noise_pa,
                 "sd of the pressure readings' noise where the heights are noisy [Pa] (default 20)")
      ->check(CLI::Range(0.0, 1000.0));
  app.add_option("--seeds", seeds, "noisy runs per step, the worst reported (default 3)")->check(CLI::Range(1, 100));
  if (const int parsed = nb::tools::parseCommandLine(app, argc, argv); parsed != nb::tools::kRun) return parsed;
  nb::AirbagCellParams params;
  try {
    params.cell = nb::loadCellParamsYaml(params_path);
  } catch (const std::exception& e) {
    return nb::tools::reportMistake(app, app.get_name(), e.what());
  }
  const bool noisy = height_noise_m > 0.0;
  if (noisy) {
    params.height_noise_m = height_noise_m;
    params.pressure_noise_pa = pressure_noise_pa;
  } else {
    seeds = 1;
  }
  const double band_m = std::max(1e-3, 3.0 * height_noise_m);
  const double moves[][2] = {{0.02, 0.10}, {0.0, 0.08}, {0.05, 0.13}, {0.10, 0.11}, {0.13, 0.05}, {0.10, 0.02}};
  std::printf("load [N]  from -> to [mm]   T_min [s]  settle +-%.1f mm [s]  ratio  overshoot [mm]  final error [mm]\n",
              band_m * 1e3);
  for (double load : {5.6, 15.6, 25.6}) {
    for (const auto& m : moves) {
      const double t_min = nb::flowLimitedMinimumTime(params.cell, load, m[0], m[1]);
      StepFigures worst;
      for (int seed = 1; seed <= seeds; ++seed) {
        params.noise_seed = static_cast<std::uint32_t>(seed);
        const StepFigures f = step(params, load, m[0], m[1], band_m);
        worst.settle_s = std::max(worst.settle_s, f.settle_s);
        worst.overshoot_m = std::max(worst.overshoot_m, f.overshoot_m);
        if (std::fabs(f.final_m) > std::fabs(worst.final_m)) worst.final_m = f.final_m;
      }
      std::printf("%8.1f  %5.0f -> %5.0f  %9.3f  %19.3f  %5.2f  %14.2f  %16.2f\n", load, m[0] * 1e3, m[1] * 1e3, t_min,
                  worst.settle_s, worst.settle_s / t_min, worst.overshoot_m * 1e3, worst.final_m * 1e3);
    }
  }
  return 0;
}
