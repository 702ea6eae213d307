// The stages of diagnoseRuns() one by one (diagnosis_stages.h), on short runs of the small
// protocol: roles, the candidate list, the nominal replay, the noise model, the fits, the
// scores and the shrinkage.
#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

#include "nursing_bed/core/gap/diagnosis_stages.h"
#include "nursing_bed/core/gap/synth.h"

#include "../../test_helpers.h"
#include "small_protocol_runs.h"

namespace nb = nursing_bed;
namespace gs = nursing_bed::gap;

namespace {

/// The small protocol's runs, noisy, with `effects` hidden in the cell; with the protocol's roles
/// or none.
std::vector<nb::RunData> smallRuns(const std::vector<nb::CellEffectPtr>& effects, std::uint32_t seed,
                                   bool with_roles = false) {
  return nb::test::smallProtocolRuns(effects, seed, {{}, false, 1.0, with_roles});
}

nb::DiagnosisOptions leakOnly() {
  nb::DiagnosisOptions o;
  o.candidates = {"leak", "heat_transfer"};
  o.pair_pool = 0;
  return o;
}

TEST(DiagnosisStages, PrepareRunsChoosesAQuarterWithheldWhenNoRoleIsGiven) {
  const gs::PreparedRuns p = gs::prepareRuns(smallRuns({}, 1));
  EXPECT_TRUE(p.roles_chosen);
  EXPECT_EQ(p.fit.size() + p.withheld.size(), p.runs.size());
  EXPECT_GE(p.withheld.size(), 1u);
  EXPECT_GT(p.fit.size(), p.withheld.size());
  EXPECT_EQ(p.noises.size(), p.runs.size());
  EXPECT_EQ(p.measured_flow.size(), p.runs.size());
  for (std::size_t i : p.withheld) EXPECT_EQ(p.runs[i].role, "withheld");
  for (const auto& n : p.noises) EXPECT_GT(n.p_pa, 0.0);
}

TEST(DiagnosisStages, PrepareRunsKeepsGivenRolesAndRefusesBadOnes) {
  std::vector<nb::RunData> runs = smallRuns({}, 2);
  runs[0].role = "withheld";  // the others have none: fit runs
  const gs::PreparedRuns p = gs::prepareRuns(runs);
  EXPECT_FALSE(p.roles_chosen);
  EXPECT_EQ(p.withheld, std::vector<std::size_t>{0});

  runs[1].role = "training";
  EXPECT_THROW(
      {
        try {
          gs::prepareRuns(runs);
        } catch (const std::invalid_argument& e) {
          EXPECT_NE(std::string(e.what()).find("training"), std::string::npos) << e.what();
          throw;
        }
      },
      std::invalid_argument);
  for (auto& r : runs) r.role = "withheld";
  EXPECT_THROW(gs::prepareRuns(runs), std::invalid_argument);  // no fit run
  EXPECT_THROW(gs::prepareRuns({}), std::invalid_argument);
  EXPECT_THROW(gs::prepareRuns({smallRuns({}, 3)[0]}), std::invalid_argument);  // one run, no roles
}

TEST(DiagnosisStages, CandidateListIsTheCatalogueOrTheGivenNamesAndRefusesUnknownOnes) {
  nb::DiagnosisOptions o;
  EXPECT_EQ(gs::candidateList(o), nb::candidateEffectNames());
  o.candidates = {"leak"};
  EXPECT_EQ(gs::candidateList(o), std::vector<std::string>{"leak"});
  o.candidates = {"leak", "gremlins"};
  EXPECT_THROW(gs::candidateList(o), std::invalid_argument);
}

/// The stages up to the fits on one dataset, shared by the tests below.
class DiagnosisStagesOnALeak : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    const nb::CellParams params;
    state_ = new State{
        gs::prepareRuns(smallRuns({nb::makeEffect("leak", {{"leak_area_m2", 1e-8}})}, 7, true)), params, {}, {}};
    state_->nominal = gs::replayNominal(state_->prepared, params, leakOnly(), &state_->report);
  }
  static void TearDownTestSuite() {
    delete state_;
    state_ = nullptr;
  }
  struct State {
    gs::PreparedRuns prepared;
    nb::CellParams params;
    nb::DiagnosisReport report;
    std::vector<nb::Replay> nominal;
  };
  static State* state_;
};
DiagnosisStagesOnALeak::State* DiagnosisStagesOnALeak::state_ = nullptr;

