// Calibration of the cell's own parameters (calibration.h, doc/gap_calibration.md): the
// catalogue and its mapping onto CellParams, the calibration stage on runs of a rig whose film
// is stiffer than the model's file, the calibrated parameter file, runs without a flow meter or
// a height sensor, and the report's calibration block.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <map>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "nursing_bed/core/gap/calibration.h"
#include "nursing_bed/core/gap/diagnosis.h"
#include "nursing_bed/core/gap/diagnosis_stages.h"
#include "nursing_bed/core/gap/effects.h"
#include "nursing_bed/core/gap/synth.h"
#include "nursing_bed/core/physics/cell_params_io.h"

#include "../../test_helpers.h"
#include "small_protocol_runs.h"

namespace nb = nursing_bed;
namespace gs = nursing_bed::gap;
namespace fs = std::filesystem;

namespace {

/// Expects `f` to throw E with every one of `fragments` in its message.
template <typename E, typename F>
void expectThrowsWith(F f, const std::vector<std::string>& fragments) {
  try {
    f();
    ADD_FAILURE() << "no exception";
  } catch (const E& e) {
    nb::test::expectContains(e.what(), fragments);
  }
}

/// The small protocol's runs (with their roles) of a rig whose airbag differs from the model's
/// by `rig` (SynthOptions::airbag_params), valve-driven when `valve_driven`.
std::vector<nb::RunData> rigRuns(const std::map<std::string, double>& rig, std::uint32_t seed,
                                 bool valve_driven = false, double noise_scale = 1.0,
                                 const std::vector<nb::CellEffectPtr>& effects = {}) {
  return nb::test::smallProtocolRuns(effects, seed, {rig, valve_driven, noise_scale, true});
}

const nb::CalibratedParam& param(const nb::CalibrationSummary& s, const std::string& name) {
  for (const auto& p : s.parameters)
    if (p.name == name) return p;
  throw std::runtime_error("no calibrated parameter " + name);
}

}  // namespace

TEST(GapCalibrationCatalog, ParametersMapOntoTheCellAndBadNamesAreRefused) {
  const nb::CellParams nominal;
  const std::vector<std::string> names = {
      "film_stiffness_scale", "gusset_height_m", "dead_volume_m3",           "plate_mass_kg",
      "inlet_area_m2",        "vent_area_m2",    "regulator_time_constant_s"};
  const auto axes = nb::calibrationAxes(names, nominal);
  ASSERT_EQ(axes.size(), names.size());
  for (const auto& a : axes) {
    EXPECT_TRUE(a.calibration);
    EXPECT_LT(a.spec.lo, a.spec.off_value) << a.spec.name;  // the nominal lies inside its prior range
    EXPECT_GT(a.spec.hi, a.spec.off_value) << a.spec.name;
    EXPECT_NEAR(a.toValue(a.toU(a.spec.off_value)), a.spec.off_value, 1e-12 * std::fabs(a.spec.off_value));
  }
  EXPECT_DOUBLE_EQ(axes[0].spec.off_value, 1.0);
  EXPECT_DOUBLE_EQ(axes[1].spec.off_value, nominal.structure.gusset_height_m);

  const nb::CellParams c = nb::applyCalibration(
      {{"film_stiffness_scale", 1.2}, {"gusset_height_m", 0.081}, {"inlet_area_m2", 2e-5}}, nominal);
  EXPECT_DOUBLE_EQ(c.structure.material.c10_pa, 1.2 * nominal.structure.material.c10_pa);
  EXPECT_DOUBLE_EQ(c.structure.material.c20_pa, 1.2 * nominal.structure.material.c20_pa);
  EXPECT_DOUBLE_EQ(c.structure.material.c30_pa, 1.2 * nominal.structure.material.c30_pa);
  EXPECT_DOUBLE_EQ(c.structure.film_thickness_m, nominal.structure.film_thickness_m);  // the product: one of them
  EXPECT_DOUBLE_EQ(c.structure.gusset_height_m, 0.081);
  EXPECT_DOUBLE_EQ(c.inlet_area_m2, 2e-5);
  EXPECT_DOUBLE_EQ(c.vent_area_m2, nominal.vent_area_m2);

  expectThrowsWith<std::invalid_argument>([&] { nb::calibrationAxes({"film_stiffnes"}, nominal); },
                                          {"unknown calibration parameter 'film_stiffnes'", "film_stiffness_scale"});
  expectThrowsWith<std::invalid_argument>(
      [&] {
        nb::calibrationAxes({"plate_mass_kg", "plate_mass_kg"}, nominal);
      },
      {"given twice"});
  EXPECT_EQ(nb::structurallyUnidentifiable()[0],
            (std::vector<std::string>{"film_stiffness_scale", "film_thickness_m"}));
}

