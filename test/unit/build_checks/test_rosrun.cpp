// `rosrun nursing_bed <node>` finds the built nodes and tools: the devel space of a standalone
// build is <package>/devel, outside the <package>/build folder that rosrun skips.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "../../test_helpers.h"

namespace fs = std::filesystem;
using namespace nursing_bed::test;  // runCommand, shellQuote

namespace {

/// The folder this test program was built into: the devel space's lib/nursing_bed.
fs::path ownFolder() { return fs::read_symlink("/proc/self/exe").parent_path(); }

/// What `rosrun` would start for `name` (its --prefix echo prints the command instead).
ToolResult rosrunPath(const std::string& name) {
  return runCommand("rosrun --prefix echo nursing_bed " + shellQuote(name) + " </dev/null");
}

}  // namespace

TEST(Rosrun, FindsEveryCxxNodeInTheDevelSpace) {
  for (const char* node : {"airbag_node", "bed_manager_node", "simulator_node", "rig_emulator_node", "gap"}) {
    const ToolResult r = rosrunPath(node);
    EXPECT_EQ(r.code, 0) << node << ": " << r.output;
    EXPECT_NE(r.output.find((ownFolder() / node).string()), std::string::npos) << node << ": " << r.output;
  }
}

TEST(Rosrun, FindsThePythonTools) {
  const ToolResult r = rosrunPath("bedctl");
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("scripts/bedctl"), std::string::npos) << r.output;
}

TEST(Rosrun, NamesANodeThatDoesNotExist) {
  const ToolResult r = rosrunPath("no_such_node");
  EXPECT_NE(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("no_such_node"), std::string::npos) << r.output;
}
