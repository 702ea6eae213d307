// scripts/class_sizes.py: a class in core/ with more than 25 methods or 15 data members says
// why in a `// size: <reason>` line above it (or is split), and the counter counts what it
// should on small headers made to be good and bad.
#include <gtest/gtest.h>

#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

#include "../../test_helpers.h"

namespace fs = std::filesystem;
using namespace nursing_bed::test;  // runCommand, shellQuote, writeFile, freshTestDir

namespace {

ToolResult classSizes(const fs::path& where, const std::vector<std::string>& options = {}) {
  std::string cmd = "/usr/bin/python3 " + shellQuote(std::string(NURSING_BED_SOURCE_DIR) + "/scripts/class_sizes.py");
  for (const std::string& o : options) cmd += " " + shellQuote(o);
  return runCommand(cmd + " " + shellQuote(where.string()));
}

/// The line the script prints for class `name` ("methods data name (file:line) status"), or "".
std::string lineOf(const std::string& output, const std::string& name) {
  const std::string key = "  " + name + "  (";
  const auto at = output.find(key);
  if (at == std::string::npos) return "";
  const auto begin = output.rfind('\n', at);
  const auto end = output.find('\n', at);
  return output.substr(begin == std::string::npos ? 0 : begin + 1, end - (begin == std::string::npos ? 0 : begin + 1));
}

/// "<methods> <data>" as the script counted them for `name`.
std::string counts(const std::string& output, const std::string& name) {
  std::istringstream in(lineOf(output, name));
  std::string methods, data;
  in >> methods >> data;
  return methods + " " + data;
}

/// `n` one-line methods named prefix0..; `n` data members named prefix0_...
std::string methods(int n, const std::string& prefix = "m") {
  std::string s;
  for (int i = 0; i < n; ++i)
    s += "  int " + prefix + std::to_string(i) + "() const { return " + std::to_string(i) + "; }\n";
  return s;
}
std::string members(int n, const std::string& prefix = "d") {
  std::string s;
  for (int i = 0; i < n; ++i) s += "  double " + prefix + std::to_string(i) + "_ = 0.0;\n";
  return s;
}

}  // namespace

TEST(ClassSizes, EveryLargeClassInCoreGivesItsReason) {
  const ToolResult r = classSizes(fs::path(NURSING_BED_SOURCE_DIR) / "include/nursing_bed/core", {});
  EXPECT_EQ(r.code, 0) << r.output;
}

TEST(ClassSizes, CountsMethodsAndDataMembersTheWayTheRuleMeansThem) {
  const fs::path dir = freshTestDir("class_sizes", "counts");
  writeFile(dir / "a.h",
            "#pragma once\n#include <map>\nnamespace x {\n"
            "enum class Mode { kA, kB };\n"
            "/// Doc.\n"
            "class Pump : public Base {\n"
            " public:\n"
            "  explicit Pump(int a) : a_(a), b_{2}, c_{} {}\n"
            "  ~Pump() override;\n"
            "  Pump(const Pump&) = delete;              // not a method: deleted\n"
            "  Pump& operator=(const Pump&) = delete;\n"
            "  bool operator==(const Pump& o) const { return a_ == o.a_; }\n"
            "  template <typename T> void visit(T t);\n"
            "  static Pump make();\n"
            "  int rate() const {\n    if (a_ > 0) { return 1; }\n    return 0;\n  }\n"
            "  static constexpr int kMax = 3;           // not a data member: static\n"
            "  using Map = std::map<int, double>;\n"
            "  struct Inner {\n    int p = 0, q = 0;\n    void f();\n  };\n"
            " private:\n"
            "  int a_, b_, c_;                           // three\n"
            "  std::map<int, double> m_ = {{1, 2.0}, {3, 4.0}};\n"
            "  std::function<void(int, int)> cb_;       // one, not a method\n"
            "  std::array<double, 3> arr_{};\n"
            "  friend class Other;\n"
            "  /* int commented_out_; */ // double also_not;\n"
            "  const char* name_ = \"a; b { c\";\n"
            "};\n"
            "struct Plain;\n"
            "}  // namespace x\n");
  const ToolResult r = classSizes(dir, {"--all"});
  EXPECT_EQ(r.code, 0) << r.output;
  // Pump: constructor, destructor, operator==, visit, make, rate.
  EXPECT_EQ(counts(r.output, "Pump"), "6 7") << r.output;
  EXPECT_EQ(counts(r.output, "Pump::Inner"), "1 2") << r.output;
  EXPECT_EQ(lineOf(r.output, "Mode"), "") << r.output;
  EXPECT_EQ(lineOf(r.output, "Plain"), "") << r.output;
  EXPECT_NE(lineOf(r.output, "Pump").find("a.h:6)"), std::string::npos) << r.output;
}

