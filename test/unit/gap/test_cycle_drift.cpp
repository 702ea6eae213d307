// The whole-breath statistic: end-of-cycle residuals and their trend through the runs.
#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

#include "nursing_bed/core/gap/cycle_drift.h"
#include "nursing_bed/core/gap/replay.h"
#include "nursing_bed/core/physics/cell_params_io.h"

namespace nb = nursing_bed;

namespace {

const std::string kSource = NURSING_BED_SOURCE_DIR;
constexpr double kAirDensity = 1.2;  // [kg/m^3]

/// The test lung without its airway (the sensor at the chamber), a heavier, damped plate.
nb::CellParams lungParams() {
  nb::CellParams p = nb::loadCellParamsYaml(kSource + "/config/lung_quicklung_c10.yaml");
  p.airway = nb::AirwayParams{};
  p.plate_mass_kg = 0.1;
  p.plate_damping_n_s_m = 100.0;
  return p;
}

/// Two 3 s breaths (1 s in at 200 mL/s, 1 s out, 1 s still) from t0, the setpoint high while gas
/// goes in; the run ends where a third breath would start. Pressure 500 Pa at rest.
nb::RunData breaths(double t0) {
  nb::RunData run;
  run.name = "breaths.csv";
  run.load_n = 0.0;
  for (int i = 0; i < 600; ++i) {
    const double t = 0.01 * i, phase = std::fmod(t, 3.0);
    run.t_s.push_back(t0 + t);
    run.mdot_in_kg_s.push_back(kAirDensity * (phase < 1.0 ? 2e-4 : (phase < 2.0 ? -2e-4 : 0.0)));
    run.p_gauge_pa.push_back(500.0);
    run.h_m.push_back(NAN);
    run.p_setpoint_gauge_pa.push_back(phase < 1.0 ? 1500.0 : 500.0);
  }
  return run;
}

}  // namespace

TEST(CycleDrift, EndOfCycleResidualsAreTheLastWindowOfEachCycle) {
  const nb::RunData run = breaths(10.0);
  std::vector<double> model(run.size());
  // Measured less modelled: 10 Pa + 2 Pa/s since the run's start, plus a ringing in the first
  // second of every cycle that the end-of-cycle windows must not see.
  for (std::size_t i = 0; i < run.size(); ++i) {
    const double t = run.t_s[i] - 10.0, ring = std::fmod(t, 3.0) < 1.0 ? 300.0 * std::sin(40.0 * t) : 0.0;
    model[i] = run.p_gauge_pa[i] - (10.0 + 2.0 * t + ring);
  }
  const std::vector<nb::gap::CyclePoint> points = nb::gap::endOfCycleResiduals(run, model, 0.2);
  ASSERT_EQ(points.size(), 2u);  // the second breath's start and the run's end
  EXPECT_NEAR(points[0].t_s, 3.0, 1e-9);
  EXPECT_NEAR(points[1].t_s, 5.99, 1e-9);
  EXPECT_NEAR(points[0].residual_pa, 10.0 + 2.0 * 2.895, 0.02);  // the mean of t over 2.80-2.99 s
  EXPECT_NEAR(points[1].residual_pa, 10.0 + 2.0 * 5.89, 0.02);   // over 5.79-5.99 s
  // A run cut a sample before the edge: that sample is not a cycle of its own.
  nb::RunData cut = run;
  cut.p_setpoint_gauge_pa[0] = 500.0;
  const std::vector<nb::gap::CyclePoint> same = nb::gap::endOfCycleResiduals(cut, model, 0.2);
  ASSERT_EQ(same.size(), 2u);
  EXPECT_NEAR(same[0].t_s, 3.0, 1e-9);
  EXPECT_NEAR(same[1].t_s, 5.99, 1e-9);
}

TEST(CycleDrift, ARunOfOneCycleEndsItWhenItIsAsLongAsTheOthersCycles) {
  nb::RunData one = breaths(0.0);
  one.t_s.resize(300);  // the first breath alone: 0-2.99 s
  one.mdot_in_kg_s.resize(300);
  one.p_gauge_pa.resize(300);
  one.h_m.resize(300);
  one.p_setpoint_gauge_pa.resize(300);
  const std::vector<double> model(one.size(), 480.0);
  EXPECT_TRUE(nb::gap::endOfCycleResiduals(one, model, 0.2).empty());  // no cycle length of its own
  const std::vector<nb::gap::CyclePoint> points = nb::gap::endOfCycleResiduals(one, model, 0.2, 3.0);
  ASSERT_EQ(points.size(), 1u);
  EXPECT_NEAR(points[0].t_s, 2.99, 1e-9);
  EXPECT_NEAR(points[0].residual_pa, 20.0, 1e-9);
  EXPECT_TRUE(nb::gap::endOfCycleResiduals(one, model, 0.2, 4.0).empty());  // a cycle cut short
  const nb::RunData two = breaths(0.0);
  EXPECT_NEAR(nb::gap::medianCyclePeriod({&one, &two}, 0.2), 3.0, 1e-9);
  EXPECT_TRUE(std::isnan(nb::gap::medianCyclePeriod({&one}, 0.2)));
}

