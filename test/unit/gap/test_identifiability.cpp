// Identifiability and the next experiment: the run plans gap synth adds (--add-run), the
// explanations one load cannot tell apart, and the proposed run that tells them apart.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

#include "nursing_bed/core/gap/diagnosis.h"
#include "nursing_bed/core/gap/identifiability.h"
#include "nursing_bed/core/gap/synth.h"

#include "../../test_helpers.h"

namespace nb = nursing_bed;
namespace fs = std::filesystem;

namespace {

fs::path tmpDir(const std::string& name) { return nursing_bed::test::freshTestDir("gap_identify", name, false); }

TEST(RunPlan, ParsesWhatGapSynthAddsAndRefusesTheRestNamingIt) {
  const nb::CellParams params;
  const nb::SynthRunPlan r = nb::parseRunPlan("load_n=36,flow=high,rise_scale=3", params);
  EXPECT_DOUBLE_EQ(r.load_n, 36.0);
  EXPECT_EQ(r.flow, "high");
  EXPECT_DOUBLE_EQ(r.rise_scale, 3.0);
  EXPECT_EQ(r.role, "fit");
  EXPECT_EQ(r.name, "load36p0N_high_rise3p0.csv");
  EXPECT_GT(r.inflow_mass_kg, 0.0);
  EXPECT_EQ(nb::parseRunPlan("flow=low,load_n=5,role=withheld", params).role, "withheld");
  for (const auto& [text, named] :
       std::vector<std::pair<std::string, std::string>>{{"load_n=36", "load_n and flow are required"},
                                                        {"load_n=36,flow=medium", "medium"},
                                                        {"load_n=abc,flow=low", "abc"},
                                                        {"load_n=1e9,flow=low", "outside"},
                                                        {"load_n=5,flow=low,rise_scale=0", "rise_scale"},
                                                        {"load_n=5,flow=low,speed=2", "speed=2"},
                                                        {"load_n=5,load_n=6,flow=low", "twice"},
                                                        {"load_n=5,flow=low,role=test", "role"}}) {
    try {
      nb::parseRunPlan(text, params);
      ADD_FAILURE() << text << " was accepted";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(named), std::string::npos) << e.what();
    }
  }
}

TEST(RunPlan, SynthAddsTheRunsAndRefusesOneThatIsThereAlready) {
  nb::SynthOptions o;
  o.protocol = "small";
  o.noise_scale = 0.0;
  o.out_dir = tmpDir("added").string();
  o.extra_runs = {"load_n=25,flow=low,rise_scale=2"};
  const nb::SynthResult r = nb::synthesizeDataset(o);
  ASSERT_EQ(r.runs.size(), 5u);
  EXPECT_EQ(r.runs.back().name, "load25p0N_low_rise2p0.csv");
  EXPECT_EQ(r.runs.back().role, "fit");
  // The rise twice as long: the run is the protocol's inflation time longer.
  EXPECT_NEAR(r.runs.back().t_s.back() - r.runs.front().t_s.back(), r.protocol.inflate_s, 1e-9);
  o.out_dir = tmpDir("refused").string();
  fs::remove_all(o.out_dir);
  o.extra_runs = {"load_n=15.6,flow=low"};
  EXPECT_THROW(nb::synthesizeDataset(o), std::invalid_argument);
  EXPECT_FALSE(fs::exists(fs::path(o.out_dir) / "dataset.yaml"));
}

