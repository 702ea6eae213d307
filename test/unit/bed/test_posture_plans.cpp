// Posture plans: what they command over time, and every refusal.
#include <gtest/gtest.h>

#include <cmath>

#include "nursing_bed/core/bed/posture_plans.h"

namespace nb = nursing_bed;

namespace {

const nb::BedGrid kGrid;  // 20 x 9, 100 mm
const nb::PlanConfig kConfig;
const nb::BodyFootprint kBody;

std::unique_ptr<nb::PosturePlan> make(const std::string& plan, std::map<std::string, std::string> args,
                                      std::string* error = nullptr, std::vector<double> heights = {}) {
  nb::PlanRequest r{plan, std::move(args), std::move(heights)};
  std::string e;
  auto p = nb::makePlan(r, kConfig, kGrid, kBody, &e);
  if (error) *error = e;
  return p;
}

void expectRefused(const std::string& plan, std::map<std::string, std::string> args, const std::string& fragment,
                   std::vector<double> heights = {}) {
  std::string error;
  EXPECT_EQ(make(plan, args, &error, heights), nullptr) << plan;
  EXPECT_NE(error.find(fragment), std::string::npos) << plan << ": " << error;
}

TEST(PosturePlans, BadRequestsAreRefusedWithTheReason) {
  expectRefused("sit_up", {}, "unknown plan 'sit_up'");
  expectRefused("flat", {{"hieght_m", "0.1"}}, "does not take 'hieght_m'");
  expectRefused("flat", {{"height_m", "0.5"}}, "outside");
  expectRefused("flat", {{"height_m", "tall"}}, "must be a number");
  expectRefused("flat", {{"height_m", "nan"}}, "finite");
  expectRefused("lateral_turn", {{"angle_deg", "20"}}, "needs side");
  expectRefused("lateral_turn", {{"side", "up"}, {"angle_deg", "20"}}, "side must be one of left|right");
  expectRefused("lateral_turn", {{"side", "left"}}, "needs angle_deg");
  expectRefused("lateral_turn", {{"side", "left"}, {"angle_deg", "35"}}, "exceeds the configured maximum 30");
  expectRefused("lateral_turn", {{"side", "left"}, {"angle_deg", "45"}}, "outside [0, 40]");  // the hard cap
  expectRefused("lateral_turn", {{"side", "left"}, {"angle_deg", "0"}}, "must be positive");
  expectRefused("lateral_turn", {{"side", "left"}, {"angle_deg", "20"}, {"ramp_s", "5"}}, "turns faster than");
  expectRefused("alternating", {}, "needs pattern");
  expectRefused("alternating", {{"pattern", "1in4"}}, "pattern must be one of 1in2|1in3");
  expectRefused("alternating", {{"pattern", "1in2"}, {"low_m", "0.12"}, {"high_m", "0.05"}},
                "low_m must be below high_m");
  expectRefused("alternating", {{"pattern", "1in3"}, {"period_s", "5"}}, "period_s");
  expectRefused("max_inflate", {{"timeout_s", "-1"}}, "outside");
  expectRefused("cpr", {{"now", "yes"}}, "does not take 'now'");
  expectRefused("custom", {}, "needs 180 heights", {0.1, 0.1});
  std::vector<double> bad(180, 0.1);
  bad[17] = 0.3;
  expectRefused("custom", {}, "cell 17", bad);
  expectRefused("flat", {}, "does not take per-cell heights", std::vector<double>(180, 0.1));
}

TEST(PosturePlans, FlatAndMaxInflate) {
  auto flat = make("flat", {});
  ASSERT_TRUE(flat);
  for (double h : flat->targets(5.0).heights_m) EXPECT_EQ(h, kConfig.nominal_height_m);
  auto inflate = make("max_inflate", {{"timeout_s", "30"}});
  ASSERT_TRUE(inflate);
  EXPECT_FALSE(inflate->targets(29.0).finished);
  EXPECT_TRUE(inflate->targets(30.0).finished);
  for (double h : inflate->targets(1.0).heights_m) EXPECT_EQ(h, kConfig.max_height_m);
  auto cpr = make("cpr", {});
  ASSERT_TRUE(cpr);
  EXPECT_TRUE(cpr->targets(0.0).vent_all);
}

TEST(PosturePlans, LateralTurnTiltsTheCellsUnderTheBody) {
  auto turn = make("lateral_turn", {{"side", "left"}, {"angle_deg", "20"}, {"ramp_s", "30"}, {"dwell_s", "60"}});
  ASSERT_TRUE(turn) << "refused";
  const nb::PlanTargets half = turn->targets(15.0), full = turn->targets(40.0);
  EXPECT_EQ(half.phase, "ramp");
  EXPECT_NEAR(half.tilt_deg, 10.0, 1e-9);
  EXPECT_EQ(full.phase, "dwell");
  EXPECT_NEAR(full.tilt_deg, 20.0, 1e-9);
  // Across the body's midline the heights follow the tilt plane, lower on the left (+y).
  const int row = 8;
  const double slope =
      (full.heights_m[kGrid.id(row, 5)] - full.heights_m[kGrid.id(row, 3)]) / (kGrid.y(5) - kGrid.y(3));
  EXPECT_NEAR(slope, -std::tan(20.0 * M_PI / 180.0), 1e-9);
  for (double h : full.heights_m) {
    EXPECT_GE(h, kConfig.min_height_m);
    EXPECT_LE(h, kConfig.max_height_m);
  }
  // Right turn mirrors it; after ramp + dwell + return the bed is flat again.
  auto right = make("lateral_turn", {{"side", "right"}, {"angle_deg", "20"}, {"ramp_s", "30"}, {"dwell_s", "60"}});
  EXPECT_NEAR(right->targets(40.0).tilt_deg, -20.0, 1e-9);
  const nb::PlanTargets done = turn->targets(121.0);
  EXPECT_TRUE(done.finished);
  for (double h : done.heights_m) EXPECT_NEAR(h, kConfig.nominal_height_m, 1e-12);
  // The default ramp respects the tilt-rate limit.
  auto slow = make("lateral_turn", {{"side", "left"}, {"angle_deg", "30"}});
  ASSERT_TRUE(slow);
  EXPECT_LE(slow->targets(1.0).tilt_deg, kConfig.max_tilt_rate_deg_s * 1.0 + 1e-9);
}

TEST(PosturePlans, AlternatingNeverLowersTwoAdjacentRows) {
  for (const std::string pattern : {"1in2", "1in3"}) {
    auto plan = make("alternating", {{"pattern", pattern}, {"period_s", "60"}});
    ASSERT_TRUE(plan) << pattern;
    const int groups = pattern == "1in2" ? 2 : 3;
    std::vector<double> low_time(kGrid.rows, 0.0);
    const double dt = 0.05;
    for (double t = 0.0; t < 120.0; t += dt) {
      const nb::PlanTargets tg = plan->targets(t);
      std::vector<bool> low(kGrid.rows);
      for (int r = 0; r < kGrid.rows; ++r) {
        low[r] = tg.heights_m[kGrid.id(r, 4)] < 0.5 * (kConfig.alternating_low_m + kConfig.alternating_high_m);
        for (int c = 0; c < kGrid.cols; ++c) EXPECT_EQ(tg.heights_m[kGrid.id(r, c)], tg.heights_m[kGrid.id(r, 0)]);
        if (low[r]) low_time[r] += dt;
      }
      for (int r = 1; r < kGrid.rows; ++r) ASSERT_FALSE(low[r] && low[r - 1]) << pattern << " t " << t << " row " << r;
      for (int r = 0; r < kConfig.static_head_rows; ++r) EXPECT_FALSE(low[r]);
    }
    // Every cycling row is low once per period, for one slot minus the transition.
    for (int r = kConfig.static_head_rows; r < kGrid.rows; ++r)
      EXPECT_NEAR(low_time[r], 2.0 * (60.0 / groups - kConfig.alternating_transition_s), 0.2)
          << pattern << " row " << r;
  }
}

TEST(PosturePlans, PlanKindsKeepTheirRequestNames) {
  const std::vector<std::pair<nb::PlanKind, std::string>> names = {{nb::PlanKind::kFlat, "flat"},
                                                                   {nb::PlanKind::kLateralTurn, "lateral_turn"},
                                                                   {nb::PlanKind::kAlternating, "alternating"},
                                                                   {nb::PlanKind::kMaxInflate, "max_inflate"},
                                                                   {nb::PlanKind::kCpr, "cpr"},
                                                                   {nb::PlanKind::kCustom, "custom"},
                                                                   {nb::PlanKind::kSafeLevel, "safe_level"}};
  for (const auto& [kind, name] : names) {
    EXPECT_EQ(nb::planKindName(kind), name);
    EXPECT_EQ(nb::planKindFromName(name), kind) << name;
  }
  EXPECT_FALSE(nb::planKindFromName("Flat"));
  EXPECT_FALSE(nb::planKindFromName(""));
  // Every plan knows its kind; safe_level is the manager's own, not a request.
  EXPECT_EQ(make("flat", {})->kind(), nb::PlanKind::kFlat);
  EXPECT_EQ(make("max_inflate", {})->kind(), nb::PlanKind::kMaxInflate);
  EXPECT_EQ(make("alternating", {{"pattern", "1in2"}})->name(), "alternating");
  EXPECT_EQ(nb::makeSafeLevelPlan(kGrid, 0.1)->kind(), nb::PlanKind::kSafeLevel);
  expectRefused("safe_level", {}, "unknown plan 'safe_level'", {0.1});
}

TEST(PosturePlans, ConfigValidation) {
  nb::PlanConfig c;
  EXPECT_TRUE(c.validate().ok());
  c.max_tilt_deg = 45.0;
  EXPECT_NE(c.validate().message().find("max_tilt_deg"), std::string::npos);
}

}  // namespace

