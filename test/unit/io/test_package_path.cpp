// Finding the package's folder at run time: an explicit folder alone, else ROS_PACKAGE_PATH
// (an entry that is the package or holds it directly), else the executable's prefix.
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <optional>
#include <stdexcept>
#include <string>

#include "../../test_helpers.h"
#include "nursing_bed/core/io/package_path.h"

namespace nb = nursing_bed;
namespace fs = std::filesystem;

namespace {

/// A folder holding a package.xml named `name`, with a config/ folder.
fs::path makePackage(const fs::path& dir, const std::string& name) {
  fs::create_directories(dir / "config");
  nb::test::writeFile(dir / "package.xml", "<?xml version=\"1.0\"?>\n<package format=\"3\">\n  <name>" + name +
                                               "</name>\n  <version>0.1.0</version>\n</package>\n");
  return dir;
}

/// Sets ROS_PACKAGE_PATH for one test and puts the caller's back after it.
class PackagePath : public ::testing::Test {
 protected:
  void SetUp() override {
    if (const char* v = std::getenv("ROS_PACKAGE_PATH")) saved_ = std::string(v);
    root_ = nb::test::freshTestDir("io", ::testing::UnitTest::GetInstance()->current_test_info()->name());
  }
  void TearDown() override {
    if (saved_) ::setenv("ROS_PACKAGE_PATH", saved_->c_str(), 1);
    else ::unsetenv("ROS_PACKAGE_PATH");
  }
  static void setRosPackagePath(const std::string& value) { ::setenv("ROS_PACKAGE_PATH", value.c_str(), 1); }

  std::optional<std::string> saved_;
  fs::path root_;
};

}  // namespace

TEST_F(PackagePath, AnExplicitFolderIsTheOnlyOneTried) {
  const fs::path mine = makePackage(root_ / "mine", "nursing_bed");
  setRosPackagePath(makePackage(root_ / "on_path", "nursing_bed").string());
  EXPECT_EQ(nb::findPackageDir("config", mine.string()), mine.string());
  EXPECT_EQ(nb::findPackageFile("config", mine.string()), (mine / "config").string());
  const fs::path empty = root_ / "empty";
  fs::create_directories(empty);
  try {
    nb::findPackageDir("config", empty.string());
    FAIL() << "a folder without config/ was accepted";
  } catch (const std::runtime_error& e) {
    nb::test::expectContains(e.what(), {"'config'", empty.string()});
    EXPECT_EQ(std::string(e.what()).find("on_path"), std::string::npos) << "looked past the explicit folder";
  }
}

TEST_F(PackagePath, FindsThePackageOnRosPackagePathAsAnEntryOrDirectlyInOne) {
  const fs::path src = root_ / "ws" / "src";
  makePackage(src / "other", "other_package");
  const fs::path checkout = makePackage(src / "checkout", "nursing_bed");
  setRosPackagePath((root_ / "gone").string() + ":" + src.string());
  EXPECT_EQ(nb::findPackageDir("config"), checkout.string()) << "inside a workspace's src/";
  setRosPackagePath(checkout.string());
  EXPECT_EQ(nb::findPackageDir("config"), checkout.string()) << "the entry itself";
}

TEST_F(PackagePath, APackageOfAnotherNameIsNotTaken) {
  const fs::path other = makePackage(root_ / "nursing_bed", "not_nursing_bed");
  nb::test::writeFile(other / "config" / "only_here.yaml", "a: 1\n");
  setRosPackagePath(other.string());
  for (const std::string& dir : nb::packageDirCandidates()) EXPECT_NE(dir, other.string());
  EXPECT_THROW(nb::findPackageDir("config/only_here.yaml"), std::runtime_error);
}

TEST_F(PackagePath, WithoutRosPackagePathTheExecutablesDevelSpaceLeadsToTheSource) {
  // This test program runs from the build's devel space, whose .catkin names the source tree.
  ::unsetenv("ROS_PACKAGE_PATH");
  EXPECT_EQ(fs::canonical(nb::findPackageDir("package.xml")), fs::canonical(NURSING_BED_SOURCE_DIR));
}

TEST_F(PackagePath, AFileFoundNowhereIsNamedWithTheFoldersTried) {
  const fs::path checkout = makePackage(root_ / "checkout", "nursing_bed");
  setRosPackagePath(checkout.string());
  try {
    nb::findPackageDir("config/no_such_file.yaml");
    FAIL() << "found a file that does not exist";
  } catch (const std::runtime_error& e) {
    nb::test::expectContains(e.what(), {"nursing_bed", "'config/no_such_file.yaml'", checkout.string()});
  }
}
