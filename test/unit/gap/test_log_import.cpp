// gap import: the mapping file, the conversions, cycle cutting, errors that name the file, line
// and column and leave nothing written, and the shipped ventilator recordings.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>

#include "nursing_bed/core/gap/log_import.h"

namespace nb = nursing_bed;
namespace fs = std::filesystem;

namespace {

constexpr double kCmH2O = 98.0665;
const std::string kSource = NURSING_BED_SOURCE_DIR;

std::string tmpDir(const std::string& name) {
  const fs::path d = fs::path(NURSING_BED_TEST_TMP_DIR) / "log_import" / name;
  fs::remove_all(d);
  fs::create_directories(d);
  return d.string();
}

std::string writeFile(const std::string& dir, const std::string& name, const std::string& text) {
  const std::string path = (fs::path(dir) / name).string();
  std::ofstream(path) << text;
  return path;
}

/// A small mapping: comma-separated, time in ms, pressure in kPa or cmH2O, flow in L/min with the
/// sign flipped, cut at the setpoint's rises one cycle per run.
const char* const kMapping = R"(import_mapping: 1
log: {comment: "#", delimiter: comma}
time: {column: t, unit: ms}
signals:
  p: {column: p, unit: [cmH2O, kPa], detect: {reference: sp, ratio: [0.7, 1.4]}}
  sp: {column: sp, unit: cmH2O}
  q: {column: q, unit: L/min, sign: -1}
gas: {density_kg_m3: 1.2}
run: {p_gauge_pa: p, mdot_in_kg_s: q, p_setpoint_gauge_pa: sp}
cycles: {signal: sp, cycles_per_run: 1}
roles: alternate
metadata: {load_n: 2.5, airbag: lung.yaml}
)";

/// 8 s at 100 Hz: the setpoint at 5 cmH2O, ramping to 15 over 0.1 s at 0.5, 2.5, 4.5, 6.5 s and
/// back down at +1 s; the pressure follows it (in kPa when `kpa`); the flow is 6 L/min.
std::string syntheticLog(bool kpa) {
  std::ostringstream s;
  s.precision(17);
  s << "# a comment\n# another\nt,sp,p,q\n";
  for (int i = 0; i < 800; ++i) {
    const double t = i * 0.01, phase = std::fmod(t + 1.5, 2.0);  // a rise starts where phase = 0
    double sp = 5.0;
    if (phase < 1.0) sp = 5.0 + 10.0 * std::min(1.0, phase / 0.1);
    if (t < 0.5) sp = 5.0;
    const double p = kpa ? sp * kCmH2O / 1000.0 : sp;
    s << i * 10 << "," << sp << "," << p << ",6\n";
  }
  return s.str();
}

/// `f` throws a runtime_error whose message contains every piece.
void expectError(const std::function<void()>& f, const std::vector<std::string>& pieces) {
  try {
    f();
    ADD_FAILURE() << "no error; expected one mentioning " << pieces.front();
  } catch (const std::runtime_error& e) {
    for (const auto& p : pieces) EXPECT_NE(std::string(e.what()).find(p), std::string::npos) << e.what();
  }
}

std::string replaced(std::string text, const std::string& from, const std::string& to) {
  const auto at = text.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  if (at != std::string::npos) text.replace(at, from.size(), to);
  return text;
}

}  // namespace

TEST(LogImportMapping, ReadsEveryKey) {
  const nb::ImportMapping m = nb::parseImportMapping(kMapping, "m.yaml");
  EXPECT_EQ(m.delimiter, ',');
  EXPECT_DOUBLE_EQ(m.time_to_s, 1e-3);
  ASSERT_EQ(m.signals.size(), 3u);
  EXPECT_EQ(m.signals[0].units, (std::vector<std::string>{"cmH2O", "kPa"}));
  EXPECT_EQ(m.signals[2].sign, -1.0);
  EXPECT_EQ(m.outputs.at("mdot_in_kg_s"), "q");
  EXPECT_EQ(m.cycles->cycles_per_run, 1);
  EXPECT_EQ(m.roles.pattern, (std::vector<std::string>{"fit", "withheld"}));
  EXPECT_EQ(m.metadata.at("airbag"), "lung.yaml");
}