TEST_F(DiagnosisStagesOnALeak, ReplayNominalFillsEveryRunAndLocatesTheGap) {
  const auto& s = *state_;
  ASSERT_EQ(s.nominal.size(), s.prepared.runs.size());
  ASSERT_EQ(s.report.runs.size(), s.prepared.runs.size());
  for (const auto& r : s.nominal) EXPECT_TRUE(r.ok) << r.message;
  EXPECT_GT(s.report.noise_p_pa, 0.0);
  EXPECT_FALSE(s.report.localization.empty());
}

TEST_F(DiagnosisStagesOnALeak, TheNoiseModelSeesTheLeakAsAGapAndTheFitsFindIt) {
  const auto& s = *state_;
  const gs::NoiseModel noise = gs::buildNoiseModel(s.prepared, s.params, leakOnly());
  EXPECT_EQ(noise.fit.runs.size(), s.prepared.fit.size());
  EXPECT_EQ(noise.held.runs.size(), s.prepared.withheld.size());
  const int n = noise.fitResidualCount();
  ASSERT_GT(n, 0);
  EXPECT_GT(noise.chi2_nominal / n, 5.0) << "a 1e-8 m2 leak is far outside the noise";
  EXPECT_TRUE(std::isfinite(noise.withheld_chi2_per_sample));

  const auto fits = gs::fitCandidates(noise, {"leak", "heat_transfer"}, leakOnly(), nullptr);
  ASSERT_EQ(fits.size(), 2u);  // no pairs with pair_pool 0
  EXPECT_EQ(fits[0].model.effects, std::vector<std::string>{"leak"});
  ASSERT_TRUE(fits[0].outcome.ok) << fits[0].outcome.message;
  EXPECT_LT(fits[0].outcome.chi2 / n, 1.5);

  const auto scored = gs::scoreCandidates(fits, s.prepared, noise, s.params, leakOnly());
  ASSERT_EQ(scored.size(), 2u);
  EXPECT_EQ(scored[0].first.effects, std::vector<std::string>{"leak"});  // lowest BIC first
  EXPECT_LE(scored[0].first.bic_delta, scored[1].first.bic_delta);
  EXPECT_NEAR(scored[0].first.params.at("leak_area_m2"), 1e-8, 0.3e-8);
  EXPECT_LT(scored[0].first.withheld_chi2_per_sample, noise.withheld_chi2_per_sample);
}

TEST_F(DiagnosisStagesOnALeak, PairsAreFittedFromTheirSinglesInCatalogueOrder) {
  const auto& s = *state_;
  nb::DiagnosisOptions o = leakOnly();
  o.pair_pool = 2;
  o.max_iterations = 3;      // the pair's fit itself is not under test here
  o.joint_refit_chi2 = 0.0;  // the leak alone fits within the noise: no pair else
  const gs::NoiseModel noise = gs::buildNoiseModel(s.prepared, s.params, o);
  const auto fits = gs::fitCandidates(noise, {"heat_transfer", "leak"}, o, nullptr);
  ASSERT_EQ(fits.size(), 3u);
  std::vector<std::string> catalogue_order;
  for (const auto& e : nb::effectCatalog())
    if (e.name == "leak" || e.name == "heat_transfer") catalogue_order.push_back(e.name);
  EXPECT_EQ(fits[2].model.effects, catalogue_order);
}

TEST_F(DiagnosisStagesOnALeak, ShrinkageWithoutEffectsKeepsTheNominalReplays) {
  auto s = *state_;
  gs::shrinkage(s.prepared, s.params, {}, {}, s.nominal, leakOnly(), &s.report);
  ASSERT_EQ(s.report.traces.size(), s.prepared.runs.size());
  EXPECT_EQ(s.report.withheld_before, s.report.withheld_after);
  EXPECT_EQ(s.report.traces[0].p_after_pa, s.report.traces[0].p_nominal_pa);

  auto t = *state_;
  gs::shrinkage(t.prepared, t.params, {}, {nb::makeEffect("leak", {{"leak_area_m2", 1e-8}})}, t.nominal, leakOnly(),
                &t.report);
  EXPECT_LT(t.report.withheld_after, 0.5 * t.report.withheld_before);
}