TEST(GapCalibrationCatalog, DefaultsFollowTheRunsAndValveParametersNeedValveDrivenRuns) {
  const auto metered = rigRuns({}, 1, false, 0.0);
  const auto valve = rigRuns({}, 1, true, 0.0);
  EXPECT_EQ(nb::defaultCalibrationParams(metered),
            (std::vector<std::string>{"film_stiffness_scale", "gusset_height_m", "dead_volume_m3", "plate_mass_kg"}));
  EXPECT_EQ(nb::defaultCalibrationParams(valve).size(), 7u);
  EXPECT_NO_THROW(nb::checkCalibrationParams({"inlet_area_m2"}, valve));
  expectThrowsWith<std::invalid_argument>([&] { nb::checkCalibrationParams({"inlet_area_m2"}, metered); },
                                          {"inlet_area_m2", "valve_cmd and p_supply_gauge_pa", "flow-metered"});
}

// A table structure carries the FE's film in its tables: the pillow's film and gusset are not
// its parameters, the plate's mass is.
TEST(GapCalibrationCatalog, ATableCellCalibratesNoPillowFilm) {
  const auto metered = rigRuns({}, 1, false, 0.0);
  nb::CellParams table;
  table.structure_type = "fold_table";
  table.structure_table_file = "unused.yaml";
  EXPECT_EQ(nb::defaultCalibrationParams(metered, table),
            (std::vector<std::string>{"dead_volume_m3", "plate_mass_kg"}));
  expectThrowsWith<std::invalid_argument>([&] { nb::checkCalibrationParams({"gusset_height_m"}, metered, table); },
                                          {"gusset_height_m", "pillow", "fold_table"});
}

TEST(GapCalibrationStage, AStifferFilmIsCalibratedAndNothingElseMoves) {
  const gs::PreparedRuns prepared = gs::prepareRuns(rigRuns({{"film_stiffness_scale", 1.15}}, 5));
  nb::DiagnosisOptions options;
  const nb::CellParams nominal;
  const gs::NoiseModel noise = gs::buildNoiseModel(prepared, nominal, options);
  const gs::CalibrationFit c = gs::calibrateModel(noise, nb::defaultCalibrationParams(prepared.runs), options, {});
  const nb::CalibratedParam& film = param(c.summary, "film_stiffness_scale");
  EXPECT_TRUE(film.moved);
  EXPECT_NEAR(film.value, 1.15, 0.01);
  EXPECT_GT(film.std_error, 0.0);
  EXPECT_LT(std::fabs(film.fitted - 1.15), 5.0 * film.std_error + 0.002);
  for (const auto& p : c.summary.parameters)
    if (p.name != "film_stiffness_scale") {
      EXPECT_FALSE(p.moved) << p.name << " " << p.fitted << " +- " << p.std_error;
      EXPECT_EQ(p.value, p.nominal) << p.name;
    }
  const int n = noise.fitResidualCount();
  EXPECT_GT(noise.chi2_nominal / n, 5.0);  // the film is far outside the noise ...
  EXPECT_LT(c.moved_chi2 / n, 1.2);        // ... and calibration removes it
  EXPECT_LT(c.summary.bic_delta, -1000.0);
  // The correlation matrix: unit diagonal, symmetric; the film's thickness named with its scale.
  ASSERT_EQ(c.summary.correlation.rows(), 4);
  for (int i = 0; i < 4; ++i) EXPECT_DOUBLE_EQ(c.summary.correlation(i, i), 1.0);
  EXPECT_NEAR(c.summary.correlation(0, 1), c.summary.correlation(1, 0), 1e-12);
  EXPECT_EQ(c.summary.unidentifiable.back(), (std::vector<std::string>{"film_stiffness_scale", "film_thickness_m"}));
}

