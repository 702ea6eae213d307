// The whole-breath statistic: each whole cycle's gas balance and its mean through the runs.
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

/// The lung's content slope at rest (isothermal): d(p V)/dp / (R T) with V = V0 + C p, at 500 Pa.
double contentSlope(const nb::CellParams& lung) {
  const double p = lung.ambient_pressure_pa + 500.0, c = lung.bellows.compliance_m3_pa;
  return (lung.bellows.dead_volume_m3 + c * 500.0 + p * c) /
         (lung.gas.gas_constant_j_kg_k * lung.ambient_temperature_k);
}

}  // namespace

TEST(CycleDrift, WholeCyclesRunFromTheFootOfOneRiseToTheNext) {
  const nb::CellParams lung = lungParams();
  const nb::gap::CellContent content(lung, 0.0);
  const nb::RunData run = breaths(10.0);
  // Pressure 500 Pa + 2 Pa/s since the run's start, plus a ringing in the first second of each
  // breath that the cycles' ends (the last sample before each rise) must not see.
  std::vector<double> p(run.size());
  for (std::size_t i = 0; i < run.size(); ++i) {
    const double t = run.t_s[i] - 10.0, ring = std::fmod(t, 3.0) < 1.0 ? 300.0 * std::sin(40.0 * t) : 0.0;
    p[i] = 500.0 + 2.0 * t + ring;
  }
  const std::vector<nb::gap::CycleRate> rates = nb::gap::contentRates(run, p, content);
  ASSERT_EQ(rates.size(), 2u);  // 10.00-12.99 s (the second rise's foot) and 12.99-15.99 s
  EXPECT_NEAR(rates[0].t_s, 2.99, 1e-9);
  EXPECT_NEAR(rates[0].duration_s, 2.99, 1e-9);
  EXPECT_NEAR(rates[1].t_s, 5.99, 1e-9);
  EXPECT_NEAR(rates[1].duration_s, 3.0, 1e-9);
  // The content climbs with the pressure: 2 Pa/s times the slope.
  const double slope = content.slopeKgPa(500.0);
  EXPECT_NEAR(slope, contentSlope(lung), 0.02 * contentSlope(lung));
  for (const auto& r : rates) EXPECT_NEAR(r.rate_kg_s, 2.0 * slope, 0.01 * 2.0 * slope);
  // A run cut a sample before the edge: that sample is not a cycle of its own.
  nb::RunData cut = run;
  cut.p_setpoint_gauge_pa[0] = 500.0;
  EXPECT_EQ(nb::gap::contentRates(cut, p, content).size(), 2u);
}

TEST(CycleDrift, ARunOfOneCycleCountsItWhenItIsAsLongAsTheOthersCycles) {
  const nb::gap::CellContent content(lungParams(), 0.0);
  nb::RunData one = breaths(0.0);
  one.t_s.resize(301);  // the first breath and the next one's first sample: 0-3.00 s
  one.mdot_in_kg_s.resize(301);
  one.p_gauge_pa.resize(301);
  one.h_m.resize(301);
  one.p_setpoint_gauge_pa.resize(301);
  one.p_setpoint_gauge_pa.back() = 500.0;                     // the foot of the next rise
  EXPECT_TRUE(nb::gap::cycleBalances(one, content).empty());  // no cycle length of its own
  const std::vector<nb::gap::CycleRate> balance = nb::gap::cycleBalances(one, content, 3.0);
  ASSERT_EQ(balance.size(), 1u);
  EXPECT_NEAR(balance[0].duration_s, 3.0, 1e-9);
  EXPECT_NEAR(balance[0].rate_kg_s, 0.0, 1e-12);                   // as much in as out, the pressure unchanged
  EXPECT_TRUE(nb::gap::cycleBalances(one, content, 4.0).empty());  // a cycle cut short
  const nb::RunData two = breaths(0.0);
  EXPECT_NEAR(nb::gap::medianCyclePeriod({&one, &two}, 0.2), 3.0, 1e-9);
  EXPECT_TRUE(std::isnan(nb::gap::medianCyclePeriod({&one}, 0.2)));
}

