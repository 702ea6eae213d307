// The configure-time check that a core domain includes nothing from a domain above it
// (cmake/core_layering.cmake), run in script mode on the real tree and on small trees with one
// bad include each: it must pass the first and fail the others, naming the offending file.
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

namespace fs = std::filesystem;

namespace {

struct CheckResult {
  int exit_code;
  std::string output;
};

CheckResult runCheck(const fs::path& root) {
  const std::string cmd = std::string(NURSING_BED_CMAKE_COMMAND) + " -DROOT=" + root.string() +
                          " -P " + NURSING_BED_SOURCE_DIR + "/cmake/check_core_layering.cmake 2>&1";
  CheckResult r{-1, ""};
  FILE* pipe = popen(cmd.c_str(), "r");
  if (!pipe) return r;
  char buf[512];
  while (fgets(buf, sizeof(buf), pipe)) r.output += buf;
  r.exit_code = pclose(pipe);
  return r;
}

void writeFile(const fs::path& p, const std::string& text) {
  fs::create_directories(p.parent_path());
  std::ofstream(p) << text;
}

/// A minimal good tree: physics below control, each including what it may.
fs::path goodTree(const std::string& name) {
  const fs::path root = fs::path(NURSING_BED_TEST_TMP_DIR) / name;
  fs::remove_all(root);
  writeFile(root / "include/nursing_bed/core/physics/gas.h", "#pragma once\n");
  writeFile(root / "include/nursing_bed/core/control/ctl.h",
            "#include \"nursing_bed/core/physics/gas.h\"\n");
  writeFile(root / "src/core/physics/gas.cpp", "#include \"nursing_bed/core/physics/gas.h\"\n");
  return root;
}

}  // namespace

TEST(CoreLayering, TheRealTreePasses) {
  const CheckResult r = runCheck(NURSING_BED_SOURCE_DIR);
  EXPECT_EQ(r.exit_code, 0) << r.output;
}

TEST(CoreLayering, AGoodSmallTreePasses) {
  const CheckResult r = runCheck(goodTree("good"));
  EXPECT_EQ(r.exit_code, 0) << r.output;
}

TEST(CoreLayering, PhysicsIncludingControlFails) {
  const fs::path root = goodTree("physics_up");
  writeFile(root / "src/core/physics/bad.cpp", "#include \"nursing_bed/core/control/ctl.h\"\n");
  const CheckResult r = runCheck(root);
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("physics/bad.cpp"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("'control'"), std::string::npos) << r.output;
}

TEST(CoreLayering, GapIncludingBedFails) {
  const fs::path root = goodTree("gap_side");
  writeFile(root / "include/nursing_bed/core/gap/bad.h", "#include <nursing_bed/core/bed/grid.h>\n");
  const CheckResult r = runCheck(root);
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("gap/bad.h"), std::string::npos) << r.output;
}

TEST(CoreLayering, RosHeaderInCoreFails) {
  const fs::path root = goodTree("ros_in_core");
  writeFile(root / "src/core/control/bad.cpp", "#include <ros/ros.h>\n");
  const CheckResult r = runCheck(root);
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("ROS header"), std::string::npos) << r.output;
}

TEST(CoreLayering, AFileOutsideAnyDomainFails) {
  const fs::path root = goodTree("stray");
  writeFile(root / "include/nursing_bed/core/stray.h", "#pragma once\n");
  const CheckResult r = runCheck(root);
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("not in a domain folder"), std::string::npos) << r.output;
}
