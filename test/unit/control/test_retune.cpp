// New tuning on a running cell (applyTuning over AirbagCell::setControllerParams and
// setSafetyParams, HeightController::setParams): taken while the cell runs, refused whole when
// invalid.
#include <gtest/gtest.h>

#include <string>

#include "nursing_bed/core/control/airbag_cell.h"
#include "nursing_bed/core/control/cell_tuning.h"

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
  ASSERT_EQ(nb::applyTuning(cell, tuned.controller, tuned.safety), "");
  cell.advanceTo(0.6);
  EXPECT_NE(cell.faults() & nb::kFaultSensor, 0u);
  EXPECT_EQ(cell.params().safety.sensor_fault_periods, 4);
  EXPECT_DOUBLE_EQ(cell.controller().params().height_tolerance_m, tuned.controller.height_tolerance_m);
}

TEST(AirbagCellRetune, KeepsTheTargetAndTheWatchdogsSetting) {
  nb::AirbagCell cell{nb::AirbagCellParams{}};
  cell.resetToHeight(0.05, 15.6);
  ASSERT_EQ(cell.setCommandTimeout(1.5), "");  // what the node arms
  ASSERT_EQ(cell.requestHeight(0.09, 0.0), "");
  cell.advanceTo(0.2);
  nb::AirbagCellParams tuned = cell.params();
  tuned.controller.height_tolerance_m = 0.0006;
  tuned.controller.hold_band_m = 0.0008;
  tuned.safety.command_timeout_s = 0.0;  // not the tuning's to change
  ASSERT_EQ(nb::applyTuning(cell, tuned.controller, tuned.safety), "");
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
  EXPECT_NE(nb::applyTuning(cell, bad.controller, bad.safety).find("integral_rate_per_s"), std::string::npos);
  bad = before;
  bad.controller.load_filter_time_s = 1.0;  // the load estimate was filtered with the old one
  bad.safety.relief_pressure_pa = 36000.0;  // valid, taken first, then put back
  const std::string error = nb::applyTuning(cell, bad.controller, bad.safety);
  EXPECT_NE(error.find("load_filter_time_s"), std::string::npos) << error;
  EXPECT_DOUBLE_EQ(cell.params().safety.relief_pressure_pa, before.safety.relief_pressure_pa);
  EXPECT_DOUBLE_EQ(cell.controller().params().integral_rate_per_s, before.controller.integral_rate_per_s);
  EXPECT_DOUBLE_EQ(cell.controller().params().load_filter_time_s, before.controller.load_filter_time_s);
}

TEST(AirbagCellRetune, APairValidOnlyTogetherIsTakenEitherWay) {
  // The controller's max_pressure_pa must stay below the relief: lowering both, the controller
  // must go first; raising both, the relief must.
  nb::AirbagCell cell{nb::AirbagCellParams{}};
  nb::AirbagCellParams tuned = cell.params();
  tuned.controller.max_pressure_pa = 500.0;
  tuned.safety.relief_pressure_pa = 1000.0;
  ASSERT_EQ(nb::applyTuning(cell, tuned.controller, tuned.safety), "");
  EXPECT_DOUBLE_EQ(cell.params().controller.max_pressure_pa, 500.0);
  EXPECT_DOUBLE_EQ(cell.params().safety.relief_pressure_pa, 1000.0);
  const nb::AirbagCellParams defaults;
  ASSERT_EQ(nb::applyTuning(cell, defaults.controller, defaults.safety), "");
  EXPECT_DOUBLE_EQ(cell.params().controller.max_pressure_pa, defaults.controller.max_pressure_pa);
  EXPECT_DOUBLE_EQ(cell.controller().params().max_pressure_pa, defaults.controller.max_pressure_pa);
  EXPECT_DOUBLE_EQ(cell.params().safety.relief_pressure_pa, defaults.safety.relief_pressure_pa);
}

TEST(AirbagCellRetune, APairThatContradictsItselfIsRefusedAndChangesNothing) {
  nb::AirbagCell cell{nb::AirbagCellParams{}};
  const nb::AirbagCellParams before = cell.params();
  nb::AirbagCellParams bad = before;
  bad.controller.max_pressure_pa = 30000.0;  // taken first (the relief drops), then put back
  bad.safety.relief_pressure_pa = 20000.0;
  EXPECT_NE(nb::applyTuning(cell, bad.controller, bad.safety).find("relief"), std::string::npos);
  EXPECT_DOUBLE_EQ(cell.params().controller.max_pressure_pa, before.controller.max_pressure_pa);
  EXPECT_DOUBLE_EQ(cell.controller().params().max_pressure_pa, before.controller.max_pressure_pa);
  EXPECT_DOUBLE_EQ(cell.params().safety.relief_pressure_pa, before.safety.relief_pressure_pa);
}

TEST(HeightControllerRetune, RefusesANewLoadFilterTimeAndBoundsTheIntegralByTheNewLimit) {
  const nb::AirbagCellParams cell_params;
  nb::HeightControllerParams params;
  params.move_threshold_m = 1.0;  // no shaped move: the resting error is integrated
  nb::HeightController controller(params, nb::CellCharacteristic::shared(cell_params.cell));
  controller.setTarget(0.08);
  for (int i = 0; i < 2000; ++i) controller.update(0.01, controller.targetPressure(), 0.075);
  ASSERT_GT(controller.integralCorrection(), 0.005) << "no integral correction built up";

  nb::HeightControllerParams other_filter = params;
  other_filter.load_filter_time_s = 2.0 * params.load_filter_time_s;
  const std::string error = controller.setParams(other_filter);
  EXPECT_NE(error.find("load_filter_time_s"), std::string::npos) << error;
  EXPECT_EQ(controller.params().load_filter_time_s, params.load_filter_time_s);

  nb::HeightControllerParams tighter = params;
  tighter.integral_limit_m = 0.002;
  ASSERT_EQ(controller.setParams(tighter), "");
  EXPECT_DOUBLE_EQ(controller.integralCorrection(), 0.002);
  EXPECT_DOUBLE_EQ(controller.target(), 0.08);
}
