// Height steps of the airbag cell against the flow-limited minimum time (doc/benchmarks.md).
// Not a speed benchmark: it measures how close the controller gets to the physical bound.
//
// usage: bench_controller [--params CELL.yaml]   (default: the built-in cell)
#include <cmath>
#include <cstdio>
#include <cstring>
#include <exception>
#include <string>

#include "nursing_bed/core/control/airbag_cell.h"
#include "nursing_bed/core/physics/cell_params_io.h"

namespace nb = nursing_bed;

int main(int argc, char** argv) {
  nb::AirbagCellParams params;
  if (argc == 3 && std::strcmp(argv[1], "--params") == 0) {
    try {
      params.cell = nb::loadCellParamsYaml(argv[2]);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "bench_controller: %s\n", e.what());
      return 2;
    }
  } else if (argc != 1) {
    std::fprintf(stderr, "usage: bench_controller [--params CELL.yaml]\n");
    return 2;
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
