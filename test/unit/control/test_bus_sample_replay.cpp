// A late period replayed from the driver's bus samples: the steps, and a cell whose thread is
// starved during a fill counting its gas from them (and doubting it still).
#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include "nursing_bed/core/control/airbag_cell.h"
#include "nursing_bed/core/control/bus_sample_replay.h"
#include "rig_without_height_sensor.h"

namespace nb = nursing_bed;

namespace {

/// A read at `now_s` whose bus sampled every `cycle_s` from `from_s`, the inlet open up to
/// `inlet_until_s`, the pressure rising 1000 Pa/s.
nb::CellReadings sampledRead(double from_s, double now_s, double cycle_s, double inlet_until_s) {
  nb::CellReadings r;
  double last_s = from_s;
  for (double t = from_s + cycle_s; t <= now_s - 0.5 * cycle_s; t += cycle_s) {
    const double on_s = std::clamp(inlet_until_s - last_s, 0.0, t - last_s);
    r.bus_samples.push_back({t, t - last_s, 1000.0 * t, on_s / (t - last_s), 0.0});
    last_s = t;
  }
  const double on_s = std::clamp(inlet_until_s - from_s, 0.0, now_s - from_s);
  r.gauge_pressure_pa = {r.bus_samples.back().gauge_pressure_pa, r.bus_samples.back().stamp_s};
  r.inlet_driven = {on_s / (now_s - from_s), now_s};
  r.vent_driven = {0.0, now_s};
  return r;
}

}  // namespace

TEST(BusSampleSteps, TileTheLatePeriodInControlPeriodsAndCountEveryPulseOnce) {
  const nb::CellReadings r = sampledRead(1.0, 1.102, 0.005, 1.05);
  const std::vector<nb::ReplayStep> steps = nb::busSampleSteps(r, 1.0, 1.102, 0.01, 0.03);
  ASSERT_GE(steps.size(), 10u);
  double covered_s = 0.0, inlet_s = 0.0, last_s = 1.0;
  for (std::size_t i = 0; i < steps.size(); ++i) {
    const nb::ReplayStep& s = steps[i];
    EXPECT_NEAR(s.end_s - s.dt_s, last_s, 1e-12) << "steps follow each other";
    if (s.end_s < r.bus_samples.back().stamp_s - 1e-12) {
      EXPECT_GE(s.dt_s, 0.01 - 1e-9) << "merged into control periods up to the last cycle";
    }
    if (i + 1 < steps.size()) {
      EXPECT_NEAR(s.readings.gauge_pressure_pa.value, 1000.0 * s.end_s, 1e-6) << "the step's last sample";
    }
    EXPECT_TRUE(s.readings.bus_samples.empty());
    covered_s += s.dt_s;
    inlet_s += s.readings.inlet_driven.value * s.dt_s;
    last_s = s.end_s;
  }
  EXPECT_NEAR(covered_s, 0.102, 1e-12);
  EXPECT_NEAR(inlet_s, 0.05, 1e-9) << "the read's on-time, once";
  EXPECT_NEAR(steps[2].readings.inlet_driven.value, 1.0, 1e-9) << "open early in the period";
  EXPECT_NEAR(steps[7].readings.inlet_driven.value, 0.0, 1e-9) << "shut late in it";
}

TEST(BusSampleSteps, TheReadsOnTimeIsHandedOutInTheCyclesShape) {
  // The read's mean is the driver's account, which carries on-time from a read whose caller's
  // period was shorter than the real one: the steps count the read's amount (each pulse once
  // over the reads) where the cycles say the valve was open, and what a full opening cannot
  // take where there is room.
  nb::CellReadings r = sampledRead(1.0, 1.102, 0.005, 1.05);
  for (double total_s : {0.03, 0.06}) {
    r.inlet_driven.value = total_s / 0.102;
    double inlet_s = 0.0;
    for (const nb::ReplayStep& s : nb::busSampleSteps(r, 1.0, 1.102, 0.01, 0.03)) {
      EXPECT_LE(s.readings.inlet_driven.value, 1.0);
      inlet_s += s.readings.inlet_driven.value * s.dt_s;
      if (total_s < 0.05 && s.end_s > 1.06) {
        EXPECT_EQ(s.readings.inlet_driven.value, 0.0) << "shut after 1.05 s";
      }
    }
    EXPECT_NEAR(inlet_s, total_s, 1e-9);
  }
}

TEST(BusSampleSteps, NothingIsReplayedOverAGapOrWhereASensorMeasuresTheGas) {
  const nb::CellReadings r = sampledRead(1.0, 1.1, 0.005, 1.05);
  EXPECT_FALSE(nb::busSampleSteps(r, 1.0, 1.1, 0.01, 0.03).empty());
  nb::CellReadings gap = r;
  gap.bus_samples.erase(gap.bus_samples.begin() + 5, gap.bus_samples.begin() + 12);
  EXPECT_TRUE(nb::busSampleSteps(gap, 1.0, 1.1, 0.01, 0.03).empty()) << "35 ms without a cycle";
  EXPECT_TRUE(nb::busSampleSteps(r, 0.9, 1.1, 0.01, 0.03).empty()) << "samples only from the period's middle";
  nb::CellReadings none = r;
  none.bus_samples.clear();
  EXPECT_TRUE(nb::busSampleSteps(none, 1.0, 1.1, 0.01, 0.03).empty());
  nb::CellReadings height = r;
  height.height_m = {0.1, 1.1};
  EXPECT_TRUE(nb::busSampleSteps(height, 1.0, 1.1, 0.01, 0.03).empty()) << "the height is measured";
}