TEST(LogImportMapping, RejectsUnknownAndMissingKeysWithFileAndLine) {
  expectError([] { nb::parseImportMapping(replaced(kMapping, "gas:", "gass:"), "m.yaml"); },
              {"m.yaml:8:", "unknown key 'gass'"});
  expectError([] { nb::parseImportMapping(replaced(kMapping, "sign: -1", "sing: -1"), "m.yaml"); },
              {"m.yaml:7:", "unknown key 'signals/q/sing'"});
  expectError([] { nb::parseImportMapping(replaced(kMapping, "time: {column: t, unit: ms}\n", ""), "m.yaml"); },
              {"m.yaml", "missing key 'time'"});
  expectError([] { nb::parseImportMapping(replaced(kMapping, "p_gauge_pa: p, ", ""), "m.yaml"); },
              {"m.yaml:9:", "missing key 'p_gauge_pa'"});
  expectError([] { nb::parseImportMapping(replaced(kMapping, "column: q, ", ""), "m.yaml"); },
              {"m.yaml:7:", "missing key 'signals/q/column'"});
}

TEST(LogImportMapping, RejectsBadUnitsAndReferences) {
  expectError([] { nb::parseImportMapping(replaced(kMapping, "L/min", "l/min"), "m.yaml"); },
              {"m.yaml:7:", "unknown unit 'l/min'"});
  expectError([] { nb::parseImportMapping(replaced(kMapping, "mdot_in_kg_s: q", "mdot_in_kg_s: sp"), "m.yaml"); },
              {"m.yaml:9:", "run/mdot_in_kg_s", "pressure"});
  expectError([] { nb::parseImportMapping(replaced(kMapping, "reference: sp", "reference: nope"), "m.yaml"); },
              {"m.yaml:5:", "no signal named 'nope'"});
  expectError(
      [] { nb::parseImportMapping(replaced(kMapping, ", detect: {reference: sp, ratio: [0.7, 1.4]}", ""), "m.yaml"); },
      {"m.yaml:5:", "need a 'detect' rule"});
  expectError([] { nb::parseImportMapping(replaced(kMapping, "p_setpoint_gauge_pa", "setpoint_pa"), "m.yaml"); },
              {"m.yaml:9:", "unknown run column 'setpoint_pa'"});
  expectError([] { nb::parseImportMapping(replaced(kMapping, "roles: alternate", "roles: every_other"), "m.yaml"); },
              {"m.yaml:11:", "roles"});
  expectError([] { nb::parseImportMapping(replaced(kMapping, "import_mapping: 1", "import_mapping: 2"), "m.yaml"); },
              {"m.yaml:1:", "unsupported version 2"});
}

TEST(LogImport, DetectsKpaAndCutsWholeCycles) {
  const std::string dir = tmpDir("detect");
  const nb::ImportMapping m = nb::parseImportMapping(kMapping, "m.yaml");
  for (const bool kpa : {false, true}) {
    const nb::ImportedLog log = nb::importLog(m, writeFile(dir, kpa ? "kpa.csv" : "cmh2o.csv", syntheticLog(kpa)));
    EXPECT_EQ(log.cycles, 3u);
    ASSERT_EQ(log.runs.size(), 3u);
    const nb::RunData& r = log.runs[0];
    EXPECT_EQ(r.name, kpa ? "kpa_01.csv" : "cmh2o_01.csv");
    EXPECT_DOUBLE_EQ(r.t_s.front(), 0.5);  // the first sample of the rise
    EXPECT_DOUBLE_EQ(r.t_s.back(), 2.5);   // the next cycle's start
    EXPECT_NEAR(r.p_gauge_pa.front(), 5.0 * kCmH2O, 1e-9);
    EXPECT_EQ(r.meta.at("import_units").find(kpa ? "p=kPa (detected)" : "p=cmH2O (detected)") != std::string::npos,
              true)
        << r.meta.at("import_units");
    EXPECT_NE(log.notes.back().find(kpa ? "p in kPa" : "p in cmH2O"), std::string::npos) << log.notes.back();
    EXPECT_EQ(r.role, "fit");
    EXPECT_EQ(log.runs[1].role, "withheld");
    EXPECT_EQ(log.runs[2].role, "fit");
    EXPECT_DOUBLE_EQ(r.load_n, 2.5);
    EXPECT_EQ(r.airbag, "lung.yaml");
  }
}

