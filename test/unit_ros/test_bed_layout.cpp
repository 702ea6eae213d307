// The bed layout read from the URDF that scripts/make_bed_urdf.py generates, and its checks.
#include <gtest/gtest.h>

#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>

#include "nursing_bed/ros/bed_layout.h"

namespace nb = nursing_bed;

namespace {

const std::string kScript = "/usr/bin/python3 " NURSING_BED_SOURCE_DIR "/scripts/make_bed_urdf.py";

struct RunResult {
  int exit_code = -1;
  std::string output;
};

/// Runs a shell command, returns its exit code and stdout.
RunResult run(const std::string& command) {
  RunResult result;
  FILE* pipe = popen(command.c_str(), "r");
  if (pipe == nullptr) {
    return result;
  }
  char buffer[4096];
  size_t n = 0;
  while ((n = fread(buffer, 1, sizeof(buffer), pipe)) > 0) {
    result.output.append(buffer, n);
  }
  const int status = pclose(pipe);
  result.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return result;
}

std::string generate(const std::string& args) {
  const RunResult r = run(kScript + " " + args);
  EXPECT_EQ(r.exit_code, 0) << args;
  return r.output;
}

/// The message fromUrdf throws, or "" when it accepts the URDF.
std::string layoutError(const std::string& urdf) {
  try {
    nb::BedLayout::fromUrdf(urdf);
  } catch (const std::runtime_error& e) {
    return e.what();
  }
  return "";
}

/// A hand-written cell: joint and child link, with the parts a test wants to break.
std::string cellXml(int row, int col, double x_m, double y_m, const std::string& type = "prismatic",
                    const std::string& limit = "<limit lower=\"0\" upper=\"0.15\" effort=\"100\" velocity=\"1\"/>",
                    const std::string& axis = "0 0 1", const std::string& parent = "bed_link") {
  const std::string cell = "airbag_" + std::to_string(row) + "_" + std::to_string(col);
  std::ostringstream out;
  out << "<joint name=\"" << cell << "_joint\" type=\"" << type << "\"><parent link=\"" << parent
      << "\"/><child link=\"" << cell << "_link\"/><origin xyz=\"" << x_m << " " << y_m << " 0\"/><axis xyz=\"" << axis
      << "\"/>" << limit << "</joint><link name=\"" << cell << "_link\"/>";
  return out.str();
}

std::string robotXml(const std::string& body, const std::string& root_link = "bed_link") {
  return "<?xml version=\"1.0\"?><robot name=\"nursing_bed\"><link name=\"" + root_link + "\"/>" + body + "</robot>";
}

bool contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

TEST(BedLayout, SmallGeneratedGrid) {
  const nb::BedLayout layout = nb::BedLayout::fromUrdf(generate("--rows 3 --cols 2 --pitch 0.05 --max-height 0.12"));
  EXPECT_EQ(layout.rows(), 3);
  EXPECT_EQ(layout.cols(), 2);
  EXPECT_NEAR(layout.pitchM(), 0.05, 1e-12);
  ASSERT_EQ(layout.cells().size(), 6u);
  for (uint32_t id = 0; id < 6; ++id) {
    const nb::CellLayout& cell = layout.cells()[id];
    const int row = static_cast<int>(id) / 2;
    const int col = static_cast<int>(id) % 2;
    const std::string name = "airbag_" + std::to_string(row) + "_" + std::to_string(col);
    EXPECT_EQ(cell.id, id);
    EXPECT_EQ(cell.row, row);
    EXPECT_EQ(cell.col, col);
    EXPECT_EQ(cell.joint_name, name + "_joint");
    EXPECT_EQ(cell.link_name, name + "_link");
    // Row 0 at the head (+x), col 0 on the right (-y), grid centred on bed_link.
    EXPECT_NEAR(cell.x_m, (1.5 - row - 0.5) * 0.05, 1e-9) << name;
    EXPECT_NEAR(cell.y_m, (col + 0.5 - 1.0) * 0.05, 1e-9) << name;
    EXPECT_DOUBLE_EQ(cell.min_height_m, 0.0);
    EXPECT_DOUBLE_EQ(cell.max_height_m, 0.12);
    EXPECT_EQ(layout.find(row, col), &cell);
    EXPECT_EQ(layout.findId(id), &cell);
  }
  EXPECT_NEAR(layout.find(0, 0)->x_m, 0.05, 1e-9);
  EXPECT_NEAR(layout.find(0, 0)->y_m, -0.025, 1e-9);
  EXPECT_EQ(layout.find(3, 0), nullptr);
  EXPECT_EQ(layout.find(0, 2), nullptr);
  EXPECT_EQ(layout.find(-1, 0), nullptr);
  EXPECT_EQ(layout.findId(6), nullptr);
  EXPECT_TRUE(contains(layout.describe(), "3 x 2")) << layout.describe();
  EXPECT_TRUE(contains(layout.describe(), "pitch 0.05 m")) << layout.describe();
}

TEST(BedLayout, DefaultBedIs20By9) {
  const nb::BedLayout layout = nb::BedLayout::fromUrdf(generate(""));
  EXPECT_EQ(layout.rows(), 20);
  EXPECT_EQ(layout.cols(), 9);
  EXPECT_NEAR(layout.pitchM(), 0.1, 1e-12);
  ASSERT_EQ(layout.cells().size(), 180u);
  const nb::CellLayout* head_right = layout.find(0, 0);
  const nb::CellLayout* foot_left = layout.findId(179);
  ASSERT_NE(head_right, nullptr);
  ASSERT_NE(foot_left, nullptr);
  EXPECT_EQ(foot_left->joint_name, "airbag_19_8_joint");
  EXPECT_NEAR(head_right->x_m, 0.95, 1e-9);
  EXPECT_NEAR(head_right->y_m, -0.4, 1e-9);
  EXPECT_NEAR(foot_left->x_m, -0.95, 1e-9);
  EXPECT_NEAR(foot_left->y_m, 0.4, 1e-9);
  EXPECT_NEAR(layout.find(10, 4)->y_m, 0.0, 1e-9);
  EXPECT_DOUBLE_EQ(foot_left->max_height_m, 0.15);
  EXPECT_TRUE(contains(layout.describe(), "20 x 9")) << layout.describe();
}

TEST(MakeBedUrdf, OutputStaysAStringForRosparamSet) {
  // `rosparam set robot_description "$(make_bed_urdf.py)"` parses the value as YAML.
  const std::string urdf = generate("");
  EXPECT_FALSE(contains(urdf, ": "));
  EXPECT_FALSE(contains(urdf, " #"));
  EXPECT_FALSE(contains(urdf.substr(urdf.find("<!--") + 4, urdf.find("-->") - urdf.find("<!--") - 4), "--"))
      << "XML comments may not hold a double dash";
}

TEST(BedLayout, CommittedUrdfIsTheGeneratedDefault) {
  std::ifstream file(NURSING_BED_SOURCE_DIR "/urdf/nursing_bed.urdf");
  ASSERT_TRUE(file.good()) << "urdf/nursing_bed.urdf missing";
  std::stringstream committed;
  committed << file.rdbuf();
  EXPECT_EQ(committed.str(), generate("")) << "regenerate it: scripts/make_bed_urdf.py --out urdf/nursing_bed.urdf";
}

TEST(BedLayout, SingleCellTakesPitchFromBedBox) {
  const nb::BedLayout layout = nb::BedLayout::fromUrdf(generate("--rows 1 --cols 1 --pitch 0.2"));
  EXPECT_EQ(layout.rows(), 1);
  EXPECT_EQ(layout.cols(), 1);
  EXPECT_NEAR(layout.pitchM(), 0.2, 1e-12);
  EXPECT_NEAR(layout.cells().at(0).x_m, 0.0, 1e-12);
}

TEST(BedLayout, SingleRowTakesPitchFromCols) {
  const nb::BedLayout layout = nb::BedLayout::fromUrdf(generate("--rows 1 --cols 4 --pitch 0.07"));
  EXPECT_NEAR(layout.pitchM(), 0.07, 1e-12);
  EXPECT_EQ(layout.findId(3)->col, 3);
}

TEST(BedLayout, HandWrittenGridIsAccepted) {
  // The helpers below make valid URDF, so each error case differs from it in one thing only.
  const std::string xml = robotXml(cellXml(0, 0, 0.05, -0.05) + cellXml(0, 1, 0.05, 0.05) +
                                   cellXml(1, 0, -0.05, -0.05) + cellXml(1, 1, -0.05, 0.05));
  EXPECT_EQ(layoutError(xml), "");
}

TEST(BedLayoutErrors, XmlDoesNotParse) {
  const std::string error = layoutError("<robot name=\"nursing_bed\"><link name=\"bed_link\">");
  EXPECT_TRUE(contains(error, "does not parse")) << error;
  EXPECT_TRUE(contains(layoutError(""), "does not parse"));
}

TEST(BedLayoutErrors, NoBedLink) {
  const std::string error = layoutError(robotXml("", "base_link"));
  EXPECT_TRUE(contains(error, "no link 'bed_link'")) << error;
}

TEST(BedLayoutErrors, NoCellJoints) {
  const std::string error = layoutError(
      robotXml("<joint name=\"other_joint\" type=\"fixed\"><parent link=\"bed_link\"/><child link=\"x\"/></joint>"
               "<link name=\"x\"/>"));
  EXPECT_TRUE(contains(error, "no airbag_<row>_<col>_joint")) << error;
}

TEST(BedLayoutErrors, OnlyCanonicalCellJointNamesAreCellsWhateverTheirLength) {
  // Near misses and a 40 000-digit index are other joints (left alone), read without recursion.
  std::string others;
  int n = 0;
  for (const std::string& name :
       {std::string("airbag_01_0_joint"), std::string("airbag_0_00_joint"), std::string("airbag_1234567_0_joint"),
        std::string("airbag__0_joint"), std::string("airbag_0_0_joint_"), std::string("airbag_0_0"),
        std::string("airbag_\xc3\xa9_0_joint"), "airbag_" + std::string(40000, '7') + "_0_joint",
        "airbag_0_" + std::string(40000, '1') + "_joint"}) {
    const std::string link = "other_" + std::to_string(n++);
    others += "<joint name=\"" + name + "\" type=\"fixed\"><parent link=\"bed_link\"/><child link=\"" + link +
              "\"/></joint><link name=\"" + link + "\"/>";
  }
  EXPECT_TRUE(contains(layoutError(robotXml(others)), "no airbag_<row>_<col>_joint"));
  const nb::BedLayout layout =
      nb::BedLayout::fromUrdf(robotXml(cellXml(0, 0, 0.0, -0.05) + cellXml(0, 1, 0.0, 0.05) + others));
  EXPECT_EQ(layout.cells().size(), 2u);
}

TEST(BedLayoutErrors, CellJointNotPrismatic) {
  const std::string error = layoutError(robotXml(cellXml(0, 0, 0.0, 0.0, "revolute")));
  EXPECT_TRUE(contains(error, "airbag_0_0_joint is revolute, expected prismatic")) << error;
  const std::string fixed = layoutError(robotXml(cellXml(0, 0, 0.0, 0.0, "fixed", "")));
  EXPECT_TRUE(contains(fixed, "airbag_0_0_joint is fixed")) << fixed;
}

TEST(BedLayoutErrors, CellJointWithoutLimits) {
  // urdfdom itself refuses a prismatic joint without limits; its reason is passed on.
  const std::string error = layoutError(robotXml(cellXml(0, 0, 0.0, 0.0, "prismatic", "")));
  EXPECT_TRUE(contains(error, "does not parse")) << error;
  EXPECT_TRUE(contains(error, "airbag_0_0_joint")) << error;
  EXPECT_TRUE(contains(error, "limits")) << error;
  // Limits without upper and lower parse as 0..0: no travel.
  const std::string empty =
      layoutError(robotXml(cellXml(0, 0, 0.0, 0.0, "prismatic", "<limit effort=\"1\" velocity=\"1\"/>")));
  EXPECT_TRUE(contains(empty, "airbag_0_0_joint has no travel")) << empty;
}

TEST(BedLayoutErrors, CellJointNotAlongZOrNotOnBedLink) {
  const std::string axis = layoutError(robotXml(
      cellXml(0, 0, 0.0, 0.0, "prismatic", "<limit lower=\"0\" upper=\"0.1\" effort=\"1\" velocity=\"1\"/>", "1 0 0")));
  EXPECT_TRUE(contains(axis, "airbag_0_0_joint moves along")) << axis;
  const std::string parent = layoutError(
      robotXml("<link name=\"frame\"/><joint name=\"frame_joint\" type=\"fixed\"><parent link=\"bed_link\"/>"
               "<child link=\"frame\"/></joint>" +
               cellXml(0, 0, 0.0, 0.0, "prismatic", "<limit lower=\"0\" upper=\"0.1\" effort=\"1\" velocity=\"1\"/>",
                       "0 0 1", "frame")));
  EXPECT_TRUE(contains(parent, "airbag_0_0_joint has parent frame")) << parent;
}

TEST(BedLayoutErrors, MissingCellIsNamed) {
  const std::string error =
      layoutError(robotXml(cellXml(0, 0, 0.05, -0.05) + cellXml(0, 1, 0.05, 0.05) + cellXml(1, 1, -0.05, 0.05)));
  EXPECT_TRUE(contains(error, "2 x 2 grid")) << error;
  EXPECT_TRUE(contains(error, "airbag_1_0_joint) is missing")) << error;
}

TEST(BedLayoutErrors, PitchNotUniform) {
  const std::string error =
      layoutError(robotXml(cellXml(0, 0, 0.1, 0.0) + cellXml(1, 0, 0.0, 0.0) + cellXml(2, 0, -0.12, 0.0)));
  EXPECT_TRUE(contains(error, "pitch is not uniform")) << error;
  EXPECT_TRUE(contains(error, "airbag_2_0_joint")) << error;
  // Pitch across differing from pitch along is not uniform either.
  const std::string across = layoutError(robotXml(cellXml(0, 0, 0.05, -0.06) + cellXml(0, 1, 0.05, 0.06) +
                                                  cellXml(1, 0, -0.05, -0.06) + cellXml(1, 1, -0.05, 0.06)));
  EXPECT_TRUE(contains(across, "pitch is not uniform")) << across;
}

TEST(BedLayoutErrors, RowsMustRunFromTheHead) {
  const std::string error = layoutError(robotXml(cellXml(0, 0, -0.05, 0.0) + cellXml(1, 0, 0.05, 0.0)));
  EXPECT_TRUE(contains(error, "pitch is not positive")) << error;
}

TEST(MakeBedUrdf, RefusesBadArguments) {
  const std::string out = "/tmp/nursing_bed_test_bad_args_" + std::to_string(getpid()) + ".urdf";
  const struct {
    const char* args;
    const char* named;
  } cases[] = {
      {"--rows x", "--rows"},
      {"--rows 2.5", "--rows"},
      {"--rows 0", "--rows"},
      {"--rows 101", "--rows"},
      {"--cols -1", "--cols"},
      {"--cols 101", "--cols"},
      {"--pitch 0", "--pitch"},
      {"--pitch -0.1", "--pitch"},
      {"--pitch nan", "--pitch"},
      {"--pitch inf", "--pitch"},
      {"--pitch 1.5", "--pitch"},
      {"--pitch abc", "--pitch"},
      {"--max-height 0", "--max-height"},
      {"--max-height inf", "--max-height"},
      {"--max-height -0.1", "--max-height"},
  };
  for (const auto& c : cases) {
    std::remove(out.c_str());
    // stderr into the pipe, stdout away: the message must be on stderr.
    const RunResult r = run(kScript + " " + c.args + " --out " + out + " 2>&1 >/dev/null");
    EXPECT_EQ(r.exit_code, 2) << c.args;
    EXPECT_TRUE(contains(r.output, c.named)) << c.args << ": " << r.output;
    EXPECT_NE(access(out.c_str(), F_OK), 0) << c.args << ": wrote " << out;
  }
  // Nothing on stdout either.
  const RunResult r = run(kScript + " --rows 0 2>/dev/null");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.output, "");
}

TEST(MakeBedUrdf, WritesOutFile) {
  const std::string out = "/tmp/nursing_bed_test_out_" + std::to_string(getpid()) + ".urdf";
  const RunResult r = run(kScript + " --rows 2 --cols 2 --out " + out);
  EXPECT_EQ(r.exit_code, 0);
  EXPECT_EQ(r.output, "");
  std::ifstream file(out);
  std::stringstream text;
  text << file.rdbuf();
  std::remove(out.c_str());
  EXPECT_EQ(nb::BedLayout::fromUrdf(text.str()).cells().size(), 4u);
  EXPECT_TRUE(contains(text.str(), "Generated by scripts/make_bed_urdf.py"));
}

}  // namespace
