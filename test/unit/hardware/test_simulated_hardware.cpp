// The simulated hardware's plant fault: a failed or invalid solve resets the plant flat at rest
// and is reported once as CellReadings::device_reset. And what the observer is given of a report.
#include <gtest/gtest.h>

#include <cmath>

#include "nursing_bed/core/hardware/simulated_cell_hardware.h"

namespace nb = nursing_bed;

namespace {

TEST(SimulatedCellHardware, AnInvalidPlantIsResetAndReportedOnce) {
  nb::SimulatedCellHardware hw;
  nb::HardwareConfig config;
  config.load_n = 10.6;
  config.initial_height_m = 0.10;
  hw.configure(config);
  nb::CellReadings r = hw.read(0.0);
  EXPECT_FALSE(r.device_reset);
  nb::CellModel::StateVector broken = hw.model().state();
  broken[nb::CellModel::kEnergy] = -1.0;  // a negative temperature
  const_cast<nb::CellModel&>(hw.model()).setState(hw.time(), broken);
  hw.write(nb::ValveOpenings{1.0, 0.0, false}, 0.0);
  r = hw.read(0.02);
  EXPECT_TRUE(r.device_reset);
  EXPECT_NEAR(hw.time(), 0.02, 1e-9);  // the plant's clock goes on
  EXPECT_GT(hw.variables().structure.volume_m3, 0.0);
  EXPECT_GT(hw.variables().temperature_k, 250.0);
  EXPECT_EQ(hw.actingValves().inlet, 0.0);  // valves shut by the reset
  EXPECT_TRUE(std::isfinite(r.gauge_pressure_pa.value));
  r = hw.read(0.04);
  EXPECT_FALSE(r.device_reset);  // reported once
}

TEST(ReadingsOf, TakesEachSignalsValueAndLeavesAnAbsentOneNaN) {
  nb::CellReadings r;
  r.gauge_pressure_pa = {1200.0, 3.0};
  r.inflow_kg_s = {2e-4, 3.0};
  r.gas_temperature_k = {295.0, 3.0};
  r.supply_pressure_pa = {40000.0, 3.0};
  const nb::Readings z = nb::readingsOf(r);
  EXPECT_EQ(z.gauge_pressure_pa, 1200.0);
  EXPECT_TRUE(std::isnan(z.height_m)) << "no height sensor: absent";
  EXPECT_EQ(z.inflow_kg_s, 2e-4);
  EXPECT_EQ(z.gas_temperature_k, 295.0);
  r.height_m = {0.12, 3.0};
  EXPECT_EQ(nb::readingsOf(r).height_m, 0.12);
}

}  // namespace
