// The cell's safety layer (sensor range, watchdog, relief), its pressure mode, and the cell's
// setters for new controller and safety parameters.
#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>
#include <string>

#include "nursing_bed/core/control/airbag_cell.h"
#include "nursing_bed/core/control/pressure_mode_controller.h"
#include "nursing_bed/core/control/safety_layer.h"

namespace nb = nursing_bed;

TEST(SafetyLayer, AnOutOfRangeReadingHoldsFirstAndIsAFaultOnlyWhenItPersists) {
  nb::AirbagSafetyParams p;
  p.sensor_fault_periods = 3;
  nb::SafetyLayer safety(p);
  EXPECT_EQ(safety.checkReadings(1000.0, 0.05), nb::SensorVerdict::kOk);
  EXPECT_EQ(safety.checkReadings(std::nan(""), 0.05), nb::SensorVerdict::kHold);
  EXPECT_EQ(safety.checkReadings(1000.0, 0.5), nb::SensorVerdict::kHold);
  EXPECT_EQ(safety.checkReadings(-60000.0, 0.05), nb::SensorVerdict::kFault);
  EXPECT_EQ(safety.checkReadings(1000.0, 0.05), nb::SensorVerdict::kOk);
  EXPECT_EQ(safety.checkReadings(1000.0, -0.03), nb::SensorVerdict::kHold) << "a sane reading restarts the count";
}

TEST(SafetyLayer, TheWatchdogTripsOnlyWhenArmedAndCommandsStop) {
  nb::SafetyLayer off(nb::AirbagSafetyParams{});
  EXPECT_FALSE(off.commandTimedOut(1e6)) << "command_timeout_s 0 is off";
  nb::AirbagSafetyParams p;
  p.command_timeout_s = 0.5;
  nb::SafetyLayer safety(p);
  safety.noteCommand(1.0);
  EXPECT_FALSE(safety.commandTimedOut(1.5));
  EXPECT_TRUE(safety.commandTimedOut(1.51));
  safety.noteCommand(1.4);
  EXPECT_FALSE(safety.commandTimedOut(1.51));
}

TEST(SafetyLayer, ReliefActsAheadOfTheRiseAndClearsWellBelow) {
  nb::AirbagSafetyParams p;
  p.relief_pressure_pa = 30000.0;
  p.relief_margin_pa = 500.0;
  nb::SafetyLayer safety(p);
  safety.setLastPressure(28000.0);
  // 29000 rising 1000 per period: the next period could cross 30000 - margin.
  EXPECT_EQ(safety.relief(29000.0), nb::ReliefVerdict::kVent);
  EXPECT_EQ(safety.relief(29000.0), nb::ReliefVerdict::kKeep) << "steady within two margins: the flag stays";
  EXPECT_EQ(safety.relief(28000.0), nb::ReliefVerdict::kClear);
  EXPECT_EQ(safety.relief(29600.0), nb::ReliefVerdict::kVent) << "at the margin without a rise";
}

TEST(SafetyLayer, BadParametersAndLoadsAreRefusedByNameAndChangeNothing) {
  nb::AirbagSafetyParams bad;
  bad.relief_margin_pa = -1.0;
  bad.sensor_fault_periods = 0;
  EXPECT_THROW(nb::SafetyLayer{bad}, std::invalid_argument);
  nb::SafetyLayer safety(nb::AirbagSafetyParams{});
  const std::string error = safety.setParams(bad);
  EXPECT_NE(error.find("relief_margin_pa"), std::string::npos) << error;
  EXPECT_NE(error.find("sensor_fault_periods"), std::string::npos) << error;
  EXPECT_EQ(safety.params().relief_margin_pa, nb::AirbagSafetyParams{}.relief_margin_pa);
  EXPECT_EQ(safety.params().sensor_fault_periods, nb::AirbagSafetyParams{}.sensor_fault_periods);
  EXPECT_EQ(safety.checkLoad(20.0), "");
  for (const double load : {-1.0, 2000.0, std::nan("")})
    EXPECT_NE(safety.checkLoad(load).find("max_load_n"), std::string::npos) << load;
}

TEST(PressureModeController, OpensInProportionBeyondTheDeadband) {
  nb::PressureModeController pressure;
  EXPECT_FALSE(pressure.active());
  pressure.setSetpoint(5000.0);
  EXPECT_TRUE(pressure.active());
  EXPECT_EQ(pressure.update(4960.0).inlet, 0.0) << "within the deadband";
  EXPECT_EQ(pressure.update(4960.0).vent, 0.0);
  EXPECT_NEAR(pressure.update(4500.0).inlet, 0.5, 1e-12);
  EXPECT_EQ(pressure.update(1000.0).inlet, 1.0);
  EXPECT_NEAR(pressure.update(5250.0).vent, 0.25, 1e-12);
  EXPECT_EQ(pressure.update(5250.0).inlet, 0.0);
  pressure.clear();
  EXPECT_TRUE(std::isnan(pressure.setpoint()));
  nb::PressureModeParams bad;
  bad.tolerance_pa = 2000.0;
  EXPECT_NE(bad.validate().message().find("tolerance_pa"), std::string::npos);
  EXPECT_THROW(nb::PressureModeController{bad}, std::invalid_argument);
}

TEST(AirbagCell, NewControllerAndSafetyParametersAreTakenOnlyWhenConsistent) {
  nb::AirbagCell cell{nb::AirbagCellParams{}};
  cell.resetToHeight(0.05, 15.6);
  nb::HeightControllerParams controller = cell.params().controller;
  controller.max_pressure_pa = cell.params().safety.relief_pressure_pa + 1000.0;
  EXPECT_NE(cell.setControllerParams(controller).find("relief"), std::string::npos);
  EXPECT_EQ(cell.controller().params().max_pressure_pa, nb::HeightControllerParams{}.max_pressure_pa);
  controller = cell.params().controller;
  controller.height_tolerance_m = 0.0008;
  controller.hold_band_m = 0.0008;
  EXPECT_EQ(cell.setControllerParams(controller), "");
  EXPECT_EQ(cell.controller().params().height_tolerance_m, 0.0008);
  EXPECT_EQ(cell.params().controller.height_tolerance_m, 0.0008);
  EXPECT_DOUBLE_EQ(cell.setpoint(), 0.05) << "the setpoint is kept";

  nb::AirbagSafetyParams safety = cell.params().safety;
  safety.relief_pressure_pa = 20000.0;  // below the controller's max_pressure_pa
  EXPECT_NE(cell.setSafetyParams(safety).find("relief"), std::string::npos);
  EXPECT_EQ(cell.params().safety.relief_pressure_pa, nb::AirbagSafetyParams{}.relief_pressure_pa);
  safety = cell.params().safety;
  safety.max_load_n = 500.0;
  EXPECT_EQ(cell.setSafetyParams(safety), "");
  EXPECT_NE(cell.checkLoad(600.0), "");
  EXPECT_NE(cell.setCommandTimeout(-1.0), "");
  EXPECT_EQ(cell.params().safety.command_timeout_s, 0.0);
  EXPECT_EQ(cell.setCommandTimeout(0.5), "");
  EXPECT_EQ(cell.params().safety.command_timeout_s, 0.5);
}