/// One run of the small protocol (`run`, with a pressure gain of +5 %) to fit, the same run of
/// another seed withheld, and `extra` runs added to the fit runs.
std::vector<nb::RunData> oneRun(const std::string& run_name, bool height, const std::vector<std::string>& extra) {
  std::vector<nb::RunData> runs;
  for (const std::uint32_t seed : {5u, 6u}) {
    nb::SynthOptions o;
    o.protocol = "small";
    o.seed = seed;
    o.distortions = {"pressure:gain=0.05"};
    o.height_sensor = height;
    o.extra_runs = seed == 5u ? extra : std::vector<std::string>{};
    o.out_dir = tmpDir("one_run_" + std::to_string(seed)).string();
    nb::SynthResult r = nb::synthesizeDataset(o);
    const std::size_t protocol_runs = r.runs.size() - o.extra_runs.size();
    for (std::size_t k = 0; k < r.runs.size(); ++k) {
      nb::RunData& run = r.runs[k];
      if (k >= protocol_runs) runs.push_back(run);  // the added runs, fitted
      if (run.name != run_name) continue;
      run.role = seed == 5u ? "fit" : "withheld";
      if (seed == 6u) run.name = "withheld_seed6.csv";
      runs.push_back(run);
    }
  }
  return runs;
}

/// One load (15.6 N, low flow), where a recorded load that is too light reads like a pressure
/// gauge that reads high.
std::vector<nb::RunData> oneLoad(const std::vector<std::string>& extra) {
  return oneRun("load15p6N_low.csv", true, extra);
}

nb::DiagnosisOptions gainsOnly() {
  nb::DiagnosisOptions o;
  o.candidates = {"pressure_gain", "load_gain"};
  o.pair_pool = 0;
  o.calibrate = false;
  o.discover = false;
  return o;
}

TEST(Identifiability, OneLoadCannotTellAPressureGainFromALoadGainAndTheProposedRunCan) {
  const nb::CellParams params;
  const nb::DiagnosisReport one = nb::diagnoseRuns(oneLoad({}), params, gainsOnly(), "one load");
  ASSERT_EQ(one.status, "explained");
  ASSERT_EQ(one.confusions.size(), 1u);
  const nb::Confusion& c = one.confusions[0];
  EXPECT_EQ(c.a, one.verdict_effects[0]);
  EXPECT_EQ(c.a == "pressure_gain" ? c.b : c.a, "load_gain");
  EXPECT_GT(c.correlation, 0.99);
  EXPECT_LT(std::fabs(c.bic_a - c.bic_b), gainsOnly().near_tie_bic);
  ASSERT_TRUE(c.proposed) << nb::gap::describeConfusion(c);
  EXPECT_NE(c.load_n, 15.6);  // another load: the one they read alike at says nothing
  EXPECT_GT(c.separation_chi2, 100.0 * c.fit_separation_chi2);
  bool said = false;
  for (const auto& line : one.reasons) said = said || line.find("gap synth --add-run load_n=") != std::string::npos;
  EXPECT_TRUE(said);

  // The run it proposes, synthesised with the same truth: the two are told apart.
  const nb::DiagnosisReport two =
      nb::diagnoseRuns(oneLoad({nb::gap::addRunArgument(c)}), params, gainsOnly(), "with the proposed run");
  EXPECT_EQ(two.status, "explained");
  EXPECT_EQ(two.verdict_effects, std::vector<std::string>{"pressure_gain"});
  EXPECT_TRUE(two.confusions.empty());
  ASSERT_GE(two.candidates.size(), 2u);
  EXPECT_GT(two.candidates[1].bic_delta - two.candidates[0].bic_delta, 10.0 * gainsOnly().near_tie_bic);
}

