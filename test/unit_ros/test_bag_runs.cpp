// Runs read from ROS bags (no master: bags are written and read with rosbag directly).
#include <gtest/gtest.h>
#include <rosbag/bag.h>
#include <std_msgs/Float64.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

#include "nursing_bed/AirbagState.h"
#include "nursing_bed/ros/bag_runs.h"

#include "../test_helpers.h"

namespace nb = nursing_bed;
namespace fs = std::filesystem;

namespace {

// A scratch directory for this process, removed at exit.
const fs::path& scratchDir() {
  struct Scratch {
    fs::path dir = fs::temp_directory_path() / ("nursing_bed_bag_runs_" + std::to_string(::getpid()));
    Scratch() { fs::create_directories(dir); }
    ~Scratch() {
      std::error_code ec;
      fs::remove_all(dir, ec);
    }
  };
  static const Scratch scratch;
  return scratch.dir;
}

fs::path tmpBag(const std::string& name) {
  const fs::path& dir = scratchDir();
  const fs::path p = dir / name;
  fs::remove(p);
  return p;
}

nursing_bed::AirbagState state(double stamp_s, double p, double h, double q, double load, double inlet, double vent) {
  nursing_bed::AirbagState s;
  s.header.stamp = ros::Time(stamp_s);
  s.gauge_pressure_pa = p;
  s.height_m = h;
  s.inflow_kg_s = q;
  s.external_load_n = load;
  s.inlet_valve_cmd = inlet;
  s.vent_valve_cmd = vent;
  s.gas_temperature_k = 293.15 + p * 1e-4;
  return s;
}

std::string readError(const fs::path& bag) {
  try {
    nb::readRunsFromBag(bag.string());
  } catch (const std::runtime_error& e) {
    return e.what();
  }
  return "";
}

using nursing_bed::test::expectContains;

TEST(BagRuns, OneRunPerAirbagStateTopic) {
  const fs::path path = tmpBag("rig1.bag");
  {
    rosbag::Bag bag(path.string(), rosbag::bagmode::Write);
    for (int i = 0; i < 5; ++i) {
      const double t = 100.0 + 0.1 * i;
      bag.write("/bed/cell_1/state", ros::Time(t + 0.01), state(t, 1000.0 * i, 0.01 * i, 1e-4, 10.6, 1.0, 0.0));
      if (i < 3)
        bag.write("/bed/cell_0/state", ros::Time(t + 0.02), state(t + 0.05, 50.0 * i, 0.02, -1e-5, 0.6, 0.0, 1.0));
      std_msgs::Float64 other;
      other.data = i;
      bag.write("/other", ros::Time(t), other);
    }
  }
  const std::vector<nb::RunData> runs = nb::readRunsFromBag(path.string());
  ASSERT_EQ(runs.size(), 2u);
  const nb::RunData& c0 = runs[0];
  const nb::RunData& c1 = runs[1];
  EXPECT_EQ(c0.name, "rig1/bed/cell_0/state");
  EXPECT_EQ(c1.name, "rig1/bed/cell_1/state");
  EXPECT_EQ(c1.source, path.string());
  EXPECT_EQ(c1.meta.at("topic"), "/bed/cell_1/state");
  ASSERT_EQ(c1.size(), 5u);
  ASSERT_EQ(c0.size(), 3u);
  EXPECT_EQ(c1.t_s[0], 0.0);  // relative to the topic's first stamp
  EXPECT_NEAR(c1.t_s[4], 0.4, 1e-9);
  EXPECT_NEAR(c0.t_s[2], 0.2, 1e-9);
  EXPECT_EQ(c1.p_gauge_pa[3], 3000.0);
  EXPECT_EQ(c1.h_m[2], 0.02);
  EXPECT_EQ(c1.mdot_in_kg_s[0], 1e-4);
  EXPECT_EQ(c1.load_n, 10.6);
  EXPECT_EQ(c1.load_n_series.size(), 5u);
  EXPECT_EQ(c1.valve_cmd[0], 1.0);
  EXPECT_EQ(c0.valve_cmd[0], -1.0);  // the vent's opening while it is open
  EXPECT_EQ(c0.load_n, 0.6);
  EXPECT_NEAR(c1.t_gas_k[1], 293.25, 1e-9);
  EXPECT_TRUE(c1.p_supply_gauge_pa.empty());
}

TEST(BagRuns, UnstampedMessagesUseTheRecordTime) {
  const fs::path path = tmpBag("unstamped.bag");
  {
    rosbag::Bag bag(path.string(), rosbag::bagmode::Write);
    for (int i = 0; i < 3; ++i)
      bag.write("/cell/state", ros::Time(50.0 + 0.5 * i), state(0.0, 1.0, 0.0, 0.0, 1.0, 0, 0));
  }
  const std::vector<nb::RunData> runs = nb::readRunsFromBag(path.string());
  ASSERT_EQ(runs.size(), 1u);
  EXPECT_NEAR(runs[0].t_s[2], 1.0, 1e-9);
}

TEST(BagRuns, ErrorsNameTheBagAndTopic) {
  expectContains(readError("/nonexistent/dir/x.bag"), {"/nonexistent/dir/x.bag", "cannot open"});

  const fs::path not_a_bag = tmpBag("garbage.bag");
  {
    std::ofstream f(not_a_bag);
    f << "this is not a bag";
  }
  expectContains(readError(not_a_bag), {"garbage.bag", "cannot open"});

  const fs::path no_state = tmpBag("no_state.bag");
  {
    rosbag::Bag bag(no_state.string(), rosbag::bagmode::Write);
    std_msgs::Float64 m;
    bag.write("/pressure", ros::Time(1.0), m);
    bag.write("/pressure", ros::Time(2.0), m);
  }
  expectContains(readError(no_state), {"no_state.bag", "no nursing_bed/AirbagState topic"});

  const fs::path short_topic = tmpBag("short.bag");
  {
    rosbag::Bag bag(short_topic.string(), rosbag::bagmode::Write);
    bag.write("/a/state", ros::Time(1.0), state(1.0, 0, 0, 0, 1, 0, 0));
    bag.write("/a/state", ros::Time(2.0), state(2.0, 0, 0, 0, 1, 0, 0));
    bag.write("/b/state", ros::Time(1.5), state(1.5, 0, 0, 0, 1, 0, 0));
  }
  expectContains(readError(short_topic), {"short.bag", "topic /b/state", "1 message(s)", "at least 2"});

  const fs::path backwards = tmpBag("backwards.bag");
  {
    rosbag::Bag bag(backwards.string(), rosbag::bagmode::Write);
    bag.write("/a/state", ros::Time(1.0), state(10.0, 0, 0, 0, 1, 0, 0));
    bag.write("/a/state", ros::Time(2.0), state(10.5, 0, 0, 0, 1, 0, 0));
    bag.write("/a/state", ros::Time(3.0), state(10.4, 0, 0, 0, 1, 0, 0));
  }
  expectContains(readError(backwards),
                 {"backwards.bag", "topic /a/state", "time not strictly increasing", "message 2"});
}

TEST(BagRuns, ARepeatedStateIsSkipped) {
  // A late cell repeats its last state with the same stamp (doc/safety.md): read once.
  const fs::path path = tmpBag("repeat.bag");
  {
    rosbag::Bag bag(path.string(), rosbag::bagmode::Write);
    bag.write("/a/state", ros::Time(1.0), state(10.0, 0, 0, 0, 1, 0, 0));
    bag.write("/a/state", ros::Time(2.0), state(10.5, 0, 0, 0, 1, 0, 0));
    bag.write("/a/state", ros::Time(3.0), state(10.5, 0, 0, 0, 1, 0, 0));
    bag.write("/a/state", ros::Time(4.0), state(11.0, 0, 0, 0, 1, 0, 0));
  }
  const std::vector<nb::RunData> runs = nb::readRunsFromBag(path.string());
  ASSERT_EQ(runs.size(), 1u);
  EXPECT_EQ(runs[0].t_s, (std::vector<double>{0.0, 0.5, 1.0}));
}

}  // namespace