/// A fitted model of `effects` whose chi2 is `chi2` (no replay: for the stages that only rank).
gs::ModelFit rankedFit(const std::vector<std::string>& effects, double chi2, bool ok = true) {
  gs::ModelFit f;
  f.model = gs::makeModelSpec(effects);
  f.outcome.ok = ok;
  f.outcome.chi2 = chi2;
  return f;
}

TEST(DiagnosisStages, JointRefitsTakeTheBestPairAndEveryPairOfASingleThatMovedTheCalibration) {
  // A plate friction bends the calibration-only fit as a stiffer film does; the viscoelasticity's
  // joint refit moved the calibration, so its pairs are refitted too, however badly they ranked
  // on the bent calibration (the right one, with the friction, ranked last).
  const std::vector<gs::ModelFit> fits = {
      rankedFit({"membrane_viscoelasticity"}, 3000.0),                         // 0: a single, never a pair's refit
      rankedFit({"heat_transfer", "plate_friction"}, 1800.0),                  // 1: the best pair
      rankedFit({"leak", "membrane_viscoelasticity"}, 4900.0),                 // 2
      rankedFit({"membrane_viscoelasticity", "plate_friction"}, 5500.0),       // 3
      rankedFit({"leak", "plate_friction"}, 3200.0),                           // 4
      rankedFit({"heat_transfer", "membrane_viscoelasticity"}, 100.0, false),  // 5: failed
  };
  const double log_n = std::log(1716.0);
  EXPECT_EQ(gs::jointRefitOrder(fits, 2, 1, {}, log_n), (std::vector<int>{1}));
  EXPECT_EQ(gs::jointRefitOrder(fits, 2, 1, {"membrane_viscoelasticity"}, log_n), (std::vector<int>{1, 2, 3}));
  EXPECT_EQ(gs::jointRefitOrder(fits, 2, 0, {"plate_friction"}, log_n), (std::vector<int>{1, 4, 3}));
  EXPECT_EQ(gs::jointRefitOrder(fits, 1, 3, {"leak"}, log_n), (std::vector<int>{0}));
  EXPECT_TRUE(gs::jointRefitOrder(fits, 2, 0, {}, log_n).empty());
}

TEST(DiagnosisStages, PairsAreTheBestSingleWithEveryOtherAndThePoolsPairs) {
  // A sensor lag beside a flow meter's bias barely moves chi2 alone (the bias hides it): it ranks
  // last, and only the best single's pairs reach it.
  const std::vector<gs::ModelFit> fits = {
      rankedFit({"pressure_sensor_lag"}, 9000.0),  // 0
      rankedFit({"inflow_bias"}, 1200.0),          // 1: the best
      rankedFit({"leak"}, 5000.0),                 // 2
      rankedFit({"heat_transfer"}, 6000.0),        // 3
      rankedFit({"supply_line"}, 100.0, false),    // 4: failed
  };
  const std::vector<int> order{1, 2, 3, 0, 4};
  using Pairs = std::vector<std::pair<int, int>>;
  EXPECT_EQ(gs::pairsToFit(fits, order, 1, 1000, 1.1), (Pairs{{1, 2}, {1, 3}, {1, 0}}));
  EXPECT_EQ(gs::pairsToFit(fits, order, 2, 1000, 1.1), (Pairs{{1, 2}, {1, 3}, {1, 0}, {2, 3}, {2, 0}}));
  EXPECT_TRUE(gs::pairsToFit(fits, order, 0, 1000, 1.1).empty()) << "pool 0: no pairs";
  EXPECT_TRUE(gs::pairsToFit(fits, order, 3, 1200, 1.1).empty()) << "the best single is within the noise";
  EXPECT_EQ(gs::pairsToFit(fits, {4, 1}, 3, 1000, 1.1), Pairs{}) << "one ok single: nothing to pair";
}

