// scripts/function_lengths.py: no function in src/ is longer than about 80 lines (a longer one is
// a pipeline waiting to be named), and the checker itself finds a long function and honours
// an allow-list of known exceptions.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>
#include <vector>

#include "../../test_helpers.h"

namespace fs = std::filesystem;
using namespace nursing_bed::test;  // runCommand, shellQuote, writeFile, freshTestDir

namespace {

ToolResult longFunctions(const fs::path& where, int max_lines, const std::vector<std::string>& allow = {}) {
  std::string cmd = "/usr/bin/python3 " +
                    shellQuote(std::string(NURSING_BED_SOURCE_DIR) + "/scripts/function_lengths.py") + " --max " +
                    std::to_string(max_lines);
  for (const std::string& a : allow) cmd += " --allow " + shellQuote(a);
  return runCommand(cmd + " " + shellQuote(where.string()));
}

/// A file with a 3-line function and a 19-line one (lambda and braces in comments inside).
std::string shortAndLong() {
  std::string body = "namespace x {\nint shortOne() { return 1; }\n\nint longOne(int a) {\n";
  for (int i = 0; i < 12; ++i) body += "  a += " + std::to_string(i) + ";  // { not a brace }\n";
  body += "  auto f = [&](int b) {\n    return b + a;\n  };\n  return f(a);\n}\n}  // namespace x\n";
  return body;
}

}  // namespace

TEST(FunctionLengths, NoFunctionInSrcIsLongerThan80Lines) {
  const ToolResult r = longFunctions(fs::path(NURSING_BED_SOURCE_DIR) / "src", 80, {});
  EXPECT_EQ(r.code, 0) << r.output;
}

TEST(FunctionLengths, ALongFunctionIsFoundAndNamed) {
  const fs::path dir = freshTestDir("function_lengths", "long");
  writeFile(dir / "a.cpp", shortAndLong());
  const ToolResult r = longFunctions(dir, 10);
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("longOne"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("shortOne"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("1 function(s) longer than 10 lines"), std::string::npos) << r.output;
}

TEST(FunctionLengths, AnAllowedLongFunctionIsListedButDoesNotFail) {
  const fs::path dir = freshTestDir("function_lengths", "allowed");
  writeFile(dir / "a.cpp", shortAndLong());
  for (const std::string& rule :
       {std::string("longOne"), std::string("a.cpp:longOne"), (dir / "a.cpp:longOne").string()}) {
    const ToolResult r = longFunctions(dir, 10, {rule});
    EXPECT_EQ(r.code, 0) << rule << ": " << r.output;
    EXPECT_NE(r.output.find("longOne  (allowed)"), std::string::npos) << rule << ": " << r.output;
    EXPECT_NE(r.output.find("0 function(s) longer than 10 lines, 1 more allowed"), std::string::npos) << r.output;
  }
}

TEST(FunctionLengths, AnAllowForAnotherFileOrFunctionDoesNotExcuseIt) {
  const fs::path dir = freshTestDir("function_lengths", "not_allowed");
  writeFile(dir / "a.cpp", shortAndLong());
  for (const std::string& rule : {std::string("b.cpp:longOne"), std::string("x_a.cpp:longOne"),
                                  std::string("a.cpp:shortOne"), std::string("longOn")}) {
    const ToolResult r = longFunctions(dir, 10, {rule});
    EXPECT_EQ(r.code, 1) << rule << ": " << r.output;
    EXPECT_NE(r.output.find("1 function(s) longer than 10 lines"), std::string::npos) << r.output;
    // An allow that matches nothing is reported, so that the list does not outlive its reason.
    EXPECT_NE(r.output.find("note: --allow " + rule + " matches no function"), std::string::npos) << r.output;
  }
}

TEST(FunctionLengths, AQualifiedNameIsAllowedWithOrWithoutItsFile) {
  const fs::path dir = freshTestDir("function_lengths", "qualified");
  std::string body = "int Pump::run(int a) {\n";
  for (int i = 0; i < 12; ++i) body += "  a += " + std::to_string(i) + ";\n";
  body += "  return a;\n}\n";
  writeFile(dir / "pump.cpp", body);
  EXPECT_EQ(longFunctions(dir, 10).code, 1);
  EXPECT_EQ(longFunctions(dir, 10, {"Pump::run"}).code, 0);
  EXPECT_EQ(longFunctions(dir, 10, {"pump.cpp:Pump::run"}).code, 0);
  EXPECT_EQ(longFunctions(dir, 10, {"pump.cpp:run"}).code, 1);
}