namespace {

/// A driver in front of a simulated plant without a height sensor that samples the plant every
/// 5 ms between reads, as a bus thread does, and hands a read its cycles with the openings
/// written last (the plant holds them until the next write) when `samples` is set.
class SampledHardware : public nb::CellHardware {
 public:
  explicit SampledHardware(std::shared_ptr<nb::SimulatedCellHardware> plant) : plant_(std::move(plant)) {}
  void configure(const nb::HardwareConfig&) override {}
  nb::HardwareCapabilities capabilities() const override { return {}; }
  std::string describe() const override { return "sampled test plant"; }
  nb::CellReadings read(double now_s) override {
    std::vector<nb::BusSample> cycles;
    double last_s = last_read_s_;
    for (double t = last_read_s_ + kCycleS; samples && t < now_s - 1e-9; t += kCycleS) {
      cycles.push_back({t, t - last_s, pressureAt(t), written_.inlet, written_.vent});
      last_s = t;
    }
    nb::CellReadings r = plant_->read(now_s);
    r.height_m = {};
    r.inflow_kg_s = {};
    r.gas_temperature_k = {};
    if (samples) cycles.push_back({now_s, now_s - last_s, r.gauge_pressure_pa.value, written_.inlet, written_.vent});
    r.bus_samples = cycles;
    r.inlet_driven = {written_.inlet, now_s};
    r.vent_driven = {written_.vent, now_s};
    last_read_s_ = now_s;
    return r;
  }
  void write(const nb::ValveOpenings& v, double now_s) override {
    written_ = v;
    plant_->write(v, now_s);
  }
  bool samples = true;

 private:
  static constexpr double kCycleS = 0.005;
  double pressureAt(double t) { return plant_->read(t).gauge_pressure_pa.value; }
  std::shared_ptr<nb::SimulatedCellHardware> plant_;
  nb::ValveOpenings written_;
  double last_read_s_ = 0.0;
};

struct StarvedFill {
  double error_m = 0.0, doubt_m = 0.0;
  bool flagged = false;
};

/// A fill from 60 to 100 mm under 15.6 N whose first 1.2 s run in periods 60 ms apart (`late`)
/// instead of 10, over a driver that hands out its bus cycles or not.
StarvedFill starvedFill(bool late, bool samples) {
  nb::AirbagCellParams p;
  p.control_period_s = 0.01;
  const nb::AirbagObserverSetup observer;
  auto plant = nb::test::rigWithoutHeightSensor(p, 0.06, 15.6, observer.params.valve_dead_time_s);
  auto hw = std::make_shared<SampledHardware>(plant);
  hw->samples = samples;
  nb::AirbagCell cell(p, hw, observer);
  cell.resetToHeight(0.06, 15.6);
  double t = 0.0;
  EXPECT_EQ(cell.requestHeight(0.06, t), "");
  for (; t < 1.0 - 1e-9; t += 0.01) cell.advanceTo(t);
  EXPECT_EQ(cell.requestHeight(0.10, t), "");
  for (int k = 0; late && k < 20; ++k) cell.advanceTo(t += 0.06);
  for (; t < 6.0 - 1e-9; t += 0.01) cell.advanceTo(t);
  const nb::CellEstimate e = cell.observer()->estimate();
  return {std::fabs(e.height_m - plant->variables().height_m), e.count_doubt_m, cell.heightUnverified()};
}

}  // namespace

TEST(BusSampleSteps, AStarvedCellCountsItsFillFromTheBusCycles) {
  const StarvedFill on_time = starvedFill(false, true);
  const StarvedFill unsampled = starvedFill(true, false);
  const StarvedFill sampled = starvedFill(true, true);
  std::cout << "[replay] a fill with 20 periods 60 ms late: estimate off by " << 1e3 * unsampled.error_m
            << " mm (doubt " << 1e3 * unsampled.doubt_m << " mm) counted at the periods' ends, "
            << 1e3 * sampled.error_m << " mm (doubt " << 1e3 * sampled.doubt_m << " mm) from the bus cycles; on time "
            << 1e3 * on_time.error_m << " mm\n";
  EXPECT_LT(sampled.error_m, 0.25 * unsampled.error_m) << "counted at the pressures it passed";
  EXPECT_LT(sampled.error_m, 0.001);
  EXPECT_TRUE(unsampled.flagged) << "the late periods' gas is the count's doubt";
  EXPECT_TRUE(sampled.flagged) << "with the cycles too";
  EXPECT_FALSE(on_time.flagged);
}
