// The synthetic data generator: readable runs, determinism, truth.json, noise statistics,
// effect requests.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>
#include <set>
#include <sstream>

#include "nursing_bed/core/gap/effects.h"
#include "nursing_bed/core/gap/synth.h"

#include "../../test_helpers.h"

namespace nb = nursing_bed;
namespace fs = std::filesystem;

namespace {

using nursing_bed::test::slurp;
using nursing_bed::test::writeFile;

fs::path tmpDir(const std::string& name) { return nursing_bed::test::freshTestDir("gap_synth", name, false); }

nb::SynthOptions smallOptions(const fs::path& dir) {
  nb::SynthOptions o;
  o.out_dir = dir.string();
  o.protocol = "small";
  o.seed = 11;
  return o;
}

TEST(GapSynth, SmallProtocolWritesReadableRunsWithRoles) {
  const fs::path dir = tmpDir("small");
  nb::SynthOptions o = smallOptions(dir);
  o.effects = {nb::parseEffectRequest("leak:leak_area_m2=1e-8"), nb::parseEffectRequest("heat_transfer")};
  std::ostringstream progress;
  o.progress = &progress;
  const nb::SynthResult res = nb::synthesizeDataset(o);
  EXPECT_NE(progress.str().find("[4/4]"), std::string::npos) << progress.str();

  const std::vector<nb::RunData> runs = nb::readDataset(dir.string());
  ASSERT_EQ(runs.size(), 4u);
  int fit = 0, withheld = 0;
  std::set<std::string> fit_flows, withheld_flows;
  std::set<double> fit_loads, withheld_loads;
  for (std::size_t i = 0; i < runs.size(); ++i) {
    const nb::RunData& r = runs[i];
    SCOPED_TRACE(r.name);
    EXPECT_EQ(r.size(), static_cast<std::size_t>(std::lround((5.5 + 30.0 + 10.0) * 50.0)) + 1);
    EXPECT_EQ(r.t_s[1], 0.02);
    EXPECT_EQ(r.airbag, "tpu_double_100");
    EXPECT_TRUE(r.meta.count("note"));
    EXPECT_TRUE(std::isfinite(r.load_n));
    EXPECT_EQ(r.valve_cmd.size(), r.size());
    const std::string flow = r.name.find("high") != std::string::npos ? "high" : "low";
    if (r.role == "fit") {
      ++fit;
      fit_flows.insert(flow);
      fit_loads.insert(r.load_n);
    } else if (r.role == "withheld") {
      ++withheld;
      withheld_flows.insert(flow);
      withheld_loads.insert(r.load_n);
    }
    // Phases: inflow into the bag, nothing (noise) at hold, out of it while venting.
    double inflow = 0.0, vent = 0.0;
    for (std::size_t k = 1; k < r.size(); ++k) {
      const double dt = r.t_s[k] - r.t_s[k - 1];
      if (r.t_s[k] <= 5.5) inflow += r.mdot_in_kg_s[k] * dt;
      if (r.t_s[k] > 35.5) vent += r.mdot_in_kg_s[k] * dt;
    }
    EXPECT_GT(inflow, 2e-3);
    EXPECT_LT(vent, -2e-4);
    double h_max = 0.0;
    for (double h : r.h_m) h_max = std::max(h_max, h);
    EXPECT_GT(h_max, 0.1);
  }
  EXPECT_EQ(fit, 2);
  EXPECT_EQ(withheld, 2);
  EXPECT_EQ(fit_flows.size(), 2u);  // each flow magnitude in both sets
  EXPECT_EQ(withheld_flows.size(), 2u);
  EXPECT_EQ(fit_loads.size(), 2u);  // each load in both sets
  EXPECT_EQ(withheld_loads.size(), 2u);

  // truth.json: the effects in catalogue order with every parameter, the seed and protocol.
  const std::string truth = slurp(dir / "truth.json");
  EXPECT_NE(truth.find("\"format\": \"nursing_bed_gap_truth/1\""), std::string::npos);
  EXPECT_NE(truth.find("\"seed\": 11"), std::string::npos);
  EXPECT_NE(truth.find("\"protocol\": \"small\""), std::string::npos);
  EXPECT_NE(truth.find("\"noise_scale\": 1"), std::string::npos);
  EXPECT_NE(truth.find("\"leak_area_m2\": 1e-08"), std::string::npos) << truth;
  EXPECT_NE(truth.find("\"heat_transfer_coefficient_w_m2_k\""), std::string::npos);
  EXPECT_LT(truth.find("heat_transfer"), truth.find("\"leak\""));
  ASSERT_EQ(res.effect_names.size(), 2u);
  const double h = res.effect_params[0].at("heat_transfer_coefficient_w_m2_k");
  EXPECT_GE(h, 2.0);
  EXPECT_LE(h, 25.0);
  // The run files carry nothing about the truth.
  EXPECT_EQ(slurp(dir / runs[0].name).find("leak"), std::string::npos);
}

TEST(GapSynth, SameSeedGivesIdenticalFilesAndAnotherSeedDoesNot) {
  const fs::path a = tmpDir("seed_a"), b = tmpDir("seed_b"), c = tmpDir("seed_c");
  nb::SynthOptions o = smallOptions(a);
  o.effects = {nb::parseEffectRequest("membrane_viscoelasticity"), nb::parseEffectRequest("inflow_bias")};
  nb::synthesizeDataset(o);
  o.out_dir = b.string();
  nb::synthesizeDataset(o);
  o.out_dir = c.string();
  o.seed = 12;
  nb::synthesizeDataset(o);
  int files = 0;
  for (const auto& entry : fs::directory_iterator(a)) {
    const std::string name = entry.path().filename().string();
    EXPECT_EQ(slurp(entry.path()), slurp(b / name)) << name;
    if (name != "dataset.yaml") {
      EXPECT_NE(slurp(entry.path()), slurp(c / name)) << name;
    }
    ++files;
  }
  EXPECT_EQ(files, 6);  // 4 runs, dataset.yaml, truth.json
  // The order of --effect options does not change the draw.
  const fs::path d = tmpDir("seed_d");
  o.out_dir = d.string();
  o.seed = 11;
  o.effects = {nb::parseEffectRequest("inflow_bias"), nb::parseEffectRequest("membrane_viscoelasticity")};
  nb::synthesizeDataset(o);
  EXPECT_EQ(slurp(a / "truth.json"), slurp(d / "truth.json"));
}

// Measured minus exact readings of the same runs (same seed, same truth).
struct Residuals {
  std::vector<double> p, h, q_small;
};

Residuals noiseOf(double scale) {
  nb::CellParams params;
  const nb::SynthProtocol protocol = nb::synthProtocol("small", params);
  const nb::SensorNoise noise = nb::SensorNoise{}.scaled(scale);
  Residuals r;
  for (std::size_t k = 0; k < protocol.runs.size(); ++k) {
    std::mt19937 rng(100 + k);
    const nb::RunData noisy = nb::simulateSynthRun(params, {}, protocol, protocol.runs[k], noise, &rng);
    const nb::RunData exact = nb::simulateSynthRun(params, {}, protocol, protocol.runs[k], noise, nullptr);
    for (std::size_t i = 0; i < noisy.size(); ++i) {
      r.p.push_back(noisy.p_gauge_pa[i] - exact.p_gauge_pa[i]);
      r.h.push_back(noisy.h_m[i] - exact.h_m[i]);
      if (std::fabs(exact.mdot_in_kg_s[i]) < 1e-7) r.q_small.push_back(noisy.mdot_in_kg_s[i] - exact.mdot_in_kg_s[i]);
    }
  }
  return r;
}

double sd(const std::vector<double>& x) {
  double m = 0.0, s = 0.0;
  for (double v : x) m += v;
  m /= x.size();
  for (double v : x) s += (v - m) * (v - m);
  return std::sqrt(s / (x.size() - 1));
}

double mean(const std::vector<double>& x) {
  double m = 0.0;
  for (double v : x) m += v;
  return m / x.size();
}

TEST(GapSynth, NoiseStatisticsMatchTheRequestedSensors) {
  for (double scale : {1.0, 2.0}) {
    SCOPED_TRACE(scale);
    const Residuals r = noiseOf(scale);
    // Gaussian sd plus the uniform quantisation error (step^2 / 12).
    const double p_sd = scale * std::sqrt(30.0 * 30.0 + 10.0 * 10.0 / 12.0);
    const double h_sd = scale * std::sqrt(0.3e-3 * 0.3e-3 + 0.1e-3 * 0.1e-3 / 12.0);
    const double q_sd = scale * std::sqrt(5e-6 * 5e-6 + 1e-6 * 1e-6 / 12.0);
    ASSERT_GT(r.p.size(), 5000u);
    EXPECT_NEAR(sd(r.p), p_sd, 0.04 * p_sd);
    EXPECT_NEAR(mean(r.p), 0.0, 0.05 * p_sd);
    EXPECT_NEAR(sd(r.h), h_sd, 0.04 * h_sd);
    ASSERT_GT(r.q_small.size(), 1000u);  // hold: no flow, the meter's additive noise only
    EXPECT_NEAR(sd(r.q_small), q_sd, 0.06 * q_sd);
  }
  // Scale 0: exact readings.
  const Residuals zero = noiseOf(0.0);
  EXPECT_EQ(sd(zero.p), 0.0);
  EXPECT_EQ(sd(zero.h), 0.0);
  // Readings are quantised to their steps.
  nb::CellParams params;
  const nb::SynthProtocol protocol = nb::synthProtocol("small", params);
  std::mt19937 rng(1);
  const nb::RunData run = nb::simulateSynthRun(params, {}, protocol, protocol.runs[0], nb::SensorNoise{}, &rng);
  for (std::size_t i = 0; i < run.size(); i += 37) {
    EXPECT_EQ(run.p_gauge_pa[i], std::round(run.p_gauge_pa[i] / 10.0) * 10.0);
    EXPECT_NEAR(run.h_m[i] * 1e4, std::round(run.h_m[i] * 1e4), 1e-6);
  }
}

TEST(GapSynth, TargetsAndPlantedEffectsShowInTheData) {
  nb::CellParams params;
  const nb::SynthProtocol protocol = nb::synthProtocol("standard", params);
  ASSERT_EQ(protocol.runs.size(), 8u);
  EXPECT_DOUBLE_EQ(protocol.durationS(), 75.5);
  int withheld = 0;
  for (const auto& r : protocol.runs) withheld += r.role == "withheld";
  EXPECT_EQ(withheld, 2);
  // Nominal, exact: the plate rests near its target height during hold (the gas is warm
  // from the compression, so a little above it).
  const nb::SynthRunPlan& plan = protocol.runs[2];  // 10.6 N, low
  const nb::RunData run = nb::simulateSynthRun(params, {}, protocol, plan, nb::SensorNoise{}, nullptr);
  const std::size_t hold = static_cast<std::size_t>(30.0 * protocol.sample_hz);
  EXPECT_NEAR(run.h_m[hold], plan.target_height_m, 0.005);
  // A planted pressure offset drift shows in the reading, and only there.
  const auto drift = nb::makeEffect("pressure_offset_drift", {{"drift_pa_s", 4.0}});
  const nb::RunData drifted = nb::simulateSynthRun(params, {drift}, protocol, plan, nb::SensorNoise{}, nullptr);
  EXPECT_NEAR(drifted.p_gauge_pa[hold] - run.p_gauge_pa[hold], 4.0 * 30.0, 1e-6);
  EXPECT_EQ(drifted.h_m[hold], run.h_m[hold]);
}

TEST(GapSynth, EffectRequestsAreParsedAndBadOnesRefused) {
  const nb::SynthEffectRequest r = nb::parseEffectRequest("supply_line:line_volume_m3=2e-5,line_area_m2=+4e-6");
  EXPECT_EQ(r.name, "supply_line");
  EXPECT_EQ(r.params.at("line_volume_m3"), 2e-5);
  EXPECT_EQ(r.params.at("line_area_m2"), 4e-6);
  EXPECT_TRUE(nb::parseEffectRequest("leak").params.empty());
  auto refused = [](const std::string& text, const std::string& fragment) {
    try {
      nb::parseEffectRequest(text);
      ADD_FAILURE() << "accepted " << text;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
    }
  };
  refused("leek", "unknown effect 'leek'");
  refused("leak:area=1e-9", "unknown parameter 'area'");
  refused("leak:leak_area_m2", "expected param=value");
  refused("leak:leak_area_m2=small", "'small' is not a finite number");
  refused("leak:leak_area_m2=1e-9,leak_area_m2=2e-9", "given twice");
  // Ranges are checked when the truth is resolved; an effect given twice is refused.
  std::vector<std::string> names;
  std::vector<std::map<std::string, double>> params;
  std::vector<nb::CellEffectPtr> effects;
  EXPECT_THROW(nb::resolveSynthEffects({nb::parseEffectRequest("leak:leak_area_m2=1")}, 1, &names, &params, &effects),
               std::invalid_argument);
  EXPECT_THROW(nb::resolveSynthEffects({nb::parseEffectRequest("leak"), nb::parseEffectRequest("leak")}, 1, &names,
                                       &params, &effects),
               std::invalid_argument);
  nb::resolveSynthEffects({nb::parseEffectRequest("plate_friction"), nb::parseEffectRequest("leak:leak_area_m2=2e-9")},
                          5, &names, &params, &effects);
  ASSERT_EQ(names, (std::vector<std::string>{"leak", "plate_friction"}));
  EXPECT_EQ(params[0].at("leak_area_m2"), 2e-9);
  EXPECT_GE(params[1].at("friction_force_n"), 0.2);
  EXPECT_LE(params[1].at("friction_force_n"), 3.0);
  EXPECT_THROW(nb::synthProtocol("long", nb::CellParams{}), std::invalid_argument);
}

TEST(GapSynth, TheRigRunsOnItsOwnFileWhileTheDatasetNamesTheModels) {
  // The rig on the FE table (config/airbag_tpu_double_100_fe.yaml), the model on the pillow.
  const std::string fe = std::string(NURSING_BED_SOURCE_DIR) + "/config/airbag_tpu_double_100_fe.yaml";
  nb::SynthOptions o = smallOptions(tmpDir("rig_fe"));
  o.noise_scale = 0.0;
  o.rig_airbag_file = fe;
  const nb::SynthResult rig = nb::synthesizeDataset(o);
  nb::SynthOptions p = smallOptions(tmpDir("rig_pillow"));
  p.noise_scale = 0.0;
  const nb::SynthResult pillow = nb::synthesizeDataset(p);
  ASSERT_EQ(rig.runs.size(), pillow.runs.size());
  // The same protocol, another cell: the plate stands elsewhere at the end of the hold.
  double largest = 0.0;
  for (std::size_t k = 0; k < rig.runs.size(); ++k) {
    const std::size_t i = rig.runs[k].size() * 3 / 4;
    largest = std::max(largest, std::fabs(rig.runs[k].h_m[i] - pillow.runs[k].h_m[i]));
  }
  EXPECT_GT(largest, 0.003) << "the FE rig's heights match the pillow's";
  EXPECT_NE(slurp(fs::path(o.out_dir) / "dataset.yaml").find("airbag: airbag_tpu_double_100.yaml"), std::string::npos);
  EXPECT_NE(slurp(fs::path(o.out_dir) / "truth.json").find("airbag_tpu_double_100_fe.yaml"), std::string::npos);

  // A file that is not there: refused naming it, nothing written.
  nb::SynthOptions bad = smallOptions(tmpDir("rig_missing"));
  bad.rig_airbag_file = "/nonexistent/rig.yaml";
  try {
    nb::synthesizeDataset(bad);
    ADD_FAILURE() << "a missing rig file was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/rig.yaml"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(fs::path(bad.out_dir) / "dataset.yaml"));
}

}  // namespace