TEST(ClassSizes, ALargeClassWithoutAReasonFailsAndIsNamed) {
  const fs::path dir = freshTestDir("class_sizes", "bad");
  writeFile(dir / "many_methods.h", "/// Does too much.\nclass Busy {\n public:\n" + methods(26) + "};\n");
  writeFile(dir / "many_members.h", "struct Heavy {\n" + members(16) + "  void f();\n};\n");
  writeFile(dir / "small.h", "class Small {\n" + methods(25) + members(15) + "};\n");
  const ToolResult r = classSizes(dir);
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(lineOf(r.output, "Busy").find("OVER"), std::string::npos) << r.output;
  EXPECT_NE(lineOf(r.output, "Heavy").find("OVER"), std::string::npos) << r.output;
  EXPECT_EQ(lineOf(r.output, "Small"), "") << r.output;  // at the limits: not listed
  EXPECT_NE(r.output.find("2 class(es) over 25 methods or 15 data members without a reason"), std::string::npos)
      << r.output;
}

TEST(ClassSizes, AReasonRightAboveTheClassExcusesItsSize) {
  const fs::path dir = freshTestDir("class_sizes", "good");
  writeFile(dir / "a.h",
            "/// Integrates the cell.\n// size: one state per physical quantity of the cell\nclass Cell {\n" +
                members(20) +
                "};\n"
                "// size: the doc comment may follow\n/// Template too.\ntemplate <typename T>\nclass Tpl {\n" +
                methods(30) + "};\n");
  const ToolResult r = classSizes(dir);
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(lineOf(r.output, "Cell").find("reason given"), std::string::npos) << r.output;
  EXPECT_NE(lineOf(r.output, "Tpl").find("reason given"), std::string::npos) << r.output;
}

TEST(ClassSizes, AReasonElsewhereOrEmptyDoesNotCount) {
  const fs::path dir = freshTestDir("class_sizes", "misplaced");
  writeFile(dir / "a.h", "// size: a reason for something else\nint f();\nclass Far {\n" + members(16) + "};\n" +
                             "// size:\nclass Empty {\n" + members(16) + "};\n" +
                             "class Inside {\n  // size: inside is not above\n" + members(16) + "};\n");
  const ToolResult r = classSizes(dir);
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("3 class(es) over"), std::string::npos) << r.output;
}

TEST(ClassSizes, AParamsStructWithOnlyValidateIsExempt) {
  const fs::path dir = freshTestDir("class_sizes", "params");
  writeFile(dir / "a.h", "struct PumpParams {\n" + members(20, "k") + "  std::string validate() const;\n};\n" +
                             "struct FitOptions {\n" + members(16, "k") + "};\n" + "struct LoopConfig {\n" +
                             members(16, "k") + "  double gain() const;\n};\n" + "struct Settings {\n" +
                             members(16, "k") + "};\n");
  const ToolResult r = classSizes(dir);
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(lineOf(r.output, "PumpParams").find("exempt"), std::string::npos) << r.output;
  EXPECT_NE(lineOf(r.output, "FitOptions").find("exempt"), std::string::npos) << r.output;
  // A method besides validate(), or another name: an ordinary class.
  EXPECT_NE(lineOf(r.output, "LoopConfig").find("OVER"), std::string::npos) << r.output;
  EXPECT_NE(lineOf(r.output, "Settings").find("OVER"), std::string::npos) << r.output;
}

TEST(ClassSizes, AnAllowedClassDoesNotFailAndAStaleAllowIsReported) {
  const fs::path dir = freshTestDir("class_sizes", "allow");
  writeFile(dir / "a.h", "class Busy {\n" + methods(26) + "};\nclass Small {\n" + methods(2) + "};\n");
  const ToolResult r = classSizes(dir, {"--allow", "Busy", "--allow", "Small"});
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(lineOf(r.output, "Busy").find("ALLOWED"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("note: Small is allowed but not over the limits"), std::string::npos) << r.output;
  EXPECT_EQ(classSizes(dir, {"--allow", "Bus"}).code, 1);
}
