// rostest node for the bed manager's posture plans and safety watch, against a small bed.
#include <diagnostic_msgs/DiagnosticArray.h>
#include <nodelet/NodeletUnload.h>
#include <std_msgs/Float64.h>

#include <cmath>

#include "bed_fixture.h"

namespace nursing_bed {
namespace test {

// Alternating: watched on the real cells for two periods; the period comes from ~period_s.
TEST_F(PlanFixture, AlternatingNeverLowersTwoAdjacentRowsAndKeepsItsPeriod) {
  ros::NodeHandle pnh("~");
  std::string pattern;
  double period = 0.0;
  pnh.param<std::string>("pattern", pattern, "1in2");
  pnh.param("period_s", period, 20.0);
  const double low = 0.03, high = 0.12, mid = 0.5 * (low + high);
  ASSERT_TRUE(posture("flat", {"height_m"}, {"0.12"}).success);  // a supported patient first
  ASSERT_TRUE(settle(uniform(0.12), 2e-3, 0.3, 20.0));
  ASSERT_TRUE(
      posture("alternating", {"pattern", "period_s", "static_head_rows"}, {pattern, std::to_string(period), "1"})
          .success);
  const int watched_row = 2;  // a cycling row (row 0 is the static head row)
  std::vector<double> went_low;
  bool was_low = false;
  int adjacent_violations = 0;
  const ros::WallTime start = ros::WallTime::now();
  waitFor(
      [&] {
        for (int r = 1; r < rows_; ++r)
          for (int c = 0; c < cols_; ++c) {
            const double a = states_[r * cols_ + c].height_m, b = states_[(r - 1) * cols_ + c].height_m;
            if (a < mid && b < mid) ++adjacent_violations;
          }
        const bool low_now = states_[watched_row * cols_].height_m < mid;
        if (low_now && !was_low) went_low.push_back((ros::WallTime::now() - start).toSec());
        was_low = low_now;
        return false;
      },
      2.2 * period + 5.0);
  EXPECT_EQ(adjacent_violations, 0);
  ASSERT_GE(went_low.size(), 2u) << "row " << watched_row << " did not cycle";
  const double measured = went_low.back() - went_low[went_low.size() - 2];
  EXPECT_NEAR(measured, period, 0.05 * period);
  EXPECT_EQ(bed_.plan, "alternating");
}

TEST_F(PlanFixture, CprBringsEveryCellBelow10mmWithin10s) {
  ASSERT_TRUE(posture("flat", {"height_m"}, {"0.12"}).success);
  ASSERT_TRUE(settle(uniform(0.12), 2e-3, 0.3, 20.0));
  const ros::WallTime start = ros::WallTime::now();
  ASSERT_TRUE(posture("cpr").success);
  const bool down = waitFor(
      [&] {
        for (const auto& s : states_)
          if (s.second.height_m >= 0.010) return false;
        return true;
      },
      10.0);
  const double seconds = (ros::WallTime::now() - start).toSec();
  EXPECT_TRUE(down) << "not every cell below 10 mm after 10 s";
  RecordProperty("cpr_seconds", std::to_string(seconds));
  std::printf("CPR: every cell below 10 mm after %.2f s\n", seconds);
}

TEST_F(PlanFixture, MaxInflateRevertsAfterItsTimeout) {
  ASSERT_TRUE(posture("flat", {"height_m"}, {"0.08"}).success);
  ASSERT_TRUE(settle(uniform(0.08), 2e-3, 0.3, 20.0));
  ASSERT_TRUE(posture("max_inflate", {"timeout_s"}, {"6"}).success);
  EXPECT_TRUE(settle(uniform(0.15), 3e-3, 0.3, 6.0)) << "max_inflate did not lift the cells";
  EXPECT_TRUE(waitFor([this] { return bed_.plan == "flat"; }, 8.0)) << "still " << bed_.plan;
  EXPECT_TRUE(settle(uniform(0.08), 2e-3, 0.3, 15.0));
}

TEST_F(PlanFixture, BadPostureRequestsAreRefusedAndChangeNothing) {
  ASSERT_TRUE(posture("flat").success);
  ASSERT_TRUE(waitFor([this] { return bed_.plan == "flat"; }, 5.0));
  struct Case {
    std::string plan;
    std::vector<std::string> keys, values;
    std::string fragment;
  };
  const Case cases[] = {
      {"sit_up", {}, {}, "unknown plan"},
      {"lateral_turn", {"side", "angle_deg"}, {"left", "45"}, "outside [0, 40]"},
      {"lateral_turn", {"side", "angle_deg"}, {"left", "35"}, "configured maximum"},
      {"lateral_turn", {"side", "angle_deg", "ramp_s"}, {"left", "20", "2"}, "faster than"},
      {"lateral_turn", {"side", "angle_deg"}, {"left", "nan"}, "finite"},
      {"alternating", {"pattern"}, {"1in5"}, "pattern"},
      {"flat", {"height_m"}, {"0.4"}, "outside"},
      {"flat", {"height_m"}, {"0.1", "0.2"}, "values"},
      {"custom", {}, {}, "heights"},
  };
  for (const Case& c : cases) {
    const SetPosture::Response res = posture(c.plan, c.keys, c.values);
    EXPECT_FALSE(res.success) << c.plan;
    EXPECT_NE(res.message.find(c.fragment), std::string::npos) << c.plan << ": " << res.message;
  }
  waitFor([] { return false; }, 0.5);
  EXPECT_EQ(bed_.plan, "flat");
  EXPECT_EQ(bed_.parameters, "height_m=0.1");
}

TEST_F(PlanFixture, ADeadCellIsReportedWithin1sAndTheBedStaysLevel) {
  ASSERT_TRUE(posture("flat", {"height_m"}, {"0.09"}).success);
  ASSERT_TRUE(settle(uniform(0.09), 2e-3, 0.3, 20.0));
  diagnostic_msgs::DiagnosticArray diag;
  const boost::function<void(const diagnostic_msgs::DiagnosticArray::ConstPtr&)> on_diag =
      [&diag](const diagnostic_msgs::DiagnosticArray::ConstPtr& m) { diag = *m; };
  ros::Subscriber sub = nh_.subscribe<diagnostic_msgs::DiagnosticArray>("/diagnostics", 10, on_diag);
  nodelet::NodeletUnload unload;
  unload.request.name = "/airbag_1_1";
  ASSERT_TRUE(ros::service::call("/airbag_manager/unload_nodelet", unload));
  ASSERT_TRUE(unload.response.success);
  const ros::WallTime killed = ros::WallTime::now();
  const bool reported = waitFor(
      [&] {
        for (const auto& s : diag.status)
          if (s.name == "bed/airbag_1_1" && s.level == diagnostic_msgs::DiagnosticStatus::ERROR) return true;
        return false;
      },
      3.0);
  const double seconds = (ros::WallTime::now() - killed).toSec();
  EXPECT_TRUE(reported);
  EXPECT_LE(seconds, 1.0);
  std::printf("dead cell on /diagnostics after %.2f s\n", seconds);
  // The bed goes to its safe configuration: every target the same (the dead cell's height).
  EXPECT_TRUE(waitFor([this] { return bed_.plan == "safe_level"; }, 2.0)) << bed_.plan;
  ASSERT_FALSE(bed_.target_heights_m.empty());
  for (double h : bed_.target_heights_m) EXPECT_NEAR(h, bed_.target_heights_m[0], 1e-9);
  EXPECT_NEAR(bed_.target_heights_m[0], 0.09, 2e-3);
  EXPECT_EQ(bed_.dead_cells, std::vector<uint32_t>{static_cast<uint32_t>(1 * cols_ + 1)});
}

TEST_F(PlanFixture, LateralTurnRollsTheBodyByTheRequestedAngle) {
  double roll_rad = NAN;
  const boost::function<void(const std_msgs::Float64::ConstPtr&)> on_roll =
      [&roll_rad](const std_msgs::Float64::ConstPtr& m) { roll_rad = m->data; };
  ros::Subscriber sub = nh_.subscribe<std_msgs::Float64>("/simulator/body_roll", 5, on_roll);
  ASSERT_TRUE(posture("flat").success);
  ASSERT_TRUE(waitFor([&] { return std::isfinite(roll_rad); }, 15.0)) << "no body roll from the simulator";
  waitFor([] { return false; }, 5.0);  // the body settles on the flat bed
  EXPECT_NEAR(roll_rad, 0.0, 1.0 * M_PI / 180.0);
  // The plan ramps at 1 deg/s; the bed's own slope follows at plans/bed_tilt_rate_fraction of
  // that (0.5: 40 s for 20 deg, doc/safety.md).
  ASSERT_TRUE(posture("lateral_turn", {"side", "angle_deg", "ramp_s", "dwell_s"}, {"left", "20", "20", "120"}).success);
  waitFor([] { return false; }, 45.0);
  EXPECT_EQ(bed_.phase, "dwell");
  // A left turn lowers the patient's left side; the body model's roll is + when the right side
  // goes down, so the left turn shows as a negative roll.
  EXPECT_NEAR(-roll_rad * 180.0 / M_PI, 20.0, 2.0);
  std::printf("lateral turn left 20 deg: body roll %.2f deg\n", -roll_rad * 180.0 / M_PI);
}

}  // namespace test
}  // namespace nursing_bed