TEST(Identifiability, OneRunOnPressureAloneCannotTellAPressureGainFromTheFilmAndTheProposedRunCan) {
  // 0.6 N, high flow, no height: the film holds the plate at the bag's top, and a stiffer film
  // raises the pressure there as a gauge reading 5 % high does.
  nb::DiagnosisOptions o;
  o.candidates = {"pressure_gain"};
  o.discover = false;
  const nb::CellParams params;
  const nb::DiagnosisReport one = nb::diagnoseRuns(oneRun("load0p6N_high.csv", false, {}), params, o, "one run");
  const nb::Confusion* tie = nullptr;
  for (const auto& c : one.confusions)
    if (c.a == "film_stiffness_scale" && c.b == "pressure_gain") tie = &c;
  ASSERT_NE(tie, nullptr) << one.status << ", " << one.confusions.size() << " confusions";
  EXPECT_GT(tie->correlation, 0.99);
  ASSERT_TRUE(tie->proposed) << nb::gap::describeConfusion(*tie);
  EXPECT_GT(tie->separation_chi2, 10.0 * tie->fit_separation_chi2);

  // The run it proposes, synthesised with the same truth: the gauge's gain is named alone.
  const nb::DiagnosisReport two = nb::diagnoseRuns(oneRun("load0p6N_high.csv", false, {nb::gap::addRunArgument(*tie)}),
                                                   params, o, "with the proposed run");
  EXPECT_EQ(two.status, "explained");
  EXPECT_EQ(two.verdict_effects, std::vector<std::string>{"pressure_gain"});
  EXPECT_NEAR(two.verdict_params.at("pressure_gain"), 0.05, 0.005);
  EXPECT_FALSE(two.calibration.anyMoved());
  EXPECT_TRUE(two.confusions.empty());
}

TEST(Identifiability, TheSmallProtocolNamesViscoelasticityAloneAndTheProposedRunAddsTheFriction) {
  // Viscoelasticity and a 0.3 N friction on the small protocol: the viscoelasticity alone fits
  // both run sets by the bar, its pair with the friction fits better; the report proposes the
  // run that tells, and with it the pair is named.
  auto dataset = [](const std::vector<std::string>& extra) {
    nb::SynthOptions o;
    o.protocol = "small";
    o.seed = 7;
    o.effects = {nb::parseEffectRequest("membrane_viscoelasticity"),
                 nb::parseEffectRequest("plate_friction:friction_force_n=0.3")};
    o.extra_runs = extra;
    o.out_dir = tmpDir("visco_friction_" + std::to_string(extra.size())).string();
    return nb::synthesizeDataset(o).runs;
  };
  nb::DiagnosisOptions o;
  o.candidates = {"membrane_viscoelasticity", "plate_friction"};
  o.discover = false;
  const nb::CellParams params;
  const nb::DiagnosisReport one = nb::diagnoseRuns(dataset({}), params, o, "small");
  ASSERT_EQ(one.verdict_effects, std::vector<std::string>{"membrane_viscoelasticity"}) << one.status;
  const nb::Confusion* more = nullptr;
  for (const auto& c : one.confusions)
    if (c.b == "membrane_viscoelasticity+plate_friction") more = &c;
  ASSERT_NE(more, nullptr) << one.confusions.size() << " confusions";
  ASSERT_TRUE(more->proposed) << nb::gap::describeConfusion(*more);

  const nb::DiagnosisReport two = nb::diagnoseRuns(dataset({nb::gap::addRunArgument(*more)}), params, o, "and the run");
  EXPECT_EQ(two.status, "explained");
  ASSERT_EQ(two.verdict_effects, (std::vector<std::string>{"membrane_viscoelasticity", "plate_friction"}));
  EXPECT_NEAR(two.verdict_params.at("friction_force_n"), 0.3, 0.03);
  bool needed = false;
  for (const auto& line : two.reasons)
    needed = needed || line.find("the withheld runs need the pair") != std::string::npos;
  EXPECT_TRUE(needed);
  // Each cause alone in the traces, for its own figure: neither is the pair's model.
  ASSERT_FALSE(two.traces.empty());
  const nb::RunTrace& t = two.traces[0];
  EXPECT_EQ(t.causes, two.verdict_effects);
  ASSERT_EQ(t.p_cause_pa.size(), 2u);
  double apart = 0.0;
  for (std::size_t c = 0; c < 2; ++c)
    for (std::size_t i = 0; i < t.t_s.size(); ++i)
      apart = std::max(apart, std::fabs(t.h_cause_m[c][i] - t.h_after_m[i]));
  EXPECT_GT(apart, 1e-4);
}

}  // namespace
