// Replaying runs through the model, phases, noise estimate and where the gap lies.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "nursing_bed/core/gap/effects.h"
#include "nursing_bed/core/gap/replay.h"
#include "nursing_bed/core/gap/synth.h"

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

TEST(GapReplay, AMeteredRunWithoutHeightLandsWhenTheVentHasEmptiedIt) {
  // Without height readings the landing shows as the vent's flow and pressure falling to zero;
  // replayed past it, the meter's noise would be drawn out of the few mL left.
  const nb::RunData with_height = synthRun({}, 1.0);
  nb::RunData run = with_height;
  for (double& h : run.h_m) h = NAN;
  const std::vector<nb::RunPhase> by_height = nb::classifyPhases(with_height), by_flow = nb::classifyPhases(run);
  auto first_landed = [&](const std::vector<nb::RunPhase>& ph) {
    const auto it = std::find(ph.begin(), ph.end(), nb::RunPhase::kLanded);
    return it == ph.end() ? NAN : run.t_s[it - ph.begin()];
  };
  ASSERT_TRUE(std::isfinite(first_landed(by_height)));
  EXPECT_NEAR(first_landed(by_flow), first_landed(by_height), 0.3);
  const nb::Replay rep = nb::replayRun(run, nb::CellParams{}, {});
  ASSERT_TRUE(rep.ok) << rep.message;
  // Within a few noise floors (30 Pa) of a range of several kPa.
  EXPECT_LT(nb::runResidual(run, rep).nrmse_p, 0.01);
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

TEST(GapReplay, ACoarselyQuantisedChannelsNoiseIsAtLeastItsRounding) {
  std::mt19937 rng(4);
  std::normal_distribution<double> noise(0.0, 30.0);
  std::vector<double> slow, fine, smooth;
  for (int i = 0; i < 5000; ++i) {
    const double p = 10000.0 + 2000.0 * std::sin(i * 0.002) + noise(rng);
    slow.push_back(250.0 * std::round(p / 250.0));  // steps far above the noise: flat stretches
    fine.push_back(10.0 * std::round(p / 10.0));    // steps below it: the noise shows
    smooth.push_back(p);
  }
  EXPECT_NEAR(nb::quantisationStep(slow), 250.0, 1e-9);
  EXPECT_NEAR(nb::estimateNoise(slow), 250.0 / std::sqrt(12.0), 1e-9);
  EXPECT_NEAR(nb::quantisationStep(fine), 10.0, 1e-9);
  EXPECT_NEAR(nb::estimateNoise(fine), 30.0, 4.0);
  EXPECT_EQ(nb::quantisationStep(smooth), 0.0);
  EXPECT_EQ(nb::quantisationStep({1.0, 1.0, 2.0}), 0.0);  // too few changes to tell
  // A lattice printed in decimals: 0.001 cmH2O, its float error far below the tolerance.
  std::vector<double> printed;
  for (int i = 0; i < 200; ++i) printed.push_back(std::round((15.0 + 0.3 * std::sin(i * 0.1)) * 1000.0) / 1000.0);
  EXPECT_NEAR(nb::quantisationStep(printed), 0.001, 1e-9);
}

TEST(GapReplay, AFailedReplaySaysWhy) {
  nb::RunData run = synthRun({}, 0.0);
  for (double& q : run.mdot_in_kg_s) q = NAN;
  const nb::Replay rep = nb::replayRun(run, nb::CellParams{}, {});
  EXPECT_FALSE(rep.ok);
  EXPECT_NE(rep.message.find("inflow"), std::string::npos) << rep.message;
}

}  // namespace