namespace {

/// 16 s at 100 Hz: 7 whole cycles of kMapping's setpoint (rises at 0.5, 2.5, ..., 14.5 s), the
/// flow filling at 6 L/min while the setpoint is up and emptying at 6 L/min while it is down
/// (logged with the mapping's sign flipped); the cycle starting at `odd_start` s carries a
/// third of that flow.
std::string fillingLog(double odd_start) {
  std::ostringstream s;
  s.precision(17);
  s << "t,sp,p,q\n";
  for (int i = 0; i < 1600; ++i) {
    const double t = i * 0.01, phase = std::fmod(t + 1.5, 2.0);
    double sp = 5.0;
    if (phase < 1.0) sp = 5.0 + 10.0 * std::min(1.0, phase / 0.1);
    if (t < 0.5) sp = 5.0;
    double q = sp >= 10.0 ? 6.0 : -6.0;
    if (t >= odd_start && t < odd_start + 2.0) q /= 3.0;
    s << i * 10 << "," << sp << "," << sp << "," << -q << "\n";
  }
  return s.str();
}

const std::string kTypical = "cycles: {signal: sp, cycles_per_run: 2, keep_typical: {flow: q, factor: 1.25}}";

}  // namespace

TEST(LogImport, LeavesOutCyclesUnlikeTheOthersAndNeverRunsAcrossThem) {
  const std::string dir = tmpDir("typical");
  const nb::ImportMapping m =
      nb::parseImportMapping(replaced(kMapping, "cycles: {signal: sp, cycles_per_run: 1}", kTypical), "m.yaml");
  ASSERT_TRUE(m.cycles->keep_typical);
  EXPECT_EQ(m.cycles->keep_typical->flow, "q");
  EXPECT_DOUBLE_EQ(m.cycles->keep_typical->factor, 1.25);
  const nb::ImportedLog log = nb::importLog(m, writeFile(dir, "odd.csv", fillingLog(4.5)));
  EXPECT_EQ(log.cycles, 7u);
  EXPECT_EQ(log.left_out, (std::vector<std::size_t>{2}));
  // Cycles 1-2, then 4-5 and 6-7: the run after the odd cycle starts where it ends.
  ASSERT_EQ(log.runs.size(), 3u);
  EXPECT_EQ(log.runs[0].meta.at("import_cycles"), "1-2 of 7");
  EXPECT_EQ(log.runs[1].meta.at("import_cycles"), "4-5 of 7");
  EXPECT_EQ(log.runs[2].meta.at("import_cycles"), "6-7 of 7");
  EXPECT_DOUBLE_EQ(log.runs[0].t_s.back(), 4.5);
  EXPECT_DOUBLE_EQ(log.runs[1].t_s.front(), 6.5);
  EXPECT_EQ(log.runs[1].role, "withheld");
  bool noted = false;
  for (const auto& n : log.notes) noted |= n.find("cycle 3 (4.5-6.5 s) left out") != std::string::npos;
  EXPECT_TRUE(noted);
  // Every cycle alike: nothing left out, the runs as without the rule.
  const nb::ImportedLog plain = nb::importLog(m, writeFile(dir, "plain.csv", fillingLog(100.0)));
  EXPECT_TRUE(plain.left_out.empty());
  ASSERT_EQ(plain.runs.size(), 4u);
  EXPECT_EQ(plain.runs[3].meta.at("import_cycles"), "7-7 of 7");
  // A flow that does not empty with the cycles cannot be judged.
  expectError([&] { nb::importLog(m, writeFile(dir, "steady.csv", syntheticLog(false))); },
              {"steady.csv", "cycles/keep_typical", "not positive"});
}

