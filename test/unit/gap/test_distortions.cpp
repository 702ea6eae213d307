// Channel distortions: the transforms on hand-computable series, their specs, the channels a
// dataset offers, the replay with them, planting them in gap synth, and one diagnosis.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

#include "nursing_bed/core/gap/diagnosis.h"
#include "nursing_bed/core/gap/distortions.h"
#include "nursing_bed/core/gap/fit_model.h"
#include "nursing_bed/core/gap/replay.h"
#include "nursing_bed/core/gap/synth.h"

#include "../../test_helpers.h"

namespace nb = nursing_bed;
namespace fs = std::filesystem;

namespace {

const std::vector<double> kT{0.0, 1.0, 2.0, 3.0};

std::vector<double> distorted(const std::string& kind, double value, std::vector<double> x) {
  nb::distortSeries(kind, value, kT, &x);
  return x;
}

void expectNear(const std::vector<double>& a, const std::vector<double>& b) {
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) EXPECT_NEAR(a[i], b[i], 1e-12) << "sample " << i;
}

std::string errorOf(const std::string& spec) {
  try {
    nb::parseDistortion(spec);
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "";
}

TEST(ChannelDistortion, GainOffsetAndDriftActOnEachSample) {
  expectNear(distorted("gain", -0.5, {2.0, 4.0, 6.0, 8.0}), {1.0, 2.0, 3.0, 4.0});
  expectNear(distorted("offset", 3.0, {2.0, 4.0, 6.0, 8.0}), {5.0, 7.0, 9.0, 11.0});
  expectNear(distorted("drift", 0.5, {2.0, 4.0, 6.0, 8.0}), {2.0, 4.5, 7.0, 9.5});
}

TEST(ChannelDistortion, ShiftReadsTheTruthLateOrEarlyAndHoldsTheEnds) {
  expectNear(distorted("shift", 0.5, {0.0, 2.0, 4.0, 6.0}), {0.0, 1.0, 3.0, 5.0});
  expectNear(distorted("shift", -1.0, {0.0, 2.0, 4.0, 6.0}), {2.0, 4.0, 6.0, 6.0});
}

TEST(ChannelDistortion, AShiftReadsOverAReplaysMissingTailAndFromRestBeforeTheRecord) {
  // A replay's samples after its plate landed are NaN: read early, the last finite one is held.
  std::vector<double> tail{0.0, 2.0, 4.0, NAN};
  nb::distortSeries("shift", -1.0, kT, &tail);
  EXPECT_DOUBLE_EQ(tail[1], 4.0);
  EXPECT_DOUBLE_EQ(tail[2], 4.0);
  EXPECT_TRUE(std::isnan(tail[3]));
  // A series at rest (0) before its record: 2 s late, the first two seconds ramp up from rest.
  std::vector<double> x{4.0, 4.0, 4.0, 4.0};
  nb::distortSeries("shift", 2.0, kT, &x, 0.0);
  expectNear(x, {0.0, 2.0, 4.0, 4.0});
  std::vector<double> y{4.0, 4.0, 4.0, 4.0};
  nb::undistortSeries("shift", -2.0, kT, &y, 0.0);  // a meter 2 s early, undone
  expectNear(y, {0.0, 2.0, 4.0, 4.0});
}

TEST(ChannelDistortion, ATimingBelowAMillisecondIsNotAChannelsButTheReplays) {
  // Clean valve-driven runs fitted a valve lag of 0.43 ms (a tenth of a fit's integration step).
  for (const std::string effect : {"valve_cmd_lag", "valve_cmd_shift", "pressure_shift", "height_lag"}) {
    const nb::gap::ModelSpec m = nb::gap::makeModelSpec({effect});
    const std::string param = m.axes.at(0).spec.name;
    EXPECT_FALSE(nb::gap::plausibleValues(m, {{param, 4.3e-4}}, 3.0)) << effect;
    EXPECT_TRUE(nb::gap::plausibleValues(m, {{param, 0.02}}, 3.0)) << effect;
  }
  EXPECT_FALSE(
      nb::gap::plausibleValues(nb::gap::makeModelSpec({"pressure_shift"}), {{"pressure_shift_s", -5e-4}}, 3.0));
  // Not the other kinds: a small gain is a small gain.
  EXPECT_TRUE(nb::gap::plausibleValues(nb::gap::makeModelSpec({"pressure_gain"}), {{"pressure_gain", 1e-4}}, 3.0));
}

TEST(ChannelDistortion, LagIsTheExactFirstOrderResponseToALinearlyInterpolatedInput) {
  // A ramp 0 -> 1 over the first second, then 1: tau = 1 s.
  const double a = std::exp(-1.0);
  const double y1 = a;  // 1 - tau + (0 - 0 + tau) e^-1
  const double y2 = 1.0 + (y1 - 1.0) * a;
  const double y3 = 1.0 + (y2 - 1.0) * a;
  expectNear(distorted("lag", 1.0, {0.0, 1.0, 1.0, 1.0}), {0.0, y1, y2, y3});
}

TEST(ChannelDistortion, NaNSamplesStayNaN) {
  for (const std::string kind : {"gain", "offset", "drift", "shift", "lag"}) {
    const std::vector<double> y = distorted(kind, 0.1, {1.0, NAN, 2.0, 3.0});
    EXPECT_TRUE(std::isnan(y[1])) << kind;
    EXPECT_TRUE(std::isfinite(y[2])) << kind;
  }
}

TEST(ChannelDistortion, UndistortInvertsEveryKindButTheLag) {
  const std::vector<double> x{1.0, 2.5, 3.0, 2.0};
  for (const std::string kind : {"gain", "offset", "drift", "shift"}) {
    std::vector<double> y = x;
    nb::distortSeries(kind, kind == "shift" ? 0.0 : 0.3, kT, &y);
    nb::undistortSeries(kind, kind == "shift" ? 0.0 : 0.3, kT, &y);
    expectNear(y, x);
  }
  std::vector<double> y = x;
  EXPECT_THROW(nb::undistortSeries("lag", 0.2, kT, &y), std::invalid_argument);
  std::vector<double> closed{0.0, 0.0, 1.0, 0.0};  // a closed inlet's zeroed flow passes no gas
  nb::undistortSeries("drift", 0.5, kT, &closed);
  expectNear(closed, {0.0, 0.0, 0.0, 0.0});
}

TEST(ChannelDistortion, SpecsNameTheEffectAndItsParameter) {
  const auto h = nb::parseDistortion("height:gain=-0.04");
  ASSERT_EQ(h.size(), 1u);
  EXPECT_EQ(h.at("height_gain").at("height_gain"), -0.04);
  const auto p = nb::parseDistortion("pressure:lag=0.2");
  EXPECT_EQ(p.at("pressure_sensor_lag").at("time_constant_s"), 0.2);
  const auto q = nb::parseDistortion("inflow:gain=0.05,shift=+0.08");
  EXPECT_EQ(q.at("inflow_bias").at("scale_error"), 0.05);
  EXPECT_EQ(q.at("inflow_bias").at("offset_kg_s"), 0.0);
  EXPECT_EQ(q.at("inflow_shift").at("inflow_shift_s"), 0.08);
}

TEST(ChannelDistortion, BadSpecsAreRefusedNamingWhatIsWrong) {
  EXPECT_NE(errorOf("hight:gain=0.1").find("unknown channel 'hight'"), std::string::npos);
  EXPECT_NE(errorOf("load:shift=0.1").find("unknown kind 'shift' for channel load"), std::string::npos);
  EXPECT_NE(errorOf("height").find("expected height:kind=value"), std::string::npos);
  EXPECT_NE(errorOf("height:gain").find("gain needs a value"), std::string::npos);
  EXPECT_NE(errorOf("height:gain=abc").find("'abc' is not a finite number"), std::string::npos);
  EXPECT_NE(errorOf("height:gain=0.1,gain=0.2").find("gain given twice"), std::string::npos);
  EXPECT_NE(errorOf("height:gain=2").find("outside the admissible range"), std::string::npos);
  EXPECT_NE(errorOf("height:lag=-1").find("height_lag_s"), std::string::npos);
}

TEST(ChannelDistortion, DescriptionNamesChannelKindAndValue) {
  EXPECT_EQ(nb::describeDistortion("height_gain", {{"height_gain", -0.041}}, {{"height_gain", 0.003}}),
            "height: gain -4.1 % ± 0.3 %");
  EXPECT_EQ(nb::describeDistortion("pressure_offset", {{"pressure_offset_pa", 250.0}}), "pressure: offset +250 Pa");
  EXPECT_EQ(nb::describeDistortion("inflow_bias", {{"scale_error", 0.05}, {"offset_kg_s", 0.0}}),
            "inflow: gain +5.0 %");
  EXPECT_EQ(nb::describeDistortion("leak", {{"leak_area_m2", 1e-8}}), "");
}

TEST(ChannelDistortion, OnlyTheChannelsADatasetHasAreCandidates) {
  nb::RunData metered;
  metered.t_s = {0.0, 1.0};
  metered.mdot_in_kg_s = {1e-4, 0.0};
  metered.p_gauge_pa = {0.0, 100.0};
  metered.h_m = {NAN, NAN};
  auto has = [](const std::vector<std::string>& v, const std::string& x) {
    return std::find(v.begin(), v.end(), x) != v.end();
  };
  const auto no_height = nb::distortionCandidatesFor({&metered});
  EXPECT_TRUE(has(no_height, "pressure_gain"));
  EXPECT_TRUE(has(no_height, "inflow_shift"));
  EXPECT_TRUE(has(no_height, "load_offset"));
  EXPECT_FALSE(has(no_height, "height_gain"));
  EXPECT_FALSE(has(no_height, "valve_cmd_shift"));
  EXPECT_FALSE(has(no_height, "pressure_sensor_lag"));  // a candidate of the physical catalogue already
  metered.h_m = {0.0, 0.01};
  EXPECT_TRUE(has(nb::distortionCandidatesFor({&metered}), "height_lag"));
  nb::RunData valve = metered;
  valve.mdot_in_kg_s = {NAN, NAN};
  valve.valve_cmd = {1.0, 0.0};
  valve.p_supply_gauge_pa = {2e4, 2e4};
  const auto driven = nb::distortionCandidatesFor({&valve});
  EXPECT_TRUE(has(driven, "valve_cmd_lag"));
  EXPECT_TRUE(has(driven, "supply_gain"));
  EXPECT_FALSE(has(driven, "inflow_drift"));
}

fs::path tmpDir(const std::string& name) { return nursing_bed::test::freshTestDir("gap_distort", name, false); }

nb::SynthOptions exactSmall(const std::string& name) {
  nb::SynthOptions o;
  o.out_dir = tmpDir(name).string();
  o.protocol = "small";
  o.noise_scale = 0.0;
  o.seed = 3;
  return o;
}

TEST(ChannelDistortion, ReplayAppliesOutputAndInputDistortions) {
  const nb::SynthResult clean = nb::synthesizeDataset(exactSmall("replay"));
  const nb::RunData& run = clean.runs[0];
  const nb::CellParams params;
  const nb::Replay nominal = nb::replayRun(run, params, {});
  const nb::Replay gained = nb::replayRun(run, params, {nb::makeEffect("height_gain", {{"height_gain", 0.1}})});
  for (std::size_t i = 0; i < run.size(); i += 50)
    if (std::isfinite(nominal.h_m[i])) {
      EXPECT_DOUBLE_EQ(gained.h_m[i], 1.1 * nominal.h_m[i]);
      EXPECT_DOUBLE_EQ(gained.p_gauge_pa[i], nominal.p_gauge_pa[i]);
    }
  // A recorded load 1 N high: the replay drives the model with the true (lower) load.
  nb::RunData lighter = run;
  lighter.load_n -= 1.0;
  const nb::Replay corrected = nb::replayRun(run, params, {nb::makeEffect("load_offset", {{"load_offset_n", 1.0}})});
  const nb::Replay direct = nb::replayRun(lighter, params, {});
  for (std::size_t i = 0; i < run.size(); i += 50) EXPECT_EQ(corrected.p_gauge_pa[i], direct.p_gauge_pa[i]);
}

TEST(ChannelDistortion, AHeightReadEarlyDoesNotGiveTheReplayItsStart) {
  const nb::SynthResult clean = nb::synthesizeDataset(exactSmall("early_start"));
  const nb::RunData& run = clean.runs[0];
  nb::RunData lifted = run;  // its first readings 20 mm up, as a sensor early through a fast lift
  for (std::size_t i = 0; i < lifted.size() && lifted.t_s[i] <= nb::kInitialRestS; ++i) lifted.h_m[i] = 0.02;
  const nb::CellParams params;
  for (const double d : {-0.1, 0.1}) {
    const std::vector<nb::CellEffectPtr> shift{nb::makeEffect("height_shift", {{"height_shift_s", d}})};
    const nb::Replay a = nb::replayRun(run, params, shift), b = nb::replayRun(lifted, params, shift);
    const std::size_t i = run.size() / 2;
    if (d < 0.0) EXPECT_DOUBLE_EQ(a.h_m[i], b.h_m[i]) << "read early: the start from the pressure";
    else EXPECT_GT(std::fabs(a.h_m[i] - b.h_m[i]), 1e-3) << "read late: the start from the height";
  }
}

TEST(ChannelDistortion, AHeightOffsetDoesNotGiveTheReplayItsStart) {
  const nb::SynthResult clean = nb::synthesizeDataset(exactSmall("offset_start"));
  const nb::CellParams params;
  // A run whose plate lands in the vent (its replay's last samples NaN).
  std::size_t k = 0;
  nb::Replay truth;
  for (; k < clean.runs.size(); ++k)
    if (truth = nb::replayRun(clean.runs[k], params, {}); !std::isfinite(truth.h_m.back())) break;
  ASSERT_LT(k, clean.runs.size()) << "no run lands";
  const nb::RunData& run = clean.runs[k];
  nb::RunData offset = run;  // a flat start read 10 mm up: at rest there, were it the truth
  for (double& h : offset.h_m) h += 0.01;
  const nb::Replay fitted =
      nb::replayRun(offset, params, {nb::makeEffect("height_offset", {{"height_offset_m", 0.01}})});
  std::size_t simulated = 0;
  for (std::size_t i = 0; i < run.size(); ++i) {
    if (!std::isfinite(truth.h_m[i])) break;  // landed in the vent
    EXPECT_NEAR(fitted.h_m[i], truth.h_m[i] + 0.01, 1e-9) << i;
    EXPECT_NEAR(fitted.p_gauge_pa[i], truth.p_gauge_pa[i], 1e-6) << i;
    simulated = i + 1;
  }
  // Read 10 mm up, the plate never shows landing in the vent: after it, flat and at ambient.
  ASSERT_GT(simulated, 0u);
  ASSERT_LT(simulated, run.size());
  for (std::size_t i = simulated; i < run.size(); ++i) {
    EXPECT_DOUBLE_EQ(fitted.h_m[i], 0.01) << i;
    EXPECT_DOUBLE_EQ(fitted.p_gauge_pa[i], 0.0) << i;
  }
}

TEST(ChannelDistortion, SynthPlantsDistortionsOnTheTrueReadings) {
  const nb::SynthResult clean = nb::synthesizeDataset(exactSmall("clean"));
  nb::SynthOptions o = exactSmall("planted");
  o.distortions = {"height:gain=-0.04", "load:offset=0.5", "pressure:lag=0.2"};
  const nb::SynthResult planted = nb::synthesizeDataset(o);
  ASSERT_EQ(planted.distortion_names, (std::vector<std::string>{"height_gain", "load_offset"}));
  EXPECT_EQ(planted.effect_names, std::vector<std::string>{"pressure_sensor_lag"});
  const nb::RunData& a = clean.runs[1];
  const nb::RunData& b = planted.runs[1];
  // The sensor lag's extra state changes the integrator's steps, which moves the plate within
  // the step tolerance (a few microns); a wrong gain would be off by millimetres.
  for (std::size_t i = 0; i < a.size(); i += 37) EXPECT_NEAR(b.h_m[i], 0.96 * a.h_m[i], 5e-6);
  EXPECT_DOUBLE_EQ(b.load_n, a.load_n + 0.5);
  EXPECT_NE(nb::test::slurp(fs::path(o.out_dir) / "truth.json").find("\"channel\": \"height\""), std::string::npos);
}

TEST(ChannelDistortion, SynthPlantsTheValvesDistortionsOnValveDrivenRuns) {
  nb::SynthOptions o = exactSmall("valves_clean");
  o.flow_meter = false;
  const nb::SynthResult clean = nb::synthesizeDataset(o);
  const nb::CellParams params;
  for (const char* planted : {"valve_cmd:shift=0.1", "valve_cmd:lag=0.1", "supply:gain=0.08"}) {
    nb::SynthOptions d = exactSmall("valves_planted");
    d.flow_meter = false;
    d.distortions = {planted};
    const nb::SynthResult r = nb::synthesizeDataset(d);
    ASSERT_EQ(r.distortion_names.size(), 1u) << planted;
    const nb::RunData& run = r.runs[1];
    const std::string effect = r.distortion_names[0];
    const double value = r.distortion_params[0].begin()->second;
    // The recorded command is the one given; what the readings follow is the distorted one.
    EXPECT_EQ(run.valve_cmd, clean.runs[1].valve_cmd) << planted;
    // The replay with the planted distortion reproduces the readings; the nominal one does not.
    const nb::Replay nominal = nb::replayRun(run, params, {});
    const nb::Replay given = nb::replayRun(run, params, {nb::makeEffect(effect, r.distortion_params[0])});
    double off_nominal = 0.0, off_given = 0.0;
    for (std::size_t i = 0; i < run.size(); ++i)
      if (std::isfinite(nominal.h_m[i]) && std::isfinite(given.h_m[i])) {
        off_nominal = std::max(off_nominal, std::fabs(nominal.h_m[i] - run.h_m[i]));
        off_given = std::max(off_given, std::fabs(given.h_m[i] - run.h_m[i]));
      }
    EXPECT_GT(off_nominal, 1e-3) << planted << " " << value;
    EXPECT_LT(off_given, 0.25 * off_nominal) << planted << " " << value;
  }
}

TEST(ChannelDistortion, SynthRefusesWhatItCannotPlantAndWritesNothing) {
  nb::SynthOptions o = exactSmall("refused");
  fs::remove_all(o.out_dir);
  o.distortions = {"valve_cmd:shift=0.04"};  // a metered run has no valve record to distort
  EXPECT_THROW(nb::synthesizeDataset(o), std::invalid_argument);
  o.distortions = {"supply:gain=0.05"};
  EXPECT_THROW(nb::synthesizeDataset(o), std::invalid_argument);
  o.flow_meter = false;  // ... and a valve-driven one no flow meter
  o.distortions = {"inflow:shift=0.04"};
  EXPECT_THROW(nb::synthesizeDataset(o), std::invalid_argument);
  o.flow_meter = true;
  o.distortions = {"height:gain=0.01", "height:gain=0.02"};
  EXPECT_THROW(nb::synthesizeDataset(o), std::invalid_argument);
  o.distortions = {"pressure:lag=0.1"};
  o.effects = {nb::parseEffectRequest("pressure_sensor_lag:time_constant_s=0.2")};
  EXPECT_THROW(nb::synthesizeDataset(o), std::invalid_argument);
  EXPECT_FALSE(fs::exists(o.out_dir));
}

TEST(ChannelDistortion, APlantedPressureOffsetIsNamedWithItsSize) {
  nb::SynthOptions s = exactSmall("diagnose");
  s.noise_scale = 1.0;
  s.distortions = {"pressure:offset=300"};
  nb::synthesizeDataset(s);
  nb::DiagnosisOptions o;
  o.candidates = {"leak", "pressure_offset"};
  o.pair_pool = 0;
  o.calibrate = false;
  const nb::DiagnosisReport r = nb::diagnoseRuns(nb::readDataset(s.out_dir), s.params, o, s.out_dir);
  EXPECT_EQ(r.status, "explained");
  ASSERT_EQ(r.verdict_effects, std::vector<std::string>{"pressure_offset"});
  EXPECT_NEAR(r.verdict_params.at("pressure_offset_pa"), 300.0, 75.0);
  ASSERT_EQ(r.verdict_distortions.size(), 1u);
  EXPECT_EQ(r.verdict_distortions[0].rfind("pressure: offset +", 0), 0u) << r.verdict_distortions[0];
}

}  // namespace