TEST(CycleDrift, ARunThatIsNotCyclicHasNoPointAndBadInputIsRefused) {
  nb::RunData flat = breaths(0.0);
  flat.p_setpoint_gauge_pa.assign(flat.size(), 500.0);
  EXPECT_TRUE(nb::gap::endOfCycleResiduals(flat, flat.p_gauge_pa, 0.2).empty());
  const nb::RunData run = breaths(0.0);
  EXPECT_THROW(nb::gap::endOfCycleResiduals(run, std::vector<double>(run.size() - 1, 0.0), 0.2), std::invalid_argument);
  EXPECT_THROW(nb::gap::endOfCycleResiduals(run, run.p_gauge_pa, 0.0), std::invalid_argument);
}

TEST(CycleDrift, TheTrendThroughTheRunsHasOneInterceptAndAStandardError) {
  using nb::gap::CyclePoint;
  // Three runs, points on 4 + 1.5 t give or take 0.3 Pa.
  const std::vector<std::vector<CyclePoint>> runs = {
      {{3.0, 8.8}, {6.0, 12.7}}, {{3.0, 8.2}, {6.0, 13.3}}, {{3.0, 8.5}, {6.0, 13.0}}};
  const nb::gap::CycleDrift d = nb::gap::fitCycleDrift(runs, 0.0);
  ASSERT_TRUE(d.ok());
  EXPECT_EQ(d.points, 6);
  EXPECT_NEAR(d.slope_pa_s, 1.5, 1e-9);
  EXPECT_NEAR(d.intercept_pa, 4.0, 1e-9);
  // Four residuals of 0.3 Pa: rss 0.36 over 4 degrees of freedom; the times' spread about their
  // mean 6 * 1.5^2.
  EXPECT_NEAR(d.se_pa_s, std::sqrt(0.36 / 4.0) / std::sqrt(13.5), 1e-9);
  EXPECT_TRUE(d.significant(3.0));
  // The scatter's floor: exactly collinear points do not make a tiny slope significant.
  const nb::gap::CycleDrift flat = nb::gap::fitCycleDrift({{{3.0, 1.0}, {6.0, 1.01}}, {{3.0, 1.0}, {6.0, 1.01}}}, 1.0);
  EXPECT_NEAR(flat.se_pa_s, 1.0 / std::sqrt(9.0), 1e-9);
  EXPECT_FALSE(flat.significant(3.0));
  EXPECT_FALSE(nb::gap::fitCycleDrift({{{3.0, 1.0}, {6.0, 2.0}}}, 0.0).ok());  // two points: no scatter
}

TEST(CycleDrift, AMetersOffsetIsItsTrendTimesTheCompliance) {
  // The lung's pressure from the true flow; the model fed the metered flow, 5 mL/s too high.
  // The end-of-cycle residual falls by offset / C per second (C the lung's compliance at its
  // port: the spring's and the bellows gas'), the same in every run.
  const nb::CellParams lung = lungParams();
  const double offset_m3_s = 5e-6;
  std::vector<std::vector<nb::gap::CyclePoint>> runs;
  for (double t0 : {0.0, 6.0, 12.0}) {
    nb::RunData run = breaths(t0);
    const nb::Replay truth = nb::replayRun(run, lung, {});
    ASSERT_TRUE(truth.ok) << truth.message;
    run.p_gauge_pa = truth.p_gauge_pa;
    for (double& m : run.mdot_in_kg_s) m += kAirDensity * offset_m3_s;
    const nb::Replay metered = nb::replayRun(run, lung, {});
    ASSERT_TRUE(metered.ok) << metered.message;
    runs.push_back(nb::gap::endOfCycleResiduals(run, metered.p_gauge_pa, 0.2));
  }
  const nb::gap::CycleDrift d = nb::gap::fitCycleDrift(runs, 0.0);
  ASSERT_TRUE(d.ok());
  const double c_port = lung.bellows.compliance_m3_pa +
                        lung.bellows.dead_volume_m3 / (lung.gas.heat_capacity_ratio * lung.ambient_pressure_pa);
  EXPECT_NEAR(-d.slope_pa_s * c_port, offset_m3_s, 0.05 * offset_m3_s);
}