TEST(GapCalibrationStage, CleanRunsMoveNothing) {
  const gs::PreparedRuns prepared = gs::prepareRuns(rigRuns({}, 6));
  nb::DiagnosisOptions options;
  const gs::NoiseModel noise = gs::buildNoiseModel(prepared, nb::CellParams{}, options);
  const gs::CalibrationFit c = gs::calibrateModel(noise, nb::defaultCalibrationParams(prepared.runs), options, {});
  EXPECT_FALSE(c.summary.anyMoved());
  EXPECT_EQ(c.summary.bic_delta, 0.0);
  EXPECT_EQ(c.moved_chi2, noise.chi2_nominal);
}

TEST(GapCalibrationStage, ValveDrivenRunsRecoverTheInletArea) {
  const gs::PreparedRuns prepared = gs::prepareRuns(rigRuns({{"inlet_area_m2", 1.8e-5}}, 7, true));
  ASSERT_TRUE(nb::runIsValveDriven(prepared.runs[0]));
  nb::DiagnosisOptions options;
  const gs::NoiseModel noise = gs::buildNoiseModel(prepared, nb::CellParams{}, options);
  const gs::CalibrationFit c = gs::calibrateModel(noise, nb::defaultCalibrationParams(prepared.runs), options, {});
  const nb::CalibratedParam& inlet = param(c.summary, "inlet_area_m2");
  EXPECT_TRUE(inlet.moved);
  EXPECT_NEAR(inlet.value / 1.8e-5, 1.0, 0.02);
}

/// The calibration of `names` on `prepared` and the singles `effects` fitted on the nominal cell.
struct CalibrationAgainstEffects {
  gs::NoiseModel noise;
  gs::CalibrationFit calibration;
  std::vector<gs::ModelFit> singles;
};
CalibrationAgainstEffects calibrateAgainst(const gs::PreparedRuns& prepared, const std::vector<std::string>& names,
                                           const std::vector<std::string>& effects) {
  nb::DiagnosisOptions options;
  options.pair_pool = 0;
  CalibrationAgainstEffects out{gs::buildNoiseModel(prepared, nb::CellParams{}, options), {}, {}};
  out.calibration = gs::calibrateModel(out.noise, names, options, {});
  out.singles = gs::fitCandidates(out.noise, effects, options, {});
  return out;
}

TEST(GapCalibrationStage, ACalibrationThatImitatesAnEffectIsDroppedForIt) {
  // Heat transfer, with only the dead volume free to calibrate: a larger dead volume softens the
  // gas spring as heat exchange does, and moves; heat transfer alone fits better on both the fit
  // and the withheld runs, so the calibration's move is dropped and the note names the effect.
  const gs::PreparedRuns prepared = gs::prepareRuns(
      rigRuns({}, 8, false, 1.0, {nb::makeEffect("heat_transfer", {{"heat_transfer_coefficient_w_m2_k", 10.0}})}));
  CalibrationAgainstEffects c = calibrateAgainst(prepared, {"dead_volume_m3"}, {"heat_transfer"});
  ASSERT_TRUE(c.calibration.summary.anyMoved()) << "the dead volume did not imitate heat transfer here";
  EXPECT_TRUE(gs::dropCalibrationForEffect(c.noise, c.singles, nb::DiagnosisOptions{}, &c.calibration));
  EXPECT_FALSE(c.calibration.summary.anyMoved());
  EXPECT_EQ(param(c.calibration.summary, "dead_volume_m3").value,
            param(c.calibration.summary, "dead_volume_m3").nominal);
  EXPECT_EQ(c.calibration.moved_chi2, c.noise.chi2_nominal);
  ASSERT_FALSE(c.calibration.summary.notes.empty());
  nb::test::expectContains(c.calibration.summary.notes.back(), {"heat_transfer", "imitated an effect"});
}

