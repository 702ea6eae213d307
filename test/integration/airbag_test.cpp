// rostest node for the airbag nodes and the bed manager. Each .test file runs one of these
// cases (--gtest_filter) against a small bed from bed_under_test.launch.
#include <cmath>
#include <iterator>
#include <limits>

#include <diagnostic_msgs/DiagnosticArray.h>

#include "bed_fixture.h"
#include "nursing_bed/BedHeights.h"
#include "nursing_bed/ros/names.h"

namespace nursing_bed {
namespace test {

TEST_F(BedFixture, OneCellReachesItsHeightUnder15N) {
  const SetHeight::Response res = callCell("/airbag_0_1", 1, 0.10);
  ASSERT_TRUE(res.success) << res.message;
  EXPECT_TRUE(settle({{1, 0.10}}, 1e-3, 0.5, 15.0)) << "cell 1 at " << states_[1].height_m;
  EXPECT_NEAR(states_[1].external_load_n, 15.6, 1e-9);
  EXPECT_NEAR(states_[1].height_setpoint_m, 0.10, 1e-12);
}

TEST_F(BedFixture, ManyCellsAtOnceThroughTheBedManager) {
  std::vector<uint32_t> ids;
  std::vector<double> heights;
  std::map<uint32_t, double> targets;
  for (uint32_t id = 0; id < static_cast<uint32_t>(rows_ * cols_); ++id) {
    ids.push_back(id);
    heights.push_back(0.04 + 0.015 * id);
    targets[id] = heights.back();
  }
  const SetHeights::Response res = callBed(ids, heights);
  ASSERT_TRUE(res.success) << res.message;
  EXPECT_TRUE(settle(targets, 1e-3, 0.5, 20.0));
}

TEST_F(BedFixture, BadRequestsAreRefusedWithAMessageAndChangeNothing) {
  ASSERT_TRUE(callCell("/airbag_0_0", 0, 0.06).success);
  ASSERT_TRUE(settle({{0, 0.06}}, 1e-3, 0.2, 15.0));
  struct Case {
    const char* what;
    std::vector<uint32_t> ids;
    std::vector<double> heights;
    const char* fragment;
  };
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const Case cases[] = {
      {"above the range", {0}, {0.5}, "outside"},
      {"below the range", {0}, {-0.01}, "outside"},
      {"not finite", {0}, {nan}, "finite"},
      {"infinite", {0}, {std::numeric_limits<double>::infinity()}, "finite"},
      {"unknown cell", {999}, {0.05}, "does not exist"},
      {"twice the same cell", {0, 0}, {0.05, 0.07}, "twice"},
      {"lengths differ", {0, 1}, {0.05}, "heights"},
      {"nothing", {}, {}, "no cells"},
      {"one bad among good", {1, 2, 0}, {0.05, 0.05, 0.9}, "outside"},
  };
  for (const Case& c : cases) {
    const SetHeights::Response res = callBed(c.ids, c.heights);
    EXPECT_FALSE(res.success) << c.what;
    EXPECT_NE(res.message.find(c.fragment), std::string::npos) << c.what << ": " << res.message;
  }
  // Straight to a cell: bad values, and a cell id the node does not serve.
  for (double bad : {0.5, -0.01, nan}) {
    const SetHeight::Response res = callCell("/airbag_0_0", 0, bad);
    EXPECT_FALSE(res.success);
    EXPECT_FALSE(res.message.empty());
  }
  const SetHeight::Response wrong = callCell("/airbag_0_0", 4, 0.05);
  EXPECT_FALSE(wrong.success);
  EXPECT_NE(wrong.message.find("not served here"), std::string::npos) << wrong.message;
  // Nothing changed: every cell keeps its setpoint (cell 0 at 6 cm, the others none).
  ros::WallDuration(0.5).sleep();
  ros::spinOnce();
  EXPECT_NEAR(states_[0].height_setpoint_m, 0.06, 1e-12);
  EXPECT_NEAR(states_[0].height_m, 0.06, 1e-3);
  for (uint32_t id = 1; id < static_cast<uint32_t>(rows_ * cols_); ++id)
    EXPECT_TRUE(std::isnan(states_[id].height_setpoint_m)) << "cell " << id;
}

TEST_F(BedFixture, ReliefPressureHoldsWithTheSupplyAboveIt) {
  // The launch sets the supply to 45 kPa and the relief to 30 kPa; the load needs more than
  // the relief for the top height.
  ASSERT_TRUE(callCell("/airbag_0_0", 0, 0.15).success);
  double p_max = 0.0;
  bool flagged = false;
  waitFor(
      [&] {
        p_max = std::max(p_max, states_[0].gauge_pressure_pa);
        flagged |= (states_[0].faults & AirbagState::FAULT_OVERPRESSURE) != 0;
        return false;
      },
      8.0);
  EXPECT_LE(p_max, 30000.0);
  EXPECT_GT(p_max, 25000.0) << "the cell never pressed against the limit";
}

TEST_F(BedFixture, EveryCellPublishesAtItsRate) {
  counts_.clear();
  const ros::WallTime start = ros::WallTime::now();
  waitFor([] { return false; }, 5.0);
  const double seconds = (ros::WallTime::now() - start).toSec();
  for (uint32_t id = 0; id < static_cast<uint32_t>(rows_ * cols_); ++id)
    EXPECT_GE(counts_[id] / seconds, 45.0) << "cell " << id;
}

TEST_F(BedFixture, TheBedsHeightsCarryEachCellsOwnStamp) {
  // Every state each cell publishes, by stamp; and ~heights while the cells move.
  std::map<uint32_t, std::map<ros::Time, double>> published;
  std::vector<ros::Subscriber> cell_subs;
  for (uint32_t id = 0; id < static_cast<uint32_t>(rows_ * cols_); ++id) {
    const boost::function<void(const AirbagState::ConstPtr&)> on_state = [&published](const AirbagState::ConstPtr& m) {
      published[m->cell_id][m->header.stamp] = m->height_m;
    };
    const std::string cell = "/" + names::airbagName(static_cast<int>(id) / cols_, static_cast<int>(id) % cols_);
    cell_subs.push_back(nh_.subscribe<AirbagState>(cell + "/" + names::kState, 50, on_state));
  }
  std::vector<BedHeights> heights;
  const boost::function<void(const BedHeights::ConstPtr&)> on_heights = [&heights](const BedHeights::ConstPtr& m) {
    heights.push_back(*m);
  };
  ros::Subscriber sub = nh_.subscribe<BedHeights>("/bed_manager/heights", 50, on_heights);
  ASSERT_TRUE(
      waitFor([&] { return published.size() == static_cast<std::size_t>(rows_ * cols_) && !heights.empty(); }, 10.0));
  std::vector<uint32_t> ids;
  for (uint32_t id = 0; id < static_cast<uint32_t>(rows_ * cols_); ++id) ids.push_back(id);
  ASSERT_TRUE(callBed(ids, std::vector<double>(ids.size(), 0.08)).success);
  heights.clear();
  waitFor([] { return false; }, 2.0);
  sub.shutdown();
  waitFor([] { return false; }, 0.5);  // the states those messages carried have arrived here too
  ASSERT_GE(heights.size(), 30u);      // ~joint_state_rate_hz 30 Hz for 2 s
  int moving = 0;
  for (const BedHeights& h : heights) {
    ASSERT_EQ(h.stamps.size(), ids.size());
    ASSERT_EQ(h.height_m.size(), ids.size());
    ASSERT_EQ(h.height_sd_m.size(), ids.size());
    ASSERT_EQ(h.height_source.size(), ids.size());
    for (uint32_t id : ids) {
      // A simulated cell steps whole periods of its clock: its state may describe a moment up to
      // one update period (~update_rate_hz, 50 Hz here) past the wall clock that publishes it.
      EXPECT_LE((h.stamps[id] - h.header.stamp).toSec(), 0.02) << "cell " << id;
      const auto state = published[id].find(h.stamps[id]);
      ASSERT_NE(state, published[id].end()) << "cell " << id << ": no state stamped " << h.stamps[id];
      EXPECT_EQ(h.height_m[id], state->second) << "cell " << id;
      EXPECT_EQ(h.height_source[id], AirbagState::HEIGHT_MEASURED) << "cell " << id;
      if (state != published[id].begin() && std::prev(state)->second != state->second) ++moving;
    }
  }
  EXPECT_GT(moving, 0) << "the cells did not move: the heights' stamps were not put to the test";
}

TEST_F(BedFixture, DiagnosticsReportEveryCell) {
  diagnostic_msgs::DiagnosticArray last;
  const boost::function<void(const diagnostic_msgs::DiagnosticArray::ConstPtr&)> on_diag =
      [&last](const diagnostic_msgs::DiagnosticArray::ConstPtr& m) { last = *m; };
  ros::Subscriber sub = nh_.subscribe<diagnostic_msgs::DiagnosticArray>("/diagnostics", 5, on_diag);
  ASSERT_TRUE(waitFor([&] { return !last.status.empty(); }, 10.0));
  ASSERT_EQ(last.status.size(), static_cast<std::size_t>(rows_ * cols_ + 1));
  EXPECT_EQ(last.status[0].name, "bed");
  for (const auto& s : last.status)
    EXPECT_EQ(s.level, diagnostic_msgs::DiagnosticStatus::OK) << s.name << ": " << s.message;
  EXPECT_EQ(last.status[2].name, "bed/airbag_0_1");
}

}  // namespace test
}  // namespace nursing_bed
