// Height steps of the airbag cell against the flow-limited minimum time (doc/benchmarks.md).
// Not a speed benchmark: it measures how close the controller gets to the physical bound.
//
// usage: bench_controller [--params CELL.yaml]   (default: the built-in cell)
#include <cmath>
#include <cstdio>
#include <exception>
#include <string>

#include "nursing_bed/core/control/airbag_cell.h"
#include "nursing_bed/core/physics/cell_params_io.h"
#include "tool_cli.h"

namespace nb = nursing_bed;

int main(int argc, char** argv) {
  CLI::App app{
      "usage: bench_controller [--params CELL.yaml]\n\nHeight steps of one cell against the flow-limited minimum time.",
      "bench_controller"};
  nb::tools::configureApp(app);
  std::string params_path;
  app.add_option("--params", params_path, "the cell's parameter file (default the built-in cell)")
      ->check(CLI::ExistingFile);
  if (const int parsed = nb::tools::parseCommandLine(app, argc, argv); parsed != nb::tools::kRun) return parsed;
  nb::AirbagCellParams params;
  try {
    if (!params_path.empty()) params.cell = nb::loadCellParamsYaml(params_path);
  } catch (const std::exception& e) {
    return nb::tools::reportMistake(app, app.get_name(), e.what());
  }
  const double moves[][2] = {{0.02, 0.10}, {0.0, 0.08}, {0.05, 0.13}, {0.10, 0.11}, {0.13, 0.05}, {0.10, 0.02}};
  std::printf("load [N]  from -> to [mm]   T_min [s]  settle +-1 mm [s]  ratio  overshoot [mm]  final error [mm]\n");
  for (double load : {5.6, 15.6, 25.6}) {
    for (const auto& m : moves) {
      nb::AirbagCell cell{params};
      const double t_min = nb::flowLimitedMinimumTime(cell.params().cell, load, m[0], m[1]);
      cell.resetToHeight(m[0], load);
      cell.requestHeight(m[1], 0.0);
      double settle = 0.0, overshoot = 0.0;
      const double dir = m[1] > m[0] ? 1.0 : -1.0;
      for (double t = 0.001; t <= 6.0; t += 0.001) {
        cell.advanceTo(t);
        const double h = cell.variables().height_m;
        if (std::fabs(h - m[1]) > 1e-3) settle = t;
        overshoot = std::max(overshoot, dir * (h - m[1]));
      }
      std::printf("%8.1f  %5.0f -> %5.0f  %9.3f  %17.3f  %5.2f  %14.2f  %16.2f\n", load, m[0] * 1e3, m[1] * 1e3, t_min,
                  settle, settle / t_min, overshoot * 1e3, (cell.variables().height_m - m[1]) * 1e3);
    }
  }
  return 0;
}
