// A simulated cell driven out of its model's range by a load the cell accepts: the plant's
// non-physical state is detected, the cell reset, and it returns to its target once the load
// is sane again.
#include <gtest/gtest.h>

#include <cmath>

#include "nursing_bed/core/control/airbag_cell.h"

namespace nb = nursing_bed;

namespace {

TEST(BrokenModel, AHugeLoadLeavesNoNonPhysicalStateAndTheCellReturnsToItsTarget) {
  nb::AirbagCellParams p;
  nb::AirbagCell cell(p);
  cell.resetToHeight(0.10, 15.6);
  double t = 0.0;
  int resets = 0;
  double min_mass = INFINITY, max_temperature = 0.0;
  auto run = [&](double until_s) {
    for (; t < until_s - 1e-9; t += 0.05) {
      cell.advanceTo(t);
      // What the bed manager does: resend the target every second (clears the model fault).
      if (std::fmod(t, 1.0) < 0.05) {
        if (cell.faults() & nb::kFaultModel) ++resets;
        cell.requestHeight(0.10, t);
      }
      min_mass = std::min(min_mass, cell.variables().mass_kg);
      max_temperature = std::max(max_temperature, cell.variables().temperature_k);
    }
  };
  run(5.0);
  ASSERT_NEAR(cell.variables().height_m, 0.10, 2e-3);
  ASSERT_EQ(cell.setLoad(999.0), "");
  run(6.0);
  ASSERT_EQ(cell.setLoad(15.6), "");
  run(36.0);
  std::printf("999 N for 1 s: %d model resets seen, least gas %.3g kg, hottest %.3g K, height %.4f m\n", resets,
              min_mass, max_temperature, cell.variables().height_m);
  EXPECT_EQ(cell.faults() & (nb::kFaultModel | nb::kFaultSensor), 0u);
  EXPECT_EQ(cell.mode(), nb::AirbagMode::kHeight);
  EXPECT_NEAR(cell.variables().height_m, 0.10, 2e-3);
  // Never a non-physical state for longer than the period that produced it.
  EXPECT_GT(min_mass, 1e-9);
  EXPECT_LT(max_temperature, 1e5);
}

}  // namespace