TEST(CycleDrift, ARunThatIsNotCyclicHasNoCycleAndBadInputIsRefused) {
  const nb::gap::CellContent content(lungParams(), 0.0);
  nb::RunData flat = breaths(0.0);
  flat.p_setpoint_gauge_pa.assign(flat.size(), 500.0);
  EXPECT_TRUE(nb::gap::cycleBalances(flat, content).empty());
  const nb::RunData run = breaths(0.0);
  EXPECT_THROW(nb::gap::contentRates(run, std::vector<double>(run.size() - 1, 0.0), content), std::invalid_argument);
  nb::RunData holed = breaths(0.0);
  holed.mdot_in_kg_s[100] = NAN;  // a missing flow sample: its cycle is left out
  EXPECT_EQ(nb::gap::cycleBalances(holed, content).size(), 1u);
}

TEST(CycleDrift, TheMeanBalanceHasAStandardErrorFromTheCyclesScatter) {
  using nb::gap::CycleRate;
  const std::vector<std::vector<CycleRate>> runs = {{{3.0, 3.0, 1.0}, {6.0, 3.0, 3.0}}, {{3.0, 3.0, 2.0}}};
  const nb::gap::BalanceMean m = nb::gap::meanBalance(runs, 0.0);
  ASSERT_TRUE(m.ok());
  EXPECT_EQ(m.points, 3);
  EXPECT_NEAR(m.mean_kg_s, 2.0, 1e-12);
  EXPECT_NEAR(m.se_kg_s, 1.0 / std::sqrt(3.0), 1e-12);  // standard deviation 1 over 3 cycles
  EXPECT_NEAR(nb::gap::cycleScatter(runs), 1.0, 1e-12);
  EXPECT_TRUE(m.significant(3.0));
  EXPECT_FALSE(m.significant(3.5));
  // The floor: identical cycles do not make a small balance significant.
  const nb::gap::BalanceMean same = nb::gap::meanBalance({{{3.0, 3.0, 0.1}, {6.0, 3.0, 0.1}}}, 1.0);
  EXPECT_NEAR(same.se_kg_s, 1.0 / std::sqrt(2.0), 1e-12);
  EXPECT_FALSE(same.significant(3.0));
  // One cycle: judged with another set's scatter, or not at all.
  EXPECT_FALSE(nb::gap::meanBalance({{{3.0, 3.0, 5.0}}}, 0.0).ok());
  const nb::gap::BalanceMean one = nb::gap::meanBalance({{{3.0, 3.0, 5.0}}}, 0.0, 1.0);
  ASSERT_TRUE(one.ok());
  EXPECT_NEAR(one.se_kg_s, 1.0, 1e-12);
  EXPECT_FALSE(nb::gap::meanBalance({}, 0.0).ok());
}

TEST(CycleDrift, AMetersOffsetIsTheCyclesBalance) {
  // The lung's pressure from the true flow; the metered flow 5 mL/s too high. Every whole
  // breath takes in 5 mL/s more than the lung's content rises by: the balance is the offset.
  const nb::CellParams lung = lungParams();
  const nb::gap::CellContent content(lung, 0.0);
  const double offset_m3_s = 5e-6;
  std::vector<std::vector<nb::gap::CycleRate>> runs;
  for (double t0 : {0.0, 6.0, 12.0}) {
    nb::RunData run = breaths(t0);
    const nb::Replay truth = nb::replayRun(run, lung, {});
    ASSERT_TRUE(truth.ok) << truth.message;
    run.p_gauge_pa = truth.p_gauge_pa;
    for (double& m : run.mdot_in_kg_s) m += kAirDensity * offset_m3_s;
    runs.push_back(nb::gap::cycleBalances(run, content));
    EXPECT_EQ(runs.back().size(), 2u);
  }
  const nb::gap::BalanceMean m = nb::gap::meanBalance(runs, 0.0);
  ASSERT_TRUE(m.ok());
  EXPECT_NEAR(m.mean_kg_s, kAirDensity * offset_m3_s, 0.05 * kAirDensity * offset_m3_s);
}
