// Run CSV reader/writer and dataset directories (doc/formats/run_data.md): every error case with its
// message, round trips, dataset.yaml roles.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

#include "nursing_bed/core/gap/run_data.h"

#include "../../test_helpers.h"

namespace nb = nursing_bed;
namespace fs = std::filesystem;

namespace {

using nursing_bed::test::slurp;
using nursing_bed::test::writeFile;

fs::path tmpDir(const std::string& name) { return nursing_bed::test::freshTestDir("run_data", name, true); }

const std::string kGood =
    "# nursing_bed_run: 1\n"
    "# load_n: 10.4\n"
    "# airbag: tpu_double_100\n"
    "# note: anything: even with colons\n"
    "# operator: someone\n"
    "t_s,mdot_in_kg_s,p_gauge_pa,h_m\n"
    "0.000,0.0,0.0,0.0\n"
    "0.010,1.2e-5,35.1,0.0003\n"
    "0.020,1.3e-5,,0.0005\n";

// The message of the runtime_error that reading `text` throws ("" when it does not throw).
std::string readError(const std::string& text, const std::string& name = "bad.csv") {
  const std::string path = writeFile(tmpDir("errors") / name, text);
  try {
    nb::readRunCsv(path);
  } catch (const std::runtime_error& e) {
    return e.what();
  }
  return "";
}

using nursing_bed::test::expectContains;

TEST(RunData, ReadsTheSpecExample) {
  const std::string path = writeFile(tmpDir("good") / "a.csv", kGood);
  const nb::RunData r = nb::readRunCsv(path);
  EXPECT_EQ(r.name, "a.csv");
  EXPECT_EQ(r.source, path);
  EXPECT_EQ(r.load_n, 10.4);
  EXPECT_EQ(r.airbag, "tpu_double_100");
  EXPECT_EQ(r.meta.at("note"), "anything: even with colons");
  EXPECT_EQ(r.meta.at("operator"), "someone");  // unknown keys kept
  ASSERT_EQ(r.size(), 3u);
  EXPECT_EQ(r.t_s[1], 0.01);
  EXPECT_EQ(r.mdot_in_kg_s[1], 1.2e-5);
  EXPECT_EQ(r.p_gauge_pa[1], 35.1);
  EXPECT_EQ(r.h_m[2], 0.0005);
  EXPECT_TRUE(std::isnan(r.p_gauge_pa[2]));  // empty field: not measured
  EXPECT_TRUE(r.load_n_series.empty() && r.valve_cmd.empty() && r.p_supply_gauge_pa.empty() && r.t_gas_k.empty());
  EXPECT_EQ(r.role, "");
  EXPECT_EQ(r.loadAt(1), 10.4);
}

TEST(RunData, ColumnOrderIsFreeAndUnknownColumnsAreIgnored) {
  const std::string text =
      "# nursing_bed_run: 1\r\n"
      "h_m, extra ,t_s,p_gauge_pa,valve_cmd,mdot_in_kg_s,load_n,t_gas_k,p_supply_gauge_pa\r\n"
      "0.001,x,0,10,1,1e-5,10.5,293.1,20000\r\n"
      "0.002,y,0.5,+20,-1,-1e-5,,293.2,0\r\n";
  const nb::RunData r = nb::readRunCsv(writeFile(tmpDir("order") / "b.csv", text));
  ASSERT_EQ(r.size(), 2u);
  EXPECT_EQ(r.t_s[1], 0.5);
  EXPECT_EQ(r.h_m[0], 0.001);
  EXPECT_EQ(r.p_gauge_pa[1], 20.0);
  EXPECT_EQ(r.mdot_in_kg_s[1], -1e-5);
  EXPECT_EQ(r.valve_cmd[1], -1.0);
  EXPECT_EQ(r.t_gas_k[0], 293.1);
  EXPECT_EQ(r.p_supply_gauge_pa[0], 20000.0);
  ASSERT_EQ(r.load_n_series.size(), 2u);
  EXPECT_TRUE(std::isnan(r.load_n));  // only a column
  EXPECT_EQ(r.loadAt(0), 10.5);
  EXPECT_TRUE(std::isnan(r.load_n_series[1]));
}

TEST(RunData, ReaderErrorsNameFileLineAndColumn) {
  // Missing required column.
  expectContains(readError("# nursing_bed_run: 1\n# load_n: 1\nt_s,mdot_in_kg_s,p_gauge_pa\n0,0,0\n1,0,0\n"),
                 {"bad.csv:3:", "missing required column 'h_m'"});
  // Non-numeric field.
  expectContains(readError("# nursing_bed_run: 1\n# load_n: 1\nt_s,mdot_in_kg_s,p_gauge_pa,h_m\n0,0,0,0\n"
                           "1,0,abc,0\n"),
                 {"bad.csv:5:", "column 'p_gauge_pa' (3)", "non-numeric field 'abc'"});
  expectContains(readError("# nursing_bed_run: 1\n# load_n: 1\nt_s,mdot_in_kg_s,p_gauge_pa,h_m\n0,0,0,0\n"
                           "1,0,0,1e400\n"),
                 {"bad.csv:5:", "column 'h_m' (4)", "not finite"});
  expectContains(readError("# nursing_bed_run: 1\n# load_n: 1\nt_s,mdot_in_kg_s,p_gauge_pa,h_m\n0,0,0,0\n"
                           "1,-inf,0,0\n"),
                 {"bad.csv:5:", "column 'mdot_in_kg_s' (2)", "not finite"});
  expectContains(readError("# nursing_bed_run: 1\n# load_n: 1\nt_s,mdot_in_kg_s,p_gauge_pa,h_m\n0,0,0,0\n"
                           "1,0,12 kPa,0\n"),
                 {"bad.csv:5:", "non-numeric field '12 kPa'"});
  // Time not strictly increasing.
  expectContains(readError("# nursing_bed_run: 1\n# load_n: 1\nt_s,mdot_in_kg_s,p_gauge_pa,h_m\n0,0,0,0\n"
                           "1,0,0,0\n1,0,0,0\n"),
                 {"bad.csv:6:", "column 't_s' (1)", "time not strictly increasing", "line 5"});
  expectContains(readError("# nursing_bed_run: 1\n# load_n: 1\nh_m,t_s,mdot_in_kg_s,p_gauge_pa\n0,0.5,0,0\n"
                           "0,0.2,0,0\n"),
                 {"bad.csv:5:", "column 't_s' (2)", "time not strictly increasing"});
  expectContains(readError("# nursing_bed_run: 1\n# load_n: 1\nt_s,mdot_in_kg_s,p_gauge_pa,h_m\n0,0,0,0\n,0,0,0\n"),
                 {"bad.csv:5:", "column 't_s' (1)", "time missing"});
  // Fewer than 2 rows.
  expectContains(readError("# nursing_bed_run: 1\n# load_n: 1\nt_s,mdot_in_kg_s,p_gauge_pa,h_m\n0,0,0,0\n"),
                 {"bad.csv:", "1 data row(s)", "at least 2"});
  expectContains(readError("# nursing_bed_run: 1\n# load_n: 1\nt_s,mdot_in_kg_s,p_gauge_pa,h_m\n"), {"0 data row(s)"});
  // Unsupported or missing version.
  expectContains(readError("# nursing_bed_run: 2\n# load_n: 1\nt_s,mdot_in_kg_s,p_gauge_pa,h_m\n0,0,0,0\n1,0,0,0\n"),
                 {"bad.csv:1:", "unsupported format version '2'"});
  expectContains(readError("# load_n: 1\nt_s,mdot_in_kg_s,p_gauge_pa,h_m\n0,0,0,0\n1,0,0,0\n"),
                 {"bad.csv:2:", "missing format version", "nursing_bed_run: 1"});
  // Missing or bad load_n.
  expectContains(readError("# nursing_bed_run: 1\nt_s,mdot_in_kg_s,p_gauge_pa,h_m\n0,0,0,0\n1,0,0,0\n"),
                 {"bad.csv:2:", "missing load_n"});
  expectContains(readError("# nursing_bed_run: 1\n# load_n: ten\nt_s,mdot_in_kg_s,p_gauge_pa,h_m\n0,0,0,0\n"
                           "1,0,0,0\n"),
                 {"bad.csv:2:", "load_n", "'ten'"});
  // Row of the wrong width, duplicate column, no header at all.
  expectContains(readError("# nursing_bed_run: 1\n# load_n: 1\nt_s,mdot_in_kg_s,p_gauge_pa,h_m\n0,0,0,0\n1,0,0\n"),
                 {"bad.csv:5:", "expected 4 fields", "got 3"});
  expectContains(readError("# nursing_bed_run: 1\n# load_n: 1\nt_s,h_m,mdot_in_kg_s,p_gauge_pa,h_m\n"),
                 {"bad.csv:3:", "column 'h_m' (5) appears twice"});
  expectContains(readError("# nursing_bed_run: 1\n# load_n: 1\n"), {"bad.csv:", "no header"});
  // How the flow was sampled: instant or interval_mean only.
  expectContains(readError("# nursing_bed_run: 1\n# load_n: 1\n# mdot_sampling: averaged\n"
                           "t_s,mdot_in_kg_s,p_gauge_pa,h_m\n0,0,0,0\n1,0,0,0\n"),
                 {"bad.csv:3:", "mdot_sampling", "instant or interval_mean", "'averaged'"});
  // Unreadable file.
  try {
    nb::readRunCsv("/nonexistent/dir/run.csv");
    ADD_FAILURE() << "no error";
  } catch (const std::runtime_error& e) {
    expectContains(e.what(), {"/nonexistent/dir/run.csv", "cannot open"});
  }
}

TEST(RunData, WriteThenReadGivesTheSameRunBitForBit) {
  nb::RunData r;
  r.name = "rt.csv";
  r.airbag = "tpu_double_100";
  r.load_n = 15.6;
  r.meta["note"] = "round trip";
  r.meta["custom_key"] = "kept";
  for (int i = 0; i < 50; ++i) {
    r.t_s.push_back(i * 0.013 + 1e-9 * i * i);
    r.mdot_in_kg_s.push_back(std::sin(i) * 1.234567891234e-3);
    r.p_gauge_pa.push_back(i == 7 ? NAN : 1000.0 / 3.0 * i);
    r.h_m.push_back(0.1 + 1e-17 * i);
    r.valve_cmd.push_back(i < 25 ? 1.0 : -0.5);
    r.t_gas_k.push_back(293.15 + i * 0.1);
  }
  const fs::path dir = tmpDir("roundtrip");
  nb::writeRunCsv((dir / "rt.csv").string(), r);
  const nb::RunData back = nb::readRunCsv((dir / "rt.csv").string());
  EXPECT_EQ(back.name, r.name);
  EXPECT_EQ(back.airbag, r.airbag);
  EXPECT_EQ(back.load_n, r.load_n);
  EXPECT_EQ(back.meta.at("note"), "round trip");
  EXPECT_EQ(back.meta.at("custom_key"), "kept");
  EXPECT_EQ(back.t_s, r.t_s);
  EXPECT_EQ(back.mdot_in_kg_s, r.mdot_in_kg_s);
  EXPECT_EQ(back.h_m, r.h_m);
  EXPECT_EQ(back.valve_cmd, r.valve_cmd);
  EXPECT_EQ(back.t_gas_k, r.t_gas_k);
  EXPECT_TRUE(back.load_n_series.empty());
  EXPECT_TRUE(back.p_supply_gauge_pa.empty());
  ASSERT_EQ(back.p_gauge_pa.size(), r.p_gauge_pa.size());
  for (std::size_t i = 0; i < r.size(); ++i) {
    if (std::isnan(r.p_gauge_pa[i])) {
      EXPECT_TRUE(std::isnan(back.p_gauge_pa[i]));
    } else {
      EXPECT_EQ(back.p_gauge_pa[i], r.p_gauge_pa[i]);
    }
  }
  EXPECT_FALSE(back.flow_interval_means);
  // Interval-mean flows say so in the metadata and read back as such.
  r.flow_interval_means = true;
  nb::writeRunCsv((dir / "means.csv").string(), r);
  EXPECT_TRUE(nb::readRunCsv((dir / "means.csv").string()).flow_interval_means);
  // Inconsistent columns are refused.
  r.h_m.pop_back();
  EXPECT_THROW(nb::writeRunCsv((dir / "bad.csv").string(), r), std::runtime_error);
}

// A directory with runs a.csv, b.csv, c.csv (and a file that is not a run).
fs::path makeDataset(const std::string& name) {
  const fs::path dir = tmpDir(name);
  for (const char* run : {"c.csv", "a.csv", "b.csv"}) writeFile(dir / run, kGood);
  writeFile(dir / "readme.txt", "not a run");
  return dir;
}

std::string datasetError(const fs::path& dir) {
  try {
    nb::readDataset(dir.string());
  } catch (const std::runtime_error& e) {
    return e.what();
  }
  return "";
}

TEST(RunData, DatasetReadsEveryCsvSortedWithRoles) {
  const fs::path dir = makeDataset("dataset_roles");
  // Without dataset.yaml: no roles, sorted by name.
  std::vector<nb::RunData> runs = nb::readDataset(dir.string());
  ASSERT_EQ(runs.size(), 3u);
  EXPECT_EQ(runs[0].name, "a.csv");
  EXPECT_EQ(runs[2].name, "c.csv");
  for (const auto& r : runs) EXPECT_EQ(r.role, "");

  writeFile(dir / "dataset.yaml", "airbag: my_airbag.yaml\nruns:\n  a.csv: fit\n  c.csv: withheld\n");
  runs = nb::readDataset(dir.string());
  EXPECT_EQ(runs[0].role, "fit");
  EXPECT_EQ(runs[1].role, "");
  EXPECT_EQ(runs[2].role, "withheld");
  EXPECT_EQ(runs[0].airbag, "tpu_double_100");  // the run's own airbag wins

  // Runs from elsewhere (bags) join in and may get roles too.
  nb::RunData extra = nb::readRunCsv((dir / "a.csv").string());
  extra.name = "rig/cell_0/state";
  extra.source = (dir / "rig.bag").string();
  extra.airbag.clear();
  writeFile(dir / "dataset.yaml", "airbag: my_airbag.yaml\nruns: {rig.bag: withheld, b.csv: fit}\n");
  runs = nb::readDataset(dir.string(), {extra});
  ASSERT_EQ(runs.size(), 4u);
  EXPECT_EQ(runs[3].name, "rig/cell_0/state");
  EXPECT_EQ(runs[3].role, "withheld");
  EXPECT_EQ(runs[3].airbag, "my_airbag.yaml");
  EXPECT_EQ(runs[1].role, "fit");
}

TEST(RunData, DatasetErrorsAreClear) {
  {
    const fs::path dir = tmpDir("dataset_empty");
    writeFile(dir / "notes.txt", "x");
    expectContains(datasetError(dir), {"no runs found"});
  }
  const fs::path dir = makeDataset("dataset_errors");
  writeFile(dir / "dataset.yaml", "runs:\n  a.csv: fit\n  d.csv: withheld\n");
  expectContains(datasetError(dir), {"dataset.yaml:3:", "'d.csv'", "not a run of the dataset", "a.csv, b.csv, c.csv"});
  writeFile(dir / "dataset.yaml", "runs:\n  a.csv: training\n");
  expectContains(datasetError(dir), {"dataset.yaml:2:", "bad role 'training'", "fit or withheld"});
  writeFile(dir / "dataset.yaml", "run:\n  a.csv: fit\n");
  expectContains(datasetError(dir), {"dataset.yaml:1:", "unknown key 'run'"});
  writeFile(dir / "dataset.yaml", "runs: [a.csv, b.csv]\n");
  expectContains(datasetError(dir), {"dataset.yaml", "runs: expected a map"});
  writeFile(dir / "dataset.yaml", "runs: {a.csv: fit\n");
  expectContains(datasetError(dir), {"dataset.yaml"});
  // A bad run file names itself.
  writeFile(dir / "dataset.yaml", "");
  writeFile(dir / "z.csv", "# nursing_bed_run: 3\n");
  expectContains(datasetError(dir), {"z.csv:1:", "unsupported format version"});
  fs::remove(dir / "z.csv");
  EXPECT_EQ(datasetError(dir), "");
  expectContains(datasetError(dir / "missing"), {"not a readable directory"});
}

TEST(RunData, AirbagNamesResolveToParameterFiles) {
  const std::string config = std::string(NURSING_BED_SOURCE_DIR) + "/config/";
  EXPECT_EQ(nb::resolveAirbagParamsFile(""), config + "airbag_tpu_double_100.yaml");
  EXPECT_EQ(nb::resolveAirbagParamsFile("tpu_double_100"), config + "airbag_tpu_double_100.yaml");
  EXPECT_EQ(nb::resolveAirbagParamsFile("airbag_tpu_double_100.yaml"), config + "airbag_tpu_double_100.yaml");
  const fs::path dir = tmpDir("airbag");
  writeFile(dir / "mine.yaml", "plate:\n  mass_kg: 0.1\n");
  EXPECT_EQ(nb::resolveAirbagParamsFile("mine.yaml", dir.string()), (dir / "mine.yaml").string());
  try {
    nb::resolveAirbagParamsFile("nonesuch");
    ADD_FAILURE() << "no error";
  } catch (const std::runtime_error& e) {
    expectContains(e.what(), {"airbag 'nonesuch'", "airbag_nonesuch.yaml"});
  }
}

}  // namespace