namespace {
/// A run whose hold reads flow-meter noise around `offset_kg_s`; valve_cmd dropped when asked.
nb::RunData holdWithMeterReading(double offset_kg_s, bool keep_valve_cmd) {
  nb::RunData run = synthRun({}, 0.0);
  std::mt19937 rng(5);
  std::normal_distribution<double> noise(0.0, 5e-6);
  for (std::size_t i = 0; i < run.size(); ++i)
    if (run.valve_cmd[i] == 0.0) run.mdot_in_kg_s[i] = offset_kg_s + noise(rng);
  if (!keep_valve_cmd) run.valve_cmd.clear();
  return run;
}
}  // namespace

TEST(GapReplay, ClosedInletNoiseIsZeroedButAMeterOffsetIsKept) {
  for (bool valve : {true, false}) {
    nb::RunData noisy = holdWithMeterReading(0.0, valve);
    const nb::RunData before = noisy;
    EXPECT_GT(nb::zeroClosedInletFlow(&noisy), 1000) << "valve_cmd " << valve;
    int zero_in_hold = 0, inflow_changed = 0;
    for (std::size_t i = 0; i < noisy.size(); ++i) {
      if (before.t_s[i] > 10.0 && before.t_s[i] < 30.0) zero_in_hold += noisy.mdot_in_kg_s[i] == 0.0;
      if (before.t_s[i] < 2.0) inflow_changed += noisy.mdot_in_kg_s[i] != before.mdot_in_kg_s[i];
    }
    EXPECT_GT(zero_in_hold, 900);                            // the hold (50 Hz, 20 s) is zero
    EXPECT_EQ(inflow_changed, 0);                            // the inflation is untouched
    nb::RunData offset = holdWithMeterReading(3e-6, valve);  // 3e-6 kg/s: ~40 standard errors
    const nb::RunData kept = offset;
    EXPECT_EQ(nb::zeroClosedInletFlow(&offset), 0);
    EXPECT_EQ(offset.mdot_in_kg_s, kept.mdot_in_kg_s);
  }
}

TEST(GapReplay, AnUnmeteredVentValveIsRecognisedAndReplayed) {
  // A bed's cell: venting through its own valve (valve_cmd -1) while the inlet meter reads 0.
  nb::RunData run = synthRun({}, 0.0);
  EXPECT_FALSE(nb::ventsThroughUnmeteredValve(run));  // the generator vents through the meter
  const nb::Replay metered = nb::replayRun(run, nb::CellParams{}, {});
  for (std::size_t i = 0; i < run.size(); ++i)
    if (run.valve_cmd[i] < 0.0) run.mdot_in_kg_s[i] = 0.0;
  EXPECT_TRUE(nb::ventsThroughUnmeteredValve(run));
  const nb::Replay vented = nb::replayRun(run, nb::CellParams{}, {});
  ASSERT_TRUE(metered.ok && vented.ok) << vented.message;
  // The model's own vent valve empties it: the height falls in the vent as the data's does.
  auto at = [&](double t) {
    std::size_t i = 0;
    while (i + 1 < run.size() && run.t_s[i] < t) ++i;
    return i;
  };
  EXPECT_LT(vented.h_m[at(38.0)], vented.h_m[at(30.0)] - 0.02);  // 30 s: hold, 38 s: venting
  EXPECT_NEAR(vented.h_m[at(38.0)], metered.h_m[at(38.0)], 0.01);
}

TEST(GapReplay, AValveOfItsOwnIsRecognisedWhenTheCellVentsInSinglePulses) {
  // A controller trimming a cell near its target vents in pulses of a few ms, one interval each
  // and never two in a row; the meter reads 0 then (valve of its own) or the pulse's outflow.
  const double dt = 0.02, inflow_kg_s = 1.5e-3, vent_full_kg_s = -1.5e-3;
  auto pulsedRun = [&](bool metered_vent) {
    nb::RunData run;
    for (int i = 0; i <= 200; ++i) {
      const bool inflating = i > 10 && i <= 60;
      const bool pulse = i > 80 && i % 20 == 0;  // 6 isolated vent pulses, 10-40 % open
      const double cmd = inflating ? 1.0 : pulse ? -0.1 * (1 + (i / 20) % 4) : 0.0;
      run.t_s.push_back(i * dt);
      run.valve_cmd.push_back(cmd);
      run.mdot_in_kg_s.push_back(inflating ? inflow_kg_s : pulse && metered_vent ? -cmd * vent_full_kg_s : 0.0);
      run.p_gauge_pa.push_back(0.0);
      run.h_m.push_back(0.1);
    }
    return run;
  };
  EXPECT_TRUE(nb::ventsThroughUnmeteredValve(pulsedRun(false)));
  EXPECT_FALSE(nb::ventsThroughUnmeteredValve(pulsedRun(true)));
}

