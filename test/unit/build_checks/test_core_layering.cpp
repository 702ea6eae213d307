// The configure-time check that a core domain includes nothing from a domain above it
// (cmake/core_layering.cmake), run in script mode on the real tree and on small trees with one
// bad include each: it must pass the first and fail the others, naming the offending file.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "../../test_helpers.h"

namespace fs = std::filesystem;
using namespace nursing_bed::test;  // runCommand, shellQuote, writeFile, freshTestDir

namespace {

ToolResult runCheck(const fs::path& root) {
  return runCommand(shellQuote(NURSING_BED_CMAKE_COMMAND) + " -DROOT=" + shellQuote(root.string()) + " -P " +
                    shellQuote(std::string(NURSING_BED_SOURCE_DIR) + "/cmake/check_core_layering.cmake"));
}

/// A minimal good tree (physics below control, each including what it may), plus `bad_file`
/// holding `bad_text` when given.
fs::path tree(const std::string& name, const std::string& bad_file = "", const std::string& bad_text = "") {
  const fs::path root = freshTestDir("layering", name);
  for (const char* dir : {"include/nursing_bed/core/physics", "include/nursing_bed/core/control",
                          "include/nursing_bed/core/gap", "src/core/physics", "src/core/control"})
    fs::create_directories(root / dir);
  writeFile(root / "include/nursing_bed/core/physics/gas.h", "#pragma once\n");
  writeFile(root / "include/nursing_bed/core/control/ctl.h", "#include \"nursing_bed/core/physics/gas.h\"\n");
  writeFile(root / "src/core/physics/gas.cpp", "#include \"nursing_bed/core/physics/gas.h\"\n");
  if (!bad_file.empty()) writeFile(root / bad_file, bad_text);
  return root;
}

struct BadTree {
  const char* name;
  const char* file;
  const char* text;
  const char* message;  ///< a fragment the error must contain (besides the file)
};

}  // namespace

TEST(CoreLayering, TheRealTreePasses) {
  const ToolResult r = runCheck(NURSING_BED_SOURCE_DIR);
  EXPECT_EQ(r.code, 0) << r.output;
}

TEST(CoreLayering, AGoodSmallTreePasses) {
  const ToolResult r = runCheck(tree("good"));
  EXPECT_EQ(r.code, 0) << r.output;
}

TEST(CoreLayering, EveryBadIncludeFailsTheCheckNamingItsFile) {
  const BadTree cases[] = {
      {"physics_up", "src/core/physics/bad.cpp", "#include \"nursing_bed/core/control/ctl.h\"\n", "'control'"},
      {"gap_side", "include/nursing_bed/core/gap/bad.h", "#include <nursing_bed/core/bed/grid.h>\n", "'bed'"},
      {"ros_in_core", "src/core/control/bad.cpp", "#include <ros/ros.h>\n", "ROS header"},
      {"stray", "include/nursing_bed/core/bad.h", "#pragma once\n", "not in a domain folder"},
  };
  for (const BadTree& c : cases) {
    const ToolResult r = runCheck(tree(c.name, c.file, c.text));
    EXPECT_NE(r.code, 0) << c.name << ": " << r.output;
    EXPECT_NE(r.output.find(fs::path(c.file).filename().string()), std::string::npos) << c.name << ": " << r.output;
    EXPECT_NE(r.output.find(c.message), std::string::npos) << c.name << ": " << r.output;
  }
}
