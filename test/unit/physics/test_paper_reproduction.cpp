// The paper's experiments on our model (the physics core's targets, doc/paper_targets.md).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "nursing_bed/core/physics/cell_params_io.h"
#include "nursing_bed/core/physics/paper_experiment.h"

namespace nb = nursing_bed;

namespace {

TEST(PaperReproduction, Eq24ReadInBarMatchesThePapersRange) {
  EXPECT_NEAR(nb::paperEq24HeightM(10e3), -0.0042, 5e-4);  // ~0 mm at 10 kPa
  EXPECT_NEAR(nb::paperEq24HeightM(28e3), 0.0923, 1e-3);   // ~92 mm at 28 kPa
  // The MPa reading of the paper's text is hugely negative over its whole range.
  for (double x_mpa = 0.010; x_mpa <= 0.0221; x_mpa += 0.001)
    EXPECT_LT(nb::polyval({nb::kPaperQuarticMmVsBar.begin(), nb::kPaperQuarticMmVsBar.end()}, x_mpa), -600.0);
}

/// The paper's unloaded inflation (0.6 N plate, 20 kPa valve, inlet closed at 5.5 s) on `params`:
/// 150 mm +- 3 % at 5.5 s, the peak pressure within 5 % of the valve, the inflow peak within
/// `peak_tolerance_s` of 1 s and spent by 5.5 s. Returns the trace for the caller's own checks.
nb::InflationTrace expectThePapersUnloadedInflation(const nb::CellParams& params, double peak_tolerance_s) {
  nb::InflationSetup setup;
  setup.duration_s = 6.0;
  const nb::InflationTrace trace = nb::runInflation(params, setup);
  const nb::InflationSample* at_end = nullptr;
  double peak = 0.0;
  for (const auto& s : trace.samples) {
    if (std::abs(s.time_s - 5.5) < 1e-9) at_end = &s;
    peak = std::max(peak, s.inflow_kg_s);
  }
  EXPECT_NE(at_end, nullptr);
  if (!at_end) return trace;
  EXPECT_NEAR(at_end->height_m, 0.150, 0.03 * 0.150);
  EXPECT_NEAR(trace.maxPressurePa(), setup.valve_pressure_pa, 0.05 * setup.valve_pressure_pa);
  EXPECT_NEAR(trace.peakInflowTimeS(), 1.0, peak_tolerance_s);
  EXPECT_LT(at_end->inflow_kg_s, 0.02 * peak);       // spent by 5.5 s
  EXPECT_EQ(trace.samples.back().inflow_kg_s, 0.0);  // closed after
  EXPECT_GT(at_end->gauge_pressure_pa, 0.9 * setup.valve_pressure_pa);
  return trace;
}

TEST(PaperReproduction, UnloadedInflationMatchesThePaper) {
  const nb::InflationTrace trace = expectThePapersUnloadedInflation(nb::CellParams{}, 0.4);
  // Height and pressure both rise over the inflation (to within the plate's jitter).
  const nb::InflationSample* prev = &trace.samples.front();
  for (const auto& s : trace.samples) {
    if (s.time_s > 5.5) break;
    EXPECT_GE(s.height_m, prev->height_m - 1e-6) << "t " << s.time_s;
    EXPECT_GE(s.gauge_pressure_pa, prev->gauge_pressure_pa - 50.0) << "t " << s.time_s;
    prev = &s;
  }
}

// The FE fold-table cell (doc/cell_geometry.md), with its inlet calibrated on it.
TEST(PaperReproduction, TheFoldTableCellsUnloadedInflationMatchesThePaper) {
  const nb::CellParams params =
      nb::loadCellParamsYaml(std::string(NURSING_BED_SOURCE_DIR) + "/config/airbag_tpu_double_100_fe3d.yaml");
  const nb::InflationTrace trace = expectThePapersUnloadedInflation(params, 0.2);
  for (const auto& s : trace.samples) {
    EXPECT_GT(s.temperature_k, 285.0) << "t " << s.time_s;
    EXPECT_LT(s.temperature_k, 315.0) << "t " << s.time_s;
  }
}

TEST(PaperReproduction, LoadedHeightGrowsMonotonicallyWithPressure) {
  for (std::size_t i = 1; i < nb::kPaperLoadsN.size(); ++i) {
    nb::InflationSetup setup;
    setup.load_n = nb::kPaperLoadsN[i];
    setup.valve_pressure_pa = 22e3 + 3e3 * (i - 1);
    const nb::InflationTrace trace = nb::runInflation(nb::CellParams{}, setup);
    // Along the rising branch (each new pressure maximum) height never falls.
    double p_max = -1.0, h_at_p_max = -1.0;
    int points = 0;
    for (const auto& s : trace.samples) {
      if (s.gauge_pressure_pa > p_max) {
        EXPECT_GE(s.height_m, h_at_p_max - 1e-6) << "load " << setup.load_n << " p " << s.gauge_pressure_pa;
        p_max = s.gauge_pressure_pa;
        h_at_p_max = s.height_m;
        ++points;
      }
    }
    EXPECT_GT(points, 100);
    EXPECT_GT(trace.finalHeightM(), 0.12);
  }
}

TEST(PaperReproduction, PaperShapedInflowPeaksAtOneSecondAndEndsAt5p5) {
  const nb::TimeSeries f = nb::paperShapedInflow(3.4e-3);
  EXPECT_NEAR(f.integral(), 3.4e-3, 1e-9);
  double best = 0.0, t_best = 0.0;
  for (std::size_t i = 0; i < f.size(); ++i)
    if (f.values()[i] > best) {
      best = f.values()[i];
      t_best = f.times()[i];
    }
  EXPECT_NEAR(t_best, 1.0, 0.011);
  EXPECT_DOUBLE_EQ(f.endTime(), 5.5);
  EXPECT_NEAR(f.at(5.5), 0.0, 1e-12);
}

TEST(PaperReproduction, PolyfitRecoversAQuartic) {
  std::vector<double> x, y;
  for (int i = 0; i <= 40; ++i) {
    x.push_back(0.1 + 0.18 * i / 40.0);
    y.push_back(nb::polyval({nb::kPaperQuarticMmVsBar.begin(), nb::kPaperQuarticMmVsBar.end()}, x.back()));
  }
  const std::vector<double> c = nb::polyfit(x, y, 4);
  for (int k = 0; k < 5; ++k)
    EXPECT_NEAR(c[k], nb::kPaperQuarticMmVsBar[k], 1e-5 * std::abs(nb::kPaperQuarticMmVsBar[k]));
  EXPECT_THROW(nb::polyfit({1.0, 2.0}, {1.0, 2.0}, 4), std::invalid_argument);
}

}  // namespace