TEST(GapCalibrationStage, ARealMismatchKeepsItsCalibrationAgainstTheEffects) {
  // A stiffer film: no effect alone fits it as well, the move stays.
  const gs::PreparedRuns prepared = gs::prepareRuns(rigRuns({{"film_stiffness_scale", 1.15}}, 5));
  CalibrationAgainstEffects c =
      calibrateAgainst(prepared, nb::defaultCalibrationParams(prepared.runs), {"leak", "heat_transfer", "inflow_bias"});
  ASSERT_TRUE(param(c.calibration.summary, "film_stiffness_scale").moved);
  EXPECT_FALSE(gs::dropCalibrationForEffect(c.noise, c.singles, nb::DiagnosisOptions{}, &c.calibration));
  EXPECT_TRUE(param(c.calibration.summary, "film_stiffness_scale").moved);
}

namespace {

/// One load's low-flow run to fit and its high-flow run withheld: the low flow holds the bag
/// below where the film's stiffness shows, the high flow above.
std::vector<nb::RunData> lowFitHighWithheld(const std::map<std::string, double>& rig, std::uint32_t seed) {
  std::vector<nb::RunData> runs;
  for (nb::RunData& r : rigRuns(rig, seed)) {
    if (r.name.rfind("load15p6N_", 0) != 0) continue;
    r.role = r.name.find("_low") != std::string::npos ? "fit" : "withheld";
    runs.push_back(std::move(r));
  }
  return runs;
}

}  // namespace

TEST(GapVerdict, NoneNeedsTheWithheldRunsToAgreeElseTheGapIsUnexplained) {
  nb::DiagnosisOptions options;
  options.discover = false;
  const std::vector<nb::RunData> stiff = lowFitHighWithheld({{"film_stiffness_scale", 1.15}}, 5);
  ASSERT_EQ(stiff.size(), 2u);
  const nb::DiagnosisReport r = nb::diagnoseRuns(stiff, nb::CellParams{}, options, "low fit, high withheld");
  EXPECT_LE(r.nominal_chi2_per_sample, options.within_noise_chi2);       // the fit run sees nothing ...
  EXPECT_GT(r.nominal_withheld_chi2_per_sample, options.withheld_chi2);  // ... the withheld run does
  EXPECT_EQ(r.status, "unexplained");
  EXPECT_TRUE(r.verdict_effects.empty());
  bool said = false;
  for (const auto& line : r.reasons) said = said || line.find("do not exercise what the withheld") != std::string::npos;
  EXPECT_TRUE(said);

  const nb::DiagnosisReport clean =
      nb::diagnoseRuns(lowFitHighWithheld({}, 5), nb::CellParams{}, options, "clean, low fit, high withheld");
  EXPECT_EQ(clean.status, "none");
}

TEST(GapCalibrationFile, TheCalibratedFileIsACompleteParameterFileThatReadsBack) {
  nb::CalibrationSummary s;
  s.done = true;
  s.parameters.push_back({"film_stiffness_scale", "-", 1.0, 1.12, 1.121, 0.01, true});
  const nb::CellParams calibrated = nb::applyCalibration(s.movedValues(), nb::CellParams{});
  const std::string yaml = nb::calibratedParamsYaml(calibrated, s, "/data/rig7");
  EXPECT_NE(yaml.find("/data/rig7"), std::string::npos);
  EXPECT_NE(yaml.find("film_stiffness_scale: calibrated 1.12"), std::string::npos) << yaml;
  const nb::CellParams back = nb::parseCellParamsYaml(yaml, "calibrated_airbag.yaml");
  EXPECT_DOUBLE_EQ(back.structure.material.c10_pa, calibrated.structure.material.c10_pa);
  EXPECT_DOUBLE_EQ(back.structure.gusset_height_m, calibrated.structure.gusset_height_m);
  EXPECT_DOUBLE_EQ(back.inlet_area_m2, calibrated.inlet_area_m2);
  // Every key of the table is in the file, each with its comment.
  for (const auto& f : nb::cellParamFields()) {
    const std::string leaf = f.key.substr(f.key.rfind('/') + 1);
    EXPECT_NE(yaml.find(leaf + ": "), std::string::npos) << leaf;
  }
}

