// The folded flat cell through the whole cell (plant, safety layer and height controller): CPR
// empties a cell onto its folded films and a height request lifts it off again, under every
// load from the plate alone to 40 N; loads up to the largest a cell accepts, stepped at once or
// ramped, keep the gas and the plate physical, and the cell recovers once the load is normal.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>

#include "nursing_bed/core/control/airbag_cell.h"
#include "nursing_bed/core/physics/cell_params_io.h"

namespace nb = nursing_bed;

namespace {

constexpr double kPeriodS = 0.005;
constexpr double kTargetM = 0.10;
constexpr double kNearM = 0.002;  // "at its target": within 2 mm
// The lowest the plate may go: the folded films and the bed compress ~0.5 mm under 1000 N at
// rest and ~1.6 mm as a plate carrying it lands; -5 to -12 mm went through them.
constexpr double kBedM = -0.002;
// On the FE fold table the squeezed bag's gas bulges out beside the plate and hardly cushions a
// landing (18 kPa under 1000 N against the pillow's 37): the 102 kg a 1000 N load moves, put on
// at once at 100 mm, lands at 1.3 m/s (on the pillow 0.85 m/s) and presses the films and bed
// 2.0-2.1 mm (the pillow 1.6 mm).
constexpr double kFoldTableBedM = -0.0025;

/// Extremes of the gas and the plate over a run.
struct Extremes {
  double t_min_k = std::numeric_limits<double>::infinity();
  double t_max_k = -std::numeric_limits<double>::infinity();
  double p_max_pa = -std::numeric_limits<double>::infinity();
  double p_min_pa = std::numeric_limits<double>::infinity();
  double h_min_m = std::numeric_limits<double>::infinity();
  double h_max_m = -std::numeric_limits<double>::infinity();
  double mass_min_kg = std::numeric_limits<double>::infinity();
  int outside_limits = 0;  // periods the bag spent beyond its film's limits (CellStructure)

  void add(const nb::CellModel& model) {
    const nb::CellVariables& v = model.variables();
    outside_limits += model.structure().withinLimits(v.height_m, v.shape.data()) ? 0 : 1;
    t_min_k = std::min(t_min_k, v.temperature_k);
    t_max_k = std::max(t_max_k, v.temperature_k);
    p_max_pa = std::max(p_max_pa, v.gauge_pressure_pa);
    p_min_pa = std::min(p_min_pa, v.gauge_pressure_pa);
    h_min_m = std::min(h_min_m, v.height_m);
    h_max_m = std::max(h_max_m, v.height_m);
    mass_min_kg = std::min(mass_min_kg, v.mass_kg);
  }
};

/// One default cell (simulated plant with its sensors) stepped a control period at a time.
class Rig {
 public:
  explicit Rig(const nb::AirbagCellParams& params = {}) : cell_(params) {}
  nb::AirbagCell& cell() { return cell_; }
  const nb::CellVariables& vars() const { return cell_.variables(); }
  Extremes& extremes() { return extremes_; }

  void run(double duration_s) {
    const double end = cell_.time() + duration_s;
    while (cell_.time() < end - 1e-9) period();
  }
  void period() {
    cell_.advanceTo(cell_.time() + kPeriodS);
    extremes_.add(cell_.model());
  }
  /// Runs until the plate is within kNearM of `target_m` (and stays so for 0.5 s), at most
  /// `limit_s`; returns the time taken (infinity when it never got there).
  double runUntilAt(double target_m, double limit_s) {
    const double start = cell_.time();
    double since = std::numeric_limits<double>::quiet_NaN();
    while (cell_.time() - start < limit_s) {
      period();
      const bool near = std::fabs(vars().height_m - target_m) <= kNearM;
      if (!near) since = std::numeric_limits<double>::quiet_NaN();
      if (near && std::isnan(since)) since = cell_.time();
      if (near && cell_.time() - since >= 0.5) return since - start;
    }
    return std::numeric_limits<double>::infinity();
  }