TEST(DiagnosisStages, WhereTheBestSinglesAreDistortionsTheBestPhysicalEffectJoinsThePool) {
  // A load offset imitates a plate's friction alone; the friction's partner (viscoelasticity)
  // is reached only from the friction.
  const std::vector<gs::ModelFit> fits = {
      rankedFit({"load_offset"}, 1000.0),               // 0: the best
      rankedFit({"plate_friction"}, 1100.0),            // 1: the best physical effect
      rankedFit({"membrane_viscoelasticity"}, 5000.0),  // 2
  };
  using Pairs = std::vector<std::pair<int, int>>;
  EXPECT_EQ(gs::pairsToFit(fits, {0, 1, 2}, 1, 100, 1.1), (Pairs{{0, 1}, {0, 2}, {1, 2}}));
  // A physical effect the best: the pool as it is.
  EXPECT_EQ(gs::pairsToFit(fits, {1, 0, 2}, 1, 100, 1.1), (Pairs{{1, 0}, {1, 2}}));
}

TEST(DiagnosisStages, MedianAndFmt) {
  EXPECT_DOUBLE_EQ(gs::median({3.0, 1.0, 2.0}), 2.0);
  EXPECT_DOUBLE_EQ(gs::median({4.0, 1.0, 2.0, 3.0}), 2.5);
  EXPECT_TRUE(std::isnan(gs::median({})));
  EXPECT_EQ(gs::fmt(1.23456), "1.23");
  EXPECT_EQ(gs::fmt(1.23456, 5), "1.2346");
}

}  // namespace

namespace {

/// A bed cell's recording of a lift-off from flat at 50 Hz: valve pulses reported as interval
/// means (alternating full and half intervals, as the controller's pulses come out), then 5 s
/// sealed.
nb::RunData pulsedLiftOff(bool interval_means) {
  nb::RunData run;
  run.name = "lift_off";
  run.load_n = 10.6;
  run.flow_interval_means = interval_means;
  for (int i = 0; i <= 300; ++i) {
    run.t_s.push_back(0.02 * i);
    const bool inflating = i >= 10 && i < 60;
    run.mdot_in_kg_s.push_back(inflating ? (i % 3 == 0 ? 1.8e-3 : 3.7e-3) : 0.0);
    run.valve_cmd.push_back(inflating ? (i % 3 == 0 ? 0.5 : 1.0) : 0.0);
    run.p_gauge_pa.push_back(0.0);
    run.h_m.push_back(0.0);
  }
  return run;
}

}  // namespace

TEST(DiagnosisStages, TimingSpreadRingsAtTheLiftOffAndKeepsItsLastingOffsetShared) {
  const nb::CellParams params;
  const nb::RunData instant = pulsedLiftOff(false);
  const nb::Replay instant_replay = nb::replayRun(instant, params, {});
  ASSERT_TRUE(instant_replay.ok) << instant_replay.message;
  // Instantaneous readings: the timing is known, no spread.
  const gs::TimingSpread none = gs::timingSpread(instant, params, instant_replay);
  EXPECT_TRUE(none.modes.empty());
  for (double v : none.var_p) EXPECT_EQ(v, 0.0);

  const nb::RunData means = pulsedLiftOff(true);
  const nb::Replay nominal = nb::replayRun(means, params, {});
  ASSERT_TRUE(nominal.ok) << nominal.message;
  const gs::TimingSpread spread = gs::timingSpread(means, params, nominal);
  ASSERT_EQ(spread.modes.size(), 2u);  // half an interval earlier and later
  ASSERT_EQ(spread.var_p.size(), means.size());
  // While the pulses come, the readings spread (the plate rings); sealed, the ringing is over:
  // what the timing changed for good is in the modes, shared by every later sample, not white.
  double pulsing = 0.0, sealed_white = 0.0, sealed_mode = 0.0;
  for (std::size_t i = 10; i < 60; ++i) pulsing = std::max(pulsing, std::sqrt(spread.var_p[i]));
  for (std::size_t i = 200; i < means.size(); ++i) {
    sealed_white = std::max(sealed_white, std::sqrt(spread.var_p[i]));
    for (const gs::ErrorMode& m : spread.modes) sealed_mode = std::max(sealed_mode, std::abs(m.p[i]));
  }
  std::cout << "timing spread: pulsing up to " << pulsing << " Pa, sealed white " << sealed_white << " Pa, lasting "
            << sealed_mode << " Pa\n";
  EXPECT_GT(pulsing, 10.0);
  EXPECT_LT(sealed_white, 1.0);
  EXPECT_GT(sealed_mode, 1.0);
}