TEST(GapSynthRig, TheRigDiffersByKnownNamesOnly) {
  const nb::CellParams rig = nb::rigAirbag({}, {{"structure/film_thickness_m", 0.55e-3}, {"plate_mass_kg", 0.07}});
  EXPECT_DOUBLE_EQ(rig.structure.film_thickness_m, 0.55e-3);
  EXPECT_DOUBLE_EQ(rig.plate_mass_kg, 0.07);
  expectThrowsWith<std::invalid_argument>(
      [] {
        nb::rigAirbag({}, {{"film_thicknes", 1.0}});
      },
      {"film_thicknes", "neither"});
  expectThrowsWith<std::invalid_argument>([] { nb::rigAirbag({}, {{"gusset_height_m", -0.01}}); }, {"invalid"});
}

TEST(GapValveDriven, AValveDrivenRunReplaysThroughTheModelsValvesAndPressureAloneCounts) {
  const auto runs = rigRuns({}, 8, true, 0.0);
  const nb::RunData& run = runs[3];
  ASSERT_TRUE(nb::runIsValveDriven(run));
  for (double q : run.mdot_in_kg_s) EXPECT_TRUE(std::isnan(q));
  const nb::Replay replay = nb::replayRun(run, nb::CellParams{}, {});
  ASSERT_TRUE(replay.ok) << replay.message;
  const nb::RunResidual r = nb::runResidual(run, replay);
  EXPECT_LT(r.nrmse(), 2e-3);
  // Phases come from the valve command: inflation, hold and vent all present.
  int deploy = 0, hold = 0, vent = 0;
  for (auto ph : replay.phases) {
    deploy += ph == nb::RunPhase::kDeploy || ph == nb::RunPhase::kPressurize;
    hold += ph == nb::RunPhase::kHold;
    vent += ph == nb::RunPhase::kVent;
  }
  EXPECT_GT(deploy, 10);
  EXPECT_GT(hold, 100);
  EXPECT_GT(vent, 10);
  // Without a height sensor the nrmse is the pressure's.
  nb::RunData no_height = run;
  no_height.h_m.assign(run.size(), NAN);
  EXPECT_TRUE(nb::runHasNoHeight(no_height));
  const nb::RunResidual p_only = nb::runResidual(no_height, nb::replayRun(no_height, nb::CellParams{}, {}));
  EXPECT_EQ(p_only.samples_h, 0);
  EXPECT_DOUBLE_EQ(p_only.nrmse(), p_only.nrmse_p);
}

TEST(GapValveDriven, RunsWithoutAFlowMeterReadBackAndNeedValveAndSupply) {
  const fs::path dir = nb::test::freshTestDir("gap_calibration", "csv", true);
  const auto runs = rigRuns({}, 9, true);
  nb::writeRunCsv((dir / "v.csv").string(), runs[0]);
  const std::string text = nb::test::slurp(dir / "v.csv");
  EXPECT_EQ(text.find("mdot_in_kg_s"), std::string::npos) << text.substr(0, 400);
  const nb::RunData back = nb::readRunCsv((dir / "v.csv").string());
  EXPECT_TRUE(nb::runIsValveDriven(back));
  EXPECT_EQ(back.p_supply_gauge_pa, runs[0].p_supply_gauge_pa);
  // Supply pressure as metadata; no mdot and no valve: a clear error.
  nb::test::writeFile(dir / "meta.csv",
                      "# nursing_bed_run: 1\n# load_n: 1\n# p_supply_gauge_pa: 20000\n"
                      "t_s,p_gauge_pa,h_m,valve_cmd\n0,0,0,0\n0.1,0,,1\n");
  const nb::RunData meta = nb::readRunCsv((dir / "meta.csv").string());
  EXPECT_EQ(meta.p_supply_gauge_pa, (std::vector<double>{20000.0, 20000.0}));
  EXPECT_TRUE(nb::runIsValveDriven(meta));
  nb::test::writeFile(dir / "bad.csv",
                      "# nursing_bed_run: 1\n# load_n: 1\nt_s,p_gauge_pa,h_m,valve_cmd\n0,0,0,0\n1,0,0,1\n");
  expectThrowsWith<std::runtime_error>([&] { nb::readRunCsv((dir / "bad.csv").string()); },
                                       {"bad.csv:3:", "mdot_in_kg_s", "valve_cmd and p_supply_gauge_pa"});
}