 private:
  nb::AirbagCell cell_;
  Extremes extremes_;
};

/// Time the rate limit allows a cell to rise `distance_m` (the bed manager ramps its targets at
/// safety.max_height_rate_m_s).
double rateLimitedTime(const nb::AirbagCell& cell, double distance_m) {
  return distance_m / cell.params().safety.max_height_rate_m_s;
}

/// The cells the flat-cell tests run on: the default one and the FE fold-table cell.
nb::AirbagCellParams cellParams(const std::string& file) {
  nb::AirbagCellParams params;
  if (!file.empty()) params.cell = nb::loadCellParamsYaml(std::string(NURSING_BED_SOURCE_DIR) + "/config/" + file);
  return params;
}

struct CprCase {
  const char* cell_file;  // a file in config/; "" = the built-in cell (the reduced pillow)
  double load_n;
};

class CprCycles : public ::testing::TestWithParam<CprCase> {};

TEST_P(CprCycles, LiftOffTheFoldedCellEveryTimeWithTheGasNearRoomTemperature) {
  const double load = GetParam().load_n;
  Rig rig(cellParams(GetParam().cell_file));
  rig.cell().reset(load);
  rig.cell().requestHeight(kTargetM, 0.0);
  ASSERT_LT(rig.runUntilAt(kTargetM, 30.0), 30.0) << "the first inflation at " << load << " N";
  const double allowed_s = rateLimitedTime(rig.cell(), kTargetM);
  double worst_return_s = 0.0;
  for (int cycle = 0; cycle < 20; ++cycle) {
    rig.cell().setCpr(true, rig.cell().time());
    rig.run(8.0);  // vacuum venting: flat within a few seconds, then held flat
    ASSERT_LT(rig.vars().height_m, 0.001) << "cycle " << cycle << " at " << load << " N: not flat after CPR";
    rig.cell().setCpr(false, rig.cell().time());
    ASSERT_EQ(rig.cell().requestHeight(kTargetM, rig.cell().time()), "");
    const double back_s = rig.runUntilAt(kTargetM, 4.0 * allowed_s);
    worst_return_s = std::max(worst_return_s, back_s);
    ASSERT_LE(back_s, allowed_s) << "cycle " << cycle << " at " << load << " N: back at the target after " << back_s
                                 << " s";
  }
  const Extremes& e = rig.extremes();
  std::printf(
      "%s CPR cycles at %5.1f N: gas %.1f-%.1f K, worst return %.2f s (rate limit %.1f s), plate %.2f-%.1f mm\n",
      GetParam().cell_file, load, e.t_min_k, e.t_max_k, worst_return_s, allowed_s, e.h_min_m * 1e3, e.h_max_m * 1e3);
  EXPECT_GE(e.t_min_k, 250.0);
  EXPECT_LE(e.t_max_k, 330.0);
  EXPECT_GT(e.mass_min_kg, 0.0);
}

constexpr const char* kFoldTable = "airbag_tpu_double_100_fe3d.yaml";

INSTANTIATE_TEST_SUITE_P(FlatCell, CprCycles,
                         ::testing::Values(CprCase{"", 0.6}, CprCase{"", 5.0}, CprCase{"", 10.6}, CprCase{"", 20.6},
                                           CprCase{"", 40.0}, CprCase{kFoldTable, 0.6}, CprCase{kFoldTable, 5.0},
                                           CprCase{kFoldTable, 10.6}, CprCase{kFoldTable, 20.6},
                                           CprCase{kFoldTable, 40.0}),
                         [](const ::testing::TestParamInfo<CprCase>& info) {
                           const std::string cell = info.param.cell_file[0] ? "FoldTable" : "Pillow";
                           return cell + std::to_string(static_cast<int>(std::lround(info.param.load_n * 10))) + "dN";
                         });

struct LoadStep {
  double load_n;
  double ramp_s;               // 0: the whole load at once
  const char* cell_file = "";  // a file in config/; "" = the built-in cell (the reduced pillow)
};

class LoadSteps : public ::testing::TestWithParam<LoadStep> {};

TEST_P(LoadSteps, KeepTheGasAndPlatePhysicalAndTheCellRecovers) {
  const LoadStep step = GetParam();
  const double normal_load = 10.6;
  Rig rig(cellParams(step.cell_file));
  rig.cell().resetToHeight(kTargetM, normal_load);
  rig.run(2.0);
  rig.extremes() = Extremes{};
  // The load ramps up over ramp_s (or steps at once), is held for 1 s and ramps back alike.
  auto ramp = [&](double from, double to) {
    const int periods = static_cast<int>(std::lround(step.ramp_s / kPeriodS));
    for (int i = 1; i <= periods; ++i) {
      ASSERT_EQ(rig.cell().setLoad(from + (to - from) * i / periods), "");
      rig.period();
    }
    ASSERT_EQ(rig.cell().setLoad(to), "");
  };
  ramp(normal_load, step.load_n);
  rig.run(1.0);
  ramp(step.load_n, normal_load);
  const Extremes loaded = rig.extremes();
  const double back_s = rig.runUntilAt(kTargetM, 30.0);
  const Extremes& e = rig.extremes();
  const double relief = rig.cell().params().safety.relief_pressure_pa;
  std::printf(
      "%s load step to %6.1f N in %3.0f ms: peak %.1f kPa (relief %.0f), gas %.1f-%.1f K, plate %.2f-%.1f mm "
      "(%d periods beyond the film's limits), back at %.0f mm after %.2f s\n",
      step.cell_file, step.load_n, step.ramp_s * 1e3, loaded.p_max_pa * 1e-3, relief * 1e-3, e.t_min_k, e.t_max_k,
      e.h_min_m * 1e3, e.h_max_m * 1e3, e.outside_limits, kTargetM * 1e3, back_s);
  EXPECT_GE(e.t_min_k, 230.0);
  EXPECT_LE(e.t_max_k, 400.0);
  EXPECT_GE(e.h_min_m, step.cell_file[0] ? kFoldTableBedM : kBedM);
  EXPECT_EQ(e.outside_limits, 0);
  EXPECT_GT(e.mass_min_kg, 0.0);
  if (step.ramp_s >= 0.05) {
    EXPECT_LE(e.p_max_pa, 1.1 * relief);
  }
  EXPECT_LT(back_s, 30.0) << "the cell did not recover its target";
}

INSTANTIATE_TEST_SUITE_P(FlatCell, LoadSteps,
                         ::testing::Values(LoadStep{100.0, 0.0}, LoadStep{100.0, 0.05}, LoadStep{300.0, 0.0},
                                           LoadStep{300.0, 0.05}, LoadStep{1000.0, 0.0}, LoadStep{1000.0, 0.05},
                                           LoadStep{100.0, 0.0, kFoldTable}, LoadStep{100.0, 0.05, kFoldTable},
                                           LoadStep{300.0, 0.0, kFoldTable}, LoadStep{300.0, 0.05, kFoldTable},
                                           LoadStep{1000.0, 0.0, kFoldTable}, LoadStep{1000.0, 0.05, kFoldTable}));

TEST(FlatCell, PoundingWithTheLargestLoadLeavesTheCellWhole) {
  // The largest accepted load put on and taken off ten times, 0.3 s each: every landing on the
  // folded cell, every lift-off from it, and the cell back at its target afterwards, unflagged.
  Rig rig;
  rig.cell().resetToHeight(kTargetM, 10.6);
  rig.run(1.0);
  const double largest = rig.cell().params().safety.max_load_n;
  for (int i = 0; i < 10; ++i) {
    ASSERT_EQ(rig.cell().setLoad(largest), "");
    rig.run(0.3);
    ASSERT_EQ(rig.cell().setLoad(10.6), "");
    rig.run(0.3);
  }
  const double back_s = rig.runUntilAt(kTargetM, 30.0);
  const Extremes& e = rig.extremes();
  std::printf("pounding with %.0f N: gas %.1f-%.1f K, peak %.1f kPa, plate %.2f-%.1f mm, back after %.2f s\n", largest,
              e.t_min_k, e.t_max_k, e.p_max_pa * 1e-3, e.h_min_m * 1e3, e.h_max_m * 1e3, back_s);
  EXPECT_GE(e.t_min_k, 230.0);
  EXPECT_LE(e.t_max_k, 400.0);
  EXPECT_LE(e.p_max_pa, 1.1 * rig.cell().params().safety.relief_pressure_pa);
  EXPECT_GE(e.h_min_m, kBedM);
  EXPECT_EQ(e.outside_limits, 0);
  EXPECT_LT(back_s, 30.0);
  EXPECT_EQ(rig.cell().faults(), 0u);
}

}  // namespace
