// Replaying runs through the model, phases, noise estimate and where the gap lies.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "nursing_bed/core/gap_effects.h"
#include "nursing_bed/core/gap_replay.h"
#include "nursing_bed/core/gap_synth.h"

namespace nb = nursing_bed;

namespace {

nb::RunData synthRun(const std::vector<nb::CellEffectPtr>& effects, double noise_factor, std::size_t plan_index = 3) {
  const nb::CellParams params;
  const nb::SynthProtocol protocol = nb::synthProtocol("small", params);
  std::mt19937 rng(7);
  return nb::simulateSynthRun(params, effects, protocol, protocol.runs.at(plan_index),
                              nb::SensorNoise{}.scaled(noise_factor), noise_factor > 0 ? &rng : nullptr);
}

TEST(GapReplay, PhasesFollowTheProtocol) {
  const nb::RunData run = synthRun({}, 0.0);
  const std::vector<nb::RunPhase> ph = nb::classifyPhases(run);
  auto phase_at = [&](double t) {
    std::size_t i = 0;
    while (i + 1 < run.size() && run.t_s[i] < t) ++i;
    return ph[i];
  };
  EXPECT_EQ(phase_at(0.5), nb::RunPhase::kDeploy);
  EXPECT_EQ(phase_at(2.0), nb::RunPhase::kPressurize);
  EXPECT_EQ(phase_at(20.0), nb::RunPhase::kHold);
  EXPECT_EQ(phase_at(36.0), nb::RunPhase::kVent);
  EXPECT_EQ(ph.back(), nb::RunPhase::kLanded);
}

TEST(GapReplay, NominalModelReplaysNominalDataExactly) {
  // Noise-free data from the nominal model: the replay driven by its inflow gives it back.
  const nb::RunData run = synthRun({}, 0.0);
  const nb::Replay rep = nb::replayRun(run, nb::CellParams{}, {});
  ASSERT_TRUE(rep.ok) << rep.message;
  const nb::RunResidual r = nb::runResidual(run, rep);
  EXPECT_GT(r.samples, 1000);
  EXPECT_LT(r.nrmse_p, 2e-3);
  EXPECT_LT(r.nrmse_h, 2e-3);
}

TEST(GapReplay, ALeakLeavesItsGapInTheHold) {
  const auto leak = nb::makeEffect("leak", {{"leak_area_m2", 2e-8}});
  const nb::RunData run = synthRun({leak}, 0.0);
  const nb::Replay nominal = nb::replayRun(run, nb::CellParams{}, {});
  const nb::Replay with_leak = nb::replayRun(run, nb::CellParams{}, {leak});
  ASSERT_TRUE(nominal.ok && with_leak.ok);
  EXPECT_GT(nb::runResidual(run, nominal).nrmse(), 0.02);
  EXPECT_LT(nb::runResidual(run, with_leak).nrmse(), 2e-3);  // the right effect closes it
  const std::vector<nb::GapShare> where = nb::localizeGap({run}, {nominal});
  ASSERT_FALSE(where.empty());
  EXPECT_EQ(where.front().phase, "hold") << where.front().signal;
  double total = 0.0;
  for (const auto& g : where) total += g.share;
  EXPECT_NEAR(total, 1.0, 1e-9);
}

TEST(GapReplay, NoiseEstimateRecoversTheSensorNoise) {
  std::mt19937 rng(3);
  std::normal_distribution<double> noise(0.0, 30.0);
  std::vector<double> x;
  for (int i = 0; i < 5000; ++i) x.push_back(20000.0 * std::sin(i * 0.002) + noise(rng));
  EXPECT_NEAR(nb::estimateNoise(x), 30.0, 3.0);
  // On generated data: close to the generator's sd (quantisation adds a little).
  const nb::RunData run = synthRun({}, 1.0);
  EXPECT_NEAR(nb::estimateNoise(run.p_gauge_pa), 30.0, 6.0);
  EXPECT_NEAR(nb::estimateNoise(run.h_m), 0.3e-3, 0.06e-3);
}

TEST(GapReplay, AFailedReplaySaysWhy) {
  nb::RunData run = synthRun({}, 0.0);
  for (double& q : run.mdot_in_kg_s) q = NAN;
  const nb::Replay rep = nb::replayRun(run, nb::CellParams{}, {});
  EXPECT_FALSE(rep.ok);
  EXPECT_NE(rep.message.find("inflow"), std::string::npos) << rep.message;
}

}  // namespace