namespace {

TEST(PosturePlans, NumbersAreParsedStrictly) {
  for (const char* bad : {"0x14", "20abc", " 20", "20 ", "1e", "", "+", ".", "0x1p4", "infinity", "1e999"}) {
    double v = -1.0;
    EXPECT_FALSE(nb::parseDecimal(bad, &v)) << "'" << bad << "'";
    EXPECT_EQ(v, -1.0) << bad;
  }
  for (const auto& [text, value] : std::vector<std::pair<const char*, double>>{
           {"20", 20.0}, {"-0.5", -0.5}, {"+1.5e1", 15.0}, {".5", 0.5}, {"5.", 5.0}, {"2E-2", 0.02}}) {
    double v = 0.0;
    EXPECT_TRUE(nb::parseDecimal(text, &v)) << text;
    EXPECT_DOUBLE_EQ(v, value) << text;
  }
  expectRefused("lateral_turn", {{"side", "left"}, {"angle_deg", "0x14"}}, "must be a number");
  expectRefused("flat", {{"height_m", "inf"}}, "finite");
}

TEST(PosturePlans, HugeAndDoublySignedNumbersAreRefusedWithoutHarm) {
  const std::string huge(40000, '9');
  for (const std::string& bad : {huge, "0." + huge, std::string("+-5"), std::string("-+5"), std::string("--5")}) {
    double v = -1.0;
    EXPECT_FALSE(nb::parseDecimal(bad, &v)) << bad.substr(0, 20);
    EXPECT_EQ(v, -1.0);
  }
  expectRefused("flat", {{"height_m", huge}}, "at most 64 characters, got 40000");
}

TEST(PosturePlans, RollSlopeWeightsGiveTheLateralSlopeUnderTheBody) {
  const std::vector<double> w = nb::rollSlopeWeights(kGrid, kBody);
  ASSERT_EQ(w.size(), static_cast<std::size_t>(kGrid.cells()));
  // A plane h = 0.1 + s y under the body (and anything beyond it) gives back s.
  const double s = std::tan(15.0 * M_PI / 180.0);
  double slope = 0.0, flat = 0.0;
  for (int r = 0; r < kGrid.rows; ++r)
    for (int c = 0; c < kGrid.cols; ++c) {
      const double h = r <= kBody.last_row ? 0.1 + s * kGrid.y(c) : 0.3 * c;
      slope += w[kGrid.id(r, c)] * h;
      flat += w[kGrid.id(r, c)] * 0.1;
    }
  EXPECT_NEAR(slope, s, 1e-12);
  EXPECT_NEAR(flat, 0.0, 1e-12);
  // A turn plan's targets: the slope follows the commanded tilt (less where heights are clamped).
  auto turn = make("lateral_turn", {{"side", "left"}, {"angle_deg", "10"}});
  ASSERT_NE(turn, nullptr);
  const nb::PlanTargets t = turn->targets(100.0);  // dwell
  double turned = 0.0;
  for (std::size_t i = 0; i < w.size(); ++i) turned += w[i] * t.heights_m[i];
  EXPECT_NEAR(std::atan(turned) * 180.0 / M_PI, -10.0, 1e-9);  // the columns under the trunk are not clamped
  // Only the columns within the support width count; too narrow a support has no slope.
  const std::vector<double> narrow = nb::rollSlopeWeights(kGrid, kBody, 0.05);
  for (double x : narrow) EXPECT_EQ(x, 0.0);
  int counted = 0;
  for (int c = 0; c < kGrid.cols; ++c) counted += w[kGrid.id(5, c)] != 0.0 || std::fabs(kGrid.y(c)) < 1e-9;
  EXPECT_EQ(counted, 5);  // y = -0.2 .. 0.2 m
}

}  // namespace
