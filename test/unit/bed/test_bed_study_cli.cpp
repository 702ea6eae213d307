// bed_study's command line: a bad parameter file or supply is refused before any simulation, with
// the file and what is wrong, and nothing is written.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "../../test_helpers.h"

namespace fs = std::filesystem;
using namespace nursing_bed::test;  // expectContains, runCommand, shellQuote, writeFile

namespace {

/// bed_study: built beside the test binaries (both go to <devel>/lib/nursing_bed).
fs::path bedStudy() { return fs::read_symlink("/proc/self/exe").parent_path() / "bed_study"; }

ToolResult runBedStudy(const std::string& args) { return runCommand(shellQuote(bedStudy().string()) + " " + args); }

TEST(BedStudyCli, ABadCellFileIsRefusedWithTheFileAndTheKey) {
  const fs::path dir = freshTestDir("bed_study_cli", "bad_cell");
  const std::string bad = writeFile(dir / "bad_cell.yaml", "supply:\n  presure_pa: 20000.0\n");
  const fs::path out = dir / "out";
  const ToolResult r = runBedStudy("--out " + shellQuote(out.string()) + " --params " + shellQuote(bad));
  EXPECT_EQ(r.code, 2) << r.output;
  expectContains(r.output, {"--params", "bad_cell.yaml", "presure_pa"});
  EXPECT_FALSE(fs::exists(out)) << "wrote " << out;
}

TEST(BedStudyCli, ASupplyThatIsNoPressureIsRefused) {
  const fs::path dir = freshTestDir("bed_study_cli", "bad_supply");
  const ToolResult r = runBedStudy("--out " + shellQuote((dir / "out").string()) + " --supply -5");
  EXPECT_EQ(r.code, 2) << r.output;
  expectContains(r.output, {"--supply"});
  EXPECT_FALSE(fs::exists(dir / "out"));
}

}  // namespace
