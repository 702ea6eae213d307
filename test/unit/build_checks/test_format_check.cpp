// scripts/check_format.sh, the formatting check against .clang-format: it passes a formatted
// file, names a badly formatted one and fails, and refuses a path that does not exist; and the
// whole tree (src, include, test) follows it.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "../../test_helpers.h"

namespace fs = std::filesystem;
using namespace nursing_bed::test;  // runCommand, shellQuote, writeFile, freshTestDir

namespace {

ToolResult checkFormat(const std::string& args) {
  return runCommand(shellQuote(std::string(NURSING_BED_SOURCE_DIR) + "/scripts/check_format.sh") + " " + args);
}

const char* kGood =
    "#include <vector>\n"
    "\n"
    "namespace demo {\n"
    "\n"
    "/// Sum of the values.\n"
    "double sum(const std::vector<double>& values) {\n"
    "  double total = 0.0;\n"
    "  for (double v : values) total += v;\n"
    "  return total;\n"
    "}\n"
    "\n"
    "}  // namespace demo\n";

// Pointer bound to the name, a brace on its own line, a four-space indent.
const char* kBad =
    "namespace demo {\n"
    "int first(const int *values)\n"
    "{\n"
    "    return values[0];\n"
    "}\n"
    "}  // namespace demo\n";

}  // namespace

TEST(FormatCheck, AFormattedFilePasses) {
  const fs::path dir = freshTestDir("format", "good");
  const std::string good = writeFile(dir / "good.cpp", kGood);
  const ToolResult r = checkFormat(shellQuote(good));
  EXPECT_EQ(r.code, 0) << r.output;
}

TEST(FormatCheck, ABadlyFormattedFileIsNamedAndFailsTheCheck) {
  const fs::path dir = freshTestDir("format", "bad");
  writeFile(dir / "good.cpp", kGood);
  writeFile(dir / "bad.h", kBad);
  const ToolResult r = checkFormat(shellQuote(dir.string()));
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("bad.h"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("good.cpp"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("1 of 2 files differ"), std::string::npos) << r.output;
}

TEST(FormatCheck, APathThatDoesNotExistIsAnError) {
  const ToolResult r = checkFormat(shellQuote((freshTestDir("format", "missing", false) / "nothing.cpp").string()));
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("no such file"), std::string::npos) << r.output;
}

TEST(FormatCheck, TheWholeTreeFollowsClangFormat) {
  const ToolResult r = checkFormat("");
  EXPECT_EQ(r.code, 0) << r.output;
}
