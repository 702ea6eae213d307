// New tuning on a running cell (AirbagCell::retune, HeightController::retune): taken while the
// cell runs, refused whole when invalid.
#include <gtest/gtest.h>

#include <stdexcept>

#include "nursing_bed/core/control/airbag_cell.h"

namespace nb = nursing_bed;

TEST(AirbagCellRetune, NewSafetyThresholdsActOnTheRunningCell) {
  nb::AirbagCell cell{nb::AirbagCellParams{}};
  cell.resetToHeight(0.08, 15.6);
  ASSERT_EQ(cell.requestHeight(0.08, 0.0), "");
  cell.advanceTo(0.5);
  ASSERT_EQ(cell.faults() & nb::kFaultSensor, 0u);
  // Every reading of the loaded cell above the new range: a sensor fault after the periods.
  nb::AirbagCellParams tuned = cell.params();
  tuned.safety.sensor_pressure_max_pa = 100.0;
  tuned.safety.sensor_fault_periods = 4;
  cell.retune(tuned);
  cell.advanceTo(0.6);
  EXPECT_NE(cell.faults() & nb::kFaultSensor, 0u);
  EXPECT_EQ(cell.params().safety.sensor_fault_periods, 4);
  EXPECT_DOUBLE_EQ(cell.controller().params().height_tolerance_m, tuned.controller.height_tolerance_m);
}

TEST(AirbagCellRetune, KeepsTheTargetAndTheWatchdogsSetting) {
  nb::AirbagCell cell{nb::AirbagCellParams{}};
  cell.resetToHeight(0.05, 15.6);
  cell.setCommandTimeout(1.5);  // what the node arms
  ASSERT_EQ(cell.requestHeight(0.09, 0.0), "");
  cell.advanceTo(0.2);
  nb::AirbagCellParams tuned = cell.params();
  tuned.controller.height_tolerance_m = 0.0006;
  tuned.controller.hold_band_m = 0.0008;
  tuned.safety.command_timeout_s = 0.0;  // not the node's to change through retune
  cell.retune(tuned);
  EXPECT_DOUBLE_EQ(cell.setpoint(), 0.09);
  EXPECT_DOUBLE_EQ(cell.controller().params().hold_band_m, 0.0008);
  EXPECT_DOUBLE_EQ(cell.params().controller.hold_band_m, 0.0008);
  EXPECT_DOUBLE_EQ(cell.params().safety.command_timeout_s, 1.5);
  for (double t = 0.2; t <= 4.0; t += 0.1) {
    cell.heartbeat(t);
    cell.advanceTo(t);
  }
  EXPECT_NEAR(cell.variables().height_m, 0.09, 1e-3);
}

TEST(AirbagCellRetune, AnInvalidTuningIsRefusedAndChangesNothing) {
  nb::AirbagCell cell{nb::AirbagCellParams{}};
  const nb::AirbagCellParams before = cell.params();
  nb::AirbagCellParams bad = before;
  bad.controller.integral_rate_per_s = -1.0;
  bad.safety.relief_pressure_pa = 34000.0;  // valid, but refused with the rest
  EXPECT_THROW(cell.retune(bad), std::invalid_argument);
  bad = before;
  bad.controller.load_filter_time_s = 1.0;  // the load estimator was built with the old one
  try {
    cell.retune(bad);
    ADD_FAILURE() << "a new load filter time was taken";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("load_filter_time_s"), std::string::npos) << e.what();
  }
  EXPECT_DOUBLE_EQ(cell.params().safety.relief_pressure_pa, before.safety.relief_pressure_pa);
  EXPECT_DOUBLE_EQ(cell.controller().params().integral_rate_per_s, before.controller.integral_rate_per_s);
  EXPECT_DOUBLE_EQ(cell.controller().params().load_filter_time_s, before.controller.load_filter_time_s);
}