TEST(GapReplay, IntervalMeanFlowPutsEachPulseInItsOwnInterval) {
  // A bed's cell reports the mean flow since its previous message; a valve pulse of a few ms
  // shows as one sample. Replayed as interval means, the pulse's gas is in by the sample that
  // reports it; interpolated, only half of it.
  const nb::CellParams params;
  nb::RunData run;
  run.name = "pulse";
  run.load_n = 10.6;
  const double dt = 0.02, pulse_kg_s = 2e-4;
  for (int i = 0; i <= 100; ++i) {
    run.t_s.push_back(i * dt);
    run.mdot_in_kg_s.push_back(i == 50 ? pulse_kg_s : 0.0);
    run.p_gauge_pa.push_back(0.0);
    run.h_m.push_back(0.135);  // near full height: the pressure shows the gas
  }
  auto massAt = [&](bool interval_means, std::size_t i) {
    run.flow_interval_means = interval_means;
    // The gas in the bag at sample i, from the replay's pressure rise over the first sample's.
    const nb::Replay rep = nb::replayRun(run, params, {});
    EXPECT_TRUE(rep.ok) << rep.message;
    return rep.p_gauge_pa[i] - rep.p_gauge_pa[0];
  };
  const double full_rise = massAt(true, 100);
  ASSERT_GT(full_rise, 50.0);
  EXPECT_NEAR(massAt(true, 100), massAt(false, 100), 0.01 * full_rise);  // the same gas in the end
  // All of it by sample 50 (the plate, kicked, overshoots a little); interpolated, half.
  EXPECT_GT(massAt(true, 50), 0.9 * full_rise);
  EXPECT_LT(massAt(false, 50), 0.7 * massAt(true, 50));
}

TEST(GapReplay, MeterNoiseIsTakenWhereTheValveHeldStillNotFromValvePulses) {
  // 20 s at 50 Hz: a steady inflow with the meter's noise (valve open), then a controller
  // holding with 5 ms pulses in every other sample (valve_cmd the mean opening, 0.25).
  std::mt19937 rng(3);
  std::normal_distribution<double> meter(0.0, 2e-6);
  nb::RunData run;
  for (int i = 0; i < 1000; ++i) {
    const bool pulsing = i >= 500;
    const bool pulse = pulsing && i % 2 == 0;
    run.t_s.push_back(0.02 * i);
    run.valve_cmd.push_back(pulsing ? (pulse ? 0.25 : 0.0) : 1.0);
    run.mdot_in_kg_s.push_back(pulsing ? (pulse ? 1e-4 : 0.0) : 5e-5 + meter(rng));
  }
  run.p_gauge_pa.assign(run.size(), 0.0);
  run.h_m.assign(run.size(), 0.1);
  const std::vector<double> noise = nb::meterNoise(run, run.mdot_in_kg_s, 25);
  EXPECT_NEAR(noise[250], 2e-6, 0.5e-6);  // steady: the meter's noise
  EXPECT_LT(noise[800], 4e-6);            // pulses: not noise; the run's steady estimate
  // Without valve_cmd the pulses cannot be told from noise: they count.
  run.valve_cmd.clear();
  EXPECT_GT(nb::meterNoise(run, run.mdot_in_kg_s, 25)[800], 1e-5);
}