TEST(LogImportMapping, RejectsBadKeepTypicalValuesNamingTheKey) {
  auto with = [](const std::string& rule) {
    return replaced(kMapping, "cycles: {signal: sp, cycles_per_run: 1}",
                    "cycles: {signal: sp, cycles_per_run: 2, keep_typical: " + rule + "}");
  };
  expectError([&] { nb::parseImportMapping(with("{flow: q, factor: 1}"), "m.yaml"); },
              {"m.yaml:10:", "cycles/keep_typical/factor: must be > 1"});
  expectError([&] { nb::parseImportMapping(with("{flow: q, factor: 0.5}"), "m.yaml"); },
              {"m.yaml:10:", "cycles/keep_typical/factor"});
  expectError([&] { nb::parseImportMapping(with("{flow: q, factor: wide}"), "m.yaml"); },
              {"m.yaml:10:", "cycles/keep_typical/factor"});
  expectError([&] { nb::parseImportMapping(with("{flow: sp, factor: 1.5}"), "m.yaml"); },
              {"m.yaml:10:", "cycles/keep_typical/flow", "pressure, not a flow"});
  expectError([&] { nb::parseImportMapping(with("{flow: nope, factor: 1.5}"), "m.yaml"); },
              {"m.yaml:10:", "cycles/keep_typical/flow: no signal named 'nope'"});
  expectError([&] { nb::parseImportMapping(with("{flow: q, fator: 1.5}"), "m.yaml"); },
              {"m.yaml:10:", "unknown key 'cycles/keep_typical/fator'"});
  expectError([&] { nb::parseImportMapping(with("{flow: q}"), "m.yaml"); },
              {"m.yaml:10:", "missing key 'cycles/keep_typical/factor'"});
}

TEST(LogImport, ConvertsScaleOffsetSignAndVolumeToMassFlow) {
  const std::string dir = tmpDir("convert");
  std::string map = replaced(kMapping, "sign: -1}", "sign: -1, scale: 2, offset: 1}");
  const nb::ImportedLog log =
      nb::importLog(nb::parseImportMapping(map, "m.yaml"), writeFile(dir, "a.csv", syntheticLog(false)));
  // -(2 * 6 + 1) L/min at 1.2 kg/m^3
  EXPECT_NEAR(log.runs[0].mdot_in_kg_s[10], -13.0e-3 / 60.0 * 1.2, 1e-15);
  EXPECT_TRUE(std::isnan(log.runs[0].h_m[0]));
  ASSERT_EQ(log.runs[0].p_setpoint_gauge_pa.size(), log.runs[0].size());
  EXPECT_NEAR(log.runs[0].p_setpoint_gauge_pa.front(), 5.0 * kCmH2O, 1e-9);
  // A meter that assumed another density: Q sqrt(rho_meter rho).
  map = replaced(kMapping, "sign: -1}", "sign: -1, meter_density_kg_m3: 1.225}");
  const nb::ImportedLog metered =
      nb::importLog(nb::parseImportMapping(map, "m.yaml"), writeFile(dir, "b.csv", syntheticLog(false)));
  EXPECT_NEAR(metered.runs[0].mdot_in_kg_s[10], -6.0e-3 / 60.0 * std::sqrt(1.225 * 1.2), 1e-15);
}

TEST(LogImport, VenturiGivesTheMassFlowOfItsFormula) {
  const std::string dir = tmpDir("venturi");
  const std::string map = replaced(kMapping, "  q: {column: q, unit: L/min, sign: -1}\n",
                                   "  dpi: {column: q, unit: Pa}\n  dpe: {column: sp, unit: Pa}\n"
                                   "  q: {venturi: {forward: dpi, reverse: dpe, discharge_coefficient: 0.97,"
                                   " inlet_diameter_m: 0.01505, throat_diameter_m: 0.0055}}\n");
  const nb::ImportedLog log =
      nb::importLog(nb::parseImportMapping(map, "m.yaml"), writeFile(dir, "a.csv", syntheticLog(false)));
  const double a1 = M_PI / 4 * 0.01505 * 0.01505, a2 = M_PI / 4 * 0.0055 * 0.0055;
  const double k = 0.97 * a1 * a2 / std::sqrt(a1 * a1 - a2 * a2);
  // at the run's start: dp_inhale 6 Pa, dp_exhale 5 Pa (the setpoint column read as Pa)
  const double expected = k * (std::sqrt(2 * 6 * 1.2) - std::sqrt(2 * 5 * 1.2));
  EXPECT_NEAR(log.runs[0].mdot_in_kg_s[0], expected, 1e-12 * std::abs(expected) + 1e-15);
}

