// scripts/function_lengths.py: the gap diagnosis keeps its functions to about 80 lines (a longer
// one is a pipeline waiting to be named), and the checker itself finds a long function.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "../../test_helpers.h"

namespace fs = std::filesystem;
using namespace nursing_bed::test;  // runCommand, shellQuote, writeFile, freshTestDir

namespace {

ToolResult longFunctions(const fs::path& where, int max_lines) {
  return runCommand("/usr/bin/python3 " +
                    shellQuote(std::string(NURSING_BED_SOURCE_DIR) + "/scripts/function_lengths.py") + " --max " +
                    std::to_string(max_lines) + " " + shellQuote(where.string()));
}

}  // namespace

TEST(FunctionLengths, NoFunctionOfTheGapDiagnosisIsLongerThan80Lines) {
  const ToolResult r = longFunctions(fs::path(NURSING_BED_SOURCE_DIR) / "src/core/gap", 80);
  EXPECT_EQ(r.code, 0) << r.output;
}

TEST(FunctionLengths, ALongFunctionIsFoundAndNamed) {
  const fs::path dir = freshTestDir("function_lengths", "long");
  std::string body = "namespace x {\nint shortOne() { return 1; }\n\nint longOne(int a) {\n";
  for (int i = 0; i < 12; ++i) body += "  a += " + std::to_string(i) + ";  // { not a brace }\n";
  body += "  auto f = [&](int b) {\n    return b + a;\n  };\n  return f(a);\n}\n}  // namespace x\n";
  writeFile(dir / "a.cpp", body);
  const ToolResult r = longFunctions(dir, 10);
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("longOne"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("shortOne"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("1 function(s) longer than 10 lines"), std::string::npos) << r.output;
}