TEST(GapReplay, PooledResidualUsesTheRangeOverAllRuns) {
  const nb::RunData a = synthRun({}, 1.0, 0), b = synthRun({}, 1.0, 3);
  const nb::Replay ra = nb::replayRun(a, nb::CellParams{}, {}), rb = nb::replayRun(b, nb::CellParams{}, {});
  const nb::RunResidual pooled = nb::pooledResidual({&a, &b}, {&ra, &rb});
  EXPECT_GE(pooled.range_p_pa, std::max(nb::runResidual(a, ra).range_p_pa, nb::runResidual(b, rb).range_p_pa));
  EXPECT_EQ(pooled.samples, nb::runResidual(a, ra).samples + nb::runResidual(b, rb).samples);
}

TEST(GapReplay, HiddenEffectsFromTextAreCheckedAndNamed) {
  EXPECT_TRUE(nb::effectsFromText("", 1).empty());
  const auto two = nb::effectsFromText("leak:leak_area_m2=5e-9; heat_transfer", 3);
  ASSERT_EQ(two.size(), 2u);
  EXPECT_EQ(two[0]->name(), "heat_transfer");  // catalogue order
  EXPECT_EQ(two[1]->name(), "leak");
  EXPECT_DOUBLE_EQ(two[1]->parameters().at("leak_area_m2"), 5e-9);
  for (const char* bad : {"lek", "leak:leak_area_m2=abc", "leak:area=1e-9", "leak:leak_area_m2=-1"}) {
    try {
      nb::effectsFromText(bad, 1);
      ADD_FAILURE() << "accepted '" << bad << "'";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).size(), 0u) << bad;
    }
  }
}

namespace {

/// A bellows at rest under a constant pressure, no height sensor, no flow: a lung held at PEEP.
nb::RunData restingRun(double p_gauge_pa) {
  nb::RunData run;
  run.name = "peep.csv";
  run.load_n = 0.0;
  for (int i = 0; i <= 100; ++i) {
    run.t_s.push_back(0.01 * i);
    run.p_gauge_pa.push_back(p_gauge_pa + (i % 2 ? 5.0 : -5.0));
    run.h_m.push_back(NAN);
    run.mdot_in_kg_s.push_back(0.0);
  }
  return run;
}

nb::CellParams bellowsParams() {
  nb::CellParams p;
  p.structure_type = "bellows";
  p.plate_mass_kg = 0.1;
  p.plate_damping_n_s_m = 100.0;
  return p;
}

}  // namespace

TEST(GapReplay, ARunWithoutHeightStartsAtRestAtItsFirstPressure) {
  const nb::Replay r = nb::replayRun(restingRun(490.0), bellowsParams(), {});
  ASSERT_TRUE(r.ok) << r.message;
  EXPECT_NEAR(r.p_gauge_pa.front(), 490.0, 1.0);
  EXPECT_NEAR(r.p_gauge_pa.back(), 490.0, 1.0);  // and stays there without flow
  const double h_peep = 490.0 * bellowsParams().bellows.area_m2 / bellowsParams().bellows.springRate();
  EXPECT_NEAR(r.h_m.front(), h_peep, 0.005 * h_peep);  // the mean of the first 0.2 s, noise in it
}

TEST(GapReplay, ARunWithoutHeightAtNoisePressureStartsFlat) {
  const nb::Replay r = nb::replayRun(restingRun(20.0), bellowsParams(), {});
  ASSERT_TRUE(r.ok) << r.message;
  EXPECT_NEAR(r.p_gauge_pa.front(), 0.0, 1e-9);
  // A height-less synthetic airbag run starts flat as before.
  nb::RunData airbag = synthRun({}, 1.0);
  for (double& h : airbag.h_m) h = NAN;
  const nb::Replay a = nb::replayRun(airbag, nb::CellParams{}, {});
  ASSERT_TRUE(a.ok) << a.message;
  EXPECT_NEAR(a.p_gauge_pa.front(), 0.0, 1e-9);
}