TEST(LogImport, RefusesMalformedLogsNamingFileLineAndColumn) {
  const std::string dir = tmpDir("malformed");
  const nb::ImportMapping m = nb::parseImportMapping(kMapping, "m.yaml");
  const std::string good = syntheticLog(false);
  auto import = [&](const std::string& name, const std::string& text) {
    return [&m, path = writeFile(dir, name, text)] { nb::importLog(m, path); };
  };
  expectError(import("missing.csv", replaced(good, "t,sp,p,q", "t,sp,pressure,q")),
              {"missing.csv:3:", "column 'p'", "not in the header"});
  expectError(import("text.csv", replaced(good, "\n100,5,5,6\n", "\n100,5,five,6\n")),
              {"text.csv:14:", "column 'p' (3)", "non-numeric field 'five'"});
  expectError(import("back.csv", replaced(good, "\n100,5,5,6\n", "\n80,5,5,6\n")),
              {"back.csv:14:", "column 't' (1)", "time not strictly increasing"});
  expectError(import("width.csv", replaced(good, "\n100,5,5,6\n", "\n100,5,5\n")),
              {"width.csv:14:", "expected 4 fields"});
  expectError(import("empty.csv", "# only a comment\n"), {"empty.csv:1:", "no header"});
  // A pressure in neither unit: ten times the setpoint.
  std::string tenfold = "t,sp,p,q\n";
  for (int i = 0; i < 800; ++i) tenfold += std::to_string(i * 10) + "," + (i % 200 < 100 ? "5,50" : "15,150") + ",6\n";
  expectError(import("unit.csv", tenfold), {"unit.csv", "column 'p'", "cannot tell its unit", "none fits"});
  // No rise of the setpoint: no cycle to cut.
  std::string flat = "t,sp,p,q\n";
  for (int i = 0; i < 50; ++i) flat += std::to_string(i * 10) + ",5,5,6\n";
  expectError(import("flat.csv", flat), {"flat.csv", "column 'sp'", "0 cycle start(s)"});
}

TEST(LogImport, WritesNothingWhenAnyLogIsBad) {
  const std::string dir = tmpDir("nothing_written");
  const nb::ImportMapping m = nb::parseImportMapping(kMapping, "m.yaml");
  const std::string good = writeFile(dir, "good.csv", syntheticLog(false));
  const std::string bad = writeFile(dir, "bad.csv", replaced(syntheticLog(false), "\n100,5,5,6\n", "\n100,5,x,6\n"));
  const std::string out = (fs::path(dir) / "out").string();
  expectError([&] { nb::importLogsToDataset(m, {good, bad}, out); }, {"bad.csv:14:"});
  EXPECT_FALSE(fs::exists(out));
  for (const auto& e : fs::directory_iterator(dir)) EXPECT_EQ(e.path().extension(), ".csv") << e.path();
  // Two logs giving runs of one name, and an output directory in use, are refused too.
  expectError([&] { nb::importLogsToDataset(m, {good, good}, out); }, {"good_01.csv", "run_prefix"});
  EXPECT_FALSE(fs::exists(out));
  fs::create_directories(out);
  writeFile(out, "keep.txt", "x");
  expectError([&] { nb::importLogsToDataset(m, {good}, out); }, {"not an empty directory"});
  EXPECT_TRUE(fs::exists(fs::path(out) / "keep.txt"));
}

TEST(LogImport, WritesADatasetTheDiagnosisReads) {
  const std::string dir = tmpDir("dataset");
  const std::string map = replaced(kMapping, "roles: alternate", "roles: {a_02.csv: withheld, a_03.csv: fit}");
  const nb::ImportMapping m = nb::parseImportMapping(map, "m.yaml");
  const std::string out = (fs::path(dir) / "out").string();
  const auto logs = nb::importLogsToDataset(m, {writeFile(dir, "a.csv", syntheticLog(true))}, out);
  const std::vector<nb::RunData> runs = nb::readDataset(out);
  ASSERT_EQ(runs.size(), 3u);
  EXPECT_EQ(runs[0].role, "");
  EXPECT_EQ(runs[1].role, "withheld");
  EXPECT_EQ(runs[2].role, "fit");
  EXPECT_EQ(runs[1].p_gauge_pa, logs[0].runs[1].p_gauge_pa);
  EXPECT_EQ(runs[1].p_setpoint_gauge_pa, logs[0].runs[1].p_setpoint_gauge_pa);  // the optional column
  EXPECT_EQ(runs[1].meta.at("import_source"), "a.csv");
  EXPECT_EQ(runs[1].meta.at("import_cycles"), "2-2 of 3");
  expectError(
      [&] {
        nb::importLogsToDataset(nb::parseImportMapping(replaced(map, "a_03", "a_09"), "m.yaml"),
                                {writeFile(dir, "a.csv", syntheticLog(true))}, (fs::path(dir) / "out2").string());
      },
      {"m.yaml", "'a_09.csv' is not a run"});
  EXPECT_FALSE(fs::exists(fs::path(dir) / "out2"));
}

// ---- the shipped ventilator recordings (test/data/respiraworks) and mappings (config/import) ----

namespace {

struct Recording {
  std::string mapping, file;
  std::size_t cycles;
  double peep_cmh2o, compliance_ml_cmh2o;
  const char* pressure_unit;
};

// Settings from the recordings' test table; cycle counts are the setpoint's whole rise-to-rise
// periods in each file (3 s breaths, 5 s in tests 2 and 6).
const std::vector<Recording> kRecordings = {
    {"respiraworks_net_flow", "2020-06-21-RunForRecord2-AIR/covent_pc_1.dat", 9, 5, 50, "cmH2O"},
    {"respiraworks_net_flow", "2020-06-21-RunForRecord2-AIR/covent_pc_2.dat", 5, 10, 50, "cmH2O"},
    {"respiraworks_net_flow", "2020-06-21-RunForRecord2-AIR/covent_pc_3.dat", 10, 5, 20, "cmH2O"},
    {"respiraworks_net_flow", "2020-06-21-RunForRecord2-AIR/covent_pc_4.dat", 9, 10, 20, "cmH2O"},
    {"respiraworks_net_flow", "2020-06-21-RunForRecord2-AIR/covent_pc_5.dat", 9, 5, 20, "cmH2O"},
    {"respiraworks_net_flow", "2020-06-21-RunForRecord2-AIR/covent_pc_6.dat", 5, 10, 20, "cmH2O"},
    {"respiraworks_net_flow", "2020-06-21-RunForRecord2-AIR/covent_pc_7.dat", 9, 5, 10, "cmH2O"},
    {"respiraworks_net_flow", "2020-06-21-RunForRecord2-AIR/covent_pc_8.dat", 9, 10, 10, "cmH2O"},
    {"respiraworks_venturi", "2020-07-01-Control-Tests-AIR/covent_pc_1.dat", 7, 5, 50, "kPa"},
    {"respiraworks_venturi", "2020-07-01-Control-Tests-AIR/covent_pc_3.dat", 7, 5, 20, "kPa"},
    {"respiraworks_venturi", "2020-07-01-Control-Tests-AIR/covent_pc_5.dat", 7, 5, 20, "kPa"},
    {"respiraworks_venturi", "2020-07-01-Control-Tests-AIR/covent_pc_7.dat", 7, 5, 10, "kPa"},
    {"respiraworks_obstruction", "2020-06-18-obstruction.dat", 7, 5, 10, "cmH2O"},
};

std::string mappingPath(const std::string& name) { return kSource + "/config/import/" + name + ".yaml"; }
std::string recordingPath(const std::string& file) { return kSource + "/test/data/respiraworks/" + file; }

double medianOf(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

}  // namespace

TEST(RespiraWorksImport, ResolvesUnitsCyclesAndRolesOfEveryRecording) {
  for (const Recording& rec : kRecordings) {
    SCOPED_TRACE(rec.file);
    const nb::ImportMapping m = nb::loadImportMapping(mappingPath(rec.mapping));
    const nb::ImportedLog log = nb::importLog(m, recordingPath(rec.file));
    EXPECT_EQ(log.cycles, rec.cycles);
    const bool whole = rec.mapping == "respiraworks_obstruction";
    ASSERT_EQ(log.runs.size(), whole ? 1u : (rec.cycles + 1) / 2);
    std::vector<double> before_breath;  // end-expiratory pressure: the last 0.3 s before each run
    for (std::size_t r = 0; r < log.runs.size(); ++r) {
      const nb::RunData& run = log.runs[r];
      EXPECT_NE(run.meta.at("import_units").find(std::string("pressure=") + rec.pressure_unit + " (detected)"),
                std::string::npos)
          << run.meta.at("import_units");
      EXPECT_EQ(run.role, whole ? "" : (r % 2 == 0 ? "fit" : "withheld"));
      EXPECT_DOUBLE_EQ(run.load_n, 0.0);
      EXPECT_NE(run.airbag.find("lung_quicklung_c"), std::string::npos);
      for (std::size_t i = 0; i + 1 < run.size(); ++i)
        if (run.t_s[i] >= run.t_s.back() - 0.3) before_breath.push_back(run.p_gauge_pa[i]);
      const auto& sp = run.p_setpoint_gauge_pa;
      ASSERT_EQ(sp.size(), run.size());
      EXPECT_NEAR(*std::min_element(sp.begin(), sp.end()), rec.peep_cmh2o * kCmH2O, 1e-6);
    }
    // PEEP as measured within 12 % of the setting (the obstruction trace undershoots it most).
    EXPECT_NEAR(medianOf(before_breath) / kCmH2O, rec.peep_cmh2o, 0.12 * rec.peep_cmh2o);
  }
}

TEST(RespiraWorksImport, TidalVolumeOverPressureSwingIsRoughlyTheCompliance) {
  for (const Recording& rec : kRecordings) {
    SCOPED_TRACE(rec.file);
    const nb::ImportMapping m = nb::loadImportMapping(mappingPath(rec.mapping));
    const nb::ImportedLog log = nb::importLog(m, recordingPath(rec.file));
    const nb::RunData& run = log.runs.front();  // its first breath is a normal one in every file
    const auto& sp = run.p_setpoint_gauge_pa;
    const double swing = *std::max_element(sp.begin(), sp.end()) - *std::min_element(sp.begin(), sp.end());
    double volume = 0.0, tidal = 0.0;
    for (std::size_t i = 1; i < run.size() && run.t_s[i] < run.t_s[0] + 2.0; ++i) {
      volume += 0.5 * (run.mdot_in_kg_s[i] + run.mdot_in_kg_s[i - 1]) / m.density_kg_m3 * (run.t_s[i] - run.t_s[i - 1]);
      tidal = std::max(tidal, volume);
    }
    const double c_ml_cmh2o = tidal * 1e6 / (swing / kCmH2O);
    EXPECT_GT(c_ml_cmh2o, rec.compliance_ml_cmh2o / 2);
    EXPECT_LT(c_ml_cmh2o, rec.compliance_ml_cmh2o * 2);
  }
}

TEST(RespiraWorksImport, ObstructionTraceKeepsBothFlows) {
  const nb::ImportMapping m = nb::loadImportMapping(mappingPath("respiraworks_obstruction"));
  const nb::ImportedLog log = nb::importLog(m, recordingPath("2020-06-18-obstruction.dat"));
  ASSERT_EQ(log.runs.size(), 1u);
  const nb::RunData& run = log.runs[0];
  EXPECT_NEAR(run.t_s.front(), 2.75, 0.02);
  EXPECT_NEAR(run.t_s.back(), 23.82, 0.02);
  const auto& raw = run.mdot_uncorrected_kg_s;
  ASSERT_EQ(raw.size(), run.size());
  // The correction is constant within a breath: the raw flow minus the corrected one is a
  // meter offset of a few to a few tens of mL/s.
  std::vector<double> offset_ml_s;
  const double to_ml_s = 1e6 / std::sqrt(1.225 * m.density_kg_m3);
  for (std::size_t i = 0; i < run.size(); ++i) offset_ml_s.push_back((raw[i] - run.mdot_in_kg_s[i]) * to_ml_s);
  EXPECT_GT(medianOf(offset_ml_s), 1.0);
  EXPECT_LT(medianOf(offset_ml_s), 40.0);
  // The first sample of the run as logged (t 2.750 s: pressure 4.834 cmH2O, net_flow -6.232 mL/s,
  // flow_uncorrected 19.846 mL/s), converted.
  EXPECT_NEAR(run.p_gauge_pa[0], 4.834 * kCmH2O, 1e-9);
  EXPECT_NEAR(run.mdot_in_kg_s[0] * to_ml_s, -6.232, 1e-9);
  EXPECT_NEAR(raw[0] * to_ml_s, 19.846, 1e-9);
  // Written and read back as the run format's optional column.
  const std::string out = tmpDir("obstruction") + "/out";
  nb::importLogsToDataset(m, {recordingPath("2020-06-18-obstruction.dat")}, out);
  const std::vector<nb::RunData> back = nb::readDataset(out);
  ASSERT_EQ(back.size(), 1u);
  EXPECT_EQ(back[0].name, "ob_2020-06-18-obstruction_01.csv");
  EXPECT_EQ(back[0].mdot_uncorrected_kg_s, raw);
  EXPECT_EQ(back[0].role, "");
}
