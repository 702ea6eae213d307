// The adaptive plan: where it reads the body from a load map, what it does to the heels, the
// trunk and the pelvis, its relief rotation, its parameters, and how the supervisor runs it.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "nursing_bed/core/bed/adaptive_support.h"
#include "nursing_bed/core/bed/bed_supervisor.h"
#include "nursing_bed/core/bed/body_model.h"
#include "nursing_bed/core/bed/posture_plans.h"
#include "nursing_bed/core/bed/tissue_load.h"
#include "nursing_bed/core/physics/units.h"

namespace nb = nursing_bed;

namespace {

constexpr double kStepS = 0.1;  // the bed manager's plan rate

// The loads [N] the articulated 70 kg, 1.70 m patient puts on a level 20 x 9 bed at 0.10 m,
// rows 0-17 (head first), columns 1-7 (the outer columns carry nothing).
const double kSupineLoads[18][7] = {
    {0.0, 0.0, 0.5, 4.1, 0.5, 0.0, 0.0},    {0.0, 0.0, 4.3, 31.1, 4.3, 0.0, 0.0},
    {0.0, 0.0, 1.1, 8.7, 1.1, 0.0, 0.0},    {0.1, 0.9, 3.7, 12.3, 3.7, 0.9, 0.1},
    {1.0, 5.8, 13.4, 38.2, 13.4, 5.8, 1.0}, {1.2, 7.2, 12.8, 36.1, 12.8, 7.2, 1.2},
    {0.5, 3.6, 17.8, 35.4, 17.8, 3.6, 0.5}, {0.7, 4.4, 11.8, 26.2, 11.8, 4.4, 0.7},
    {0.6, 4.3, 14.9, 35.4, 14.9, 4.3, 0.6}, {0.3, 2.1, 9.0, 8.5, 9.0, 2.1, 0.3},
    {0.4, 3.1, 18.3, 10.7, 18.3, 3.1, 0.4}, {0.0, 0.9, 18.2, 10.7, 18.2, 0.9, 0.0},
    {0.0, 0.2, 8.0, 4.3, 8.0, 0.2, 0.0},    {0.0, 0.1, 6.1, 3.0, 6.1, 0.1, 0.0},
    {0.0, 0.2, 10.7, 5.4, 10.7, 0.2, 0.0},  {0.0, 0.1, 7.1, 3.5, 7.1, 0.1, 0.0},
    {0.0, 0.0, 5.0, 2.3, 5.0, 0.0, 0.0},    {0.0, 0.0, 4.0, 1.8, 4.0, 0.0, 0.0},
};

nb::SensedCells supineSensed(const nb::BedGrid& grid) {
  nb::SensedCells s;
  s.load_n.assign(grid.cells(), 0.0);
  s.gauge_pressure_pa.assign(grid.cells(), NAN);
  for (int r = 0; r < 18; ++r)
    for (int c = 1; c <= 7; ++c) s.load_n[grid.id(r, c)] = kSupineLoads[r][c - 1];
  return s;
}

const nb::PlanConfig kConfig;

nb::AdaptiveSupport support(const nb::AdaptiveSupportParams& p = kConfig.adaptive) {
  return nb::AdaptiveSupport(p, nb::BedGrid{}, kConfig.min_height_m, kConfig.nominal_height_m, kConfig.max_height_m);
}

/// Runs `s` from `from_s` to `to_s` at the plan rate on constant readings; the phases seen, in order.
std::vector<std::string> run(nb::AdaptiveSupport* s, const nb::SensedCells& sensed, double from_s, double to_s) {
  std::vector<std::string> phases;
  std::string phase;
  for (double t = from_s; t <= to_s + 1e-9; t += kStepS) {
    s->update(t, sensed, &phase);
    if (phases.empty() || phases.back() != phase) phases.push_back(phase);
  }
  return phases;
}

/// The area of the points of `map` bearing pressure [m^2].
double contactArea(const std::vector<nb::ContactPoint>& map) {
  double area = 0.0;
  for (const nb::ContactPoint& p : map)
    if (p.pressure_pa > 0.0) area += p.area_m2;
  return area;
}

}  // namespace

TEST(AdaptiveSupport, ReadsTheHeadTrunkPelvisAndHeelsOffTheLoadMap) {
  const nb::BedGrid grid;
  const auto layout = nb::inferBodyLayout(grid, supineSensed(grid).load_n, kConfig.adaptive);
  ASSERT_TRUE(layout);
  EXPECT_EQ(layout->midline_col, 4);
  EXPECT_EQ(layout->head_rows, (std::vector<int>{0, 1, 2}));
  EXPECT_EQ(layout->trunk_rows, (std::vector<int>{3, 4, 5, 6, 7, 8}));
  EXPECT_EQ(layout->pelvis_rows, (std::vector<int>{7, 8}));
  EXPECT_EQ(layout->heel_rows, (std::vector<int>{16, 17}));
}

TEST(AdaptiveSupport, FindsTheBodyWhereverItLiesOnTheBed) {
  // The same body two rows further down and one column to the left: the layout moves with it.
  const nb::BedGrid grid;
  nb::SensedCells shifted;
  shifted.load_n.assign(grid.cells(), 0.0);
  for (int r = 0; r < 18; ++r)
    for (int c = 1; c <= 7; ++c)
      if (r + 2 < grid.rows && c + 1 < grid.cols) shifted.load_n[grid.id(r + 2, c + 1)] = kSupineLoads[r][c - 1];
  const auto layout = nb::inferBodyLayout(grid, shifted.load_n, kConfig.adaptive);
  ASSERT_TRUE(layout);
  EXPECT_EQ(layout->midline_col, 5);
  EXPECT_EQ(layout->pelvis_rows, (std::vector<int>{9, 10}));
  EXPECT_EQ(layout->heel_rows, (std::vector<int>{18, 19}));
}

// Where each part goes without levelling (level_gain_m_n_s 0): the layout's own heights.
nb::AdaptiveSupportParams unlevelled() {
  nb::AdaptiveSupportParams p = kConfig.adaptive;
  p.level_gain_m_n_s = 0.0;
  return p;
}

TEST(AdaptiveSupport, LowersTheHeelCellsToTheFootEndAndRaisesTheCalves) {
  const nb::BedGrid grid;
  const nb::AdaptiveSupportParams p = unlevelled();
  nb::AdaptiveSupport s = support(p);
  run(&s, supineSensed(grid), 0.0, 120.0);
  for (int r : {16, 17, 18, 19})  // the heel rows and every row after them, over the feet's columns
    for (int c = 2; c <= 6; ++c) EXPECT_NEAR(s.targets()[grid.id(r, c)], p.heel_height_m, 1e-9) << r << "," << c;
  const double calf_m = std::min(kConfig.max_height_m, kConfig.nominal_height_m + p.calf_lift_m);
  for (int r : {14, 15})  // the calves go higher and take the feet's load
    for (int c = 2; c <= 6; ++c) EXPECT_NEAR(s.targets()[grid.id(r, c)], calf_m, 1e-9) << r << "," << c;
  EXPECT_NEAR(s.targets()[grid.id(17, 0)], kConfig.nominal_height_m, 1e-9);  // off the feet's columns
}

TEST(AdaptiveSupport, RaisesTheThighsAfterThePelvisUpToTheCalves) {
  const nb::BedGrid grid;
  nb::AdaptiveSupportParams p = unlevelled();
  nb::AdaptiveSupport s = support(p);
  run(&s, supineSensed(grid), 0.0, 120.0);
  for (int r : {9, 10})  // the rows after the pelvis (rows 7-8): loaded columns 2-6 and one either side
    for (int c = 0; c < grid.cols; ++c) {
      const double lift_m = c >= 1 && c <= 7 ? p.thigh_lift_m : 0.0;
      EXPECT_NEAR(s.targets()[grid.id(r, c)], kConfig.nominal_height_m + lift_m, 1e-9) << r << "," << c;
    }
  for (int r : {11, 12, 13})  // up to the calves (rows 14-15)
    EXPECT_NEAR(s.targets()[grid.id(r, 3)], kConfig.nominal_height_m + p.thigh_lift_m, 1e-9) << r;
  p.thigh_length_m = 0.2;  // two rows of thighs
  nb::AdaptiveSupport short_thighs = support(p);
  run(&short_thighs, supineSensed(grid), 0.0, 120.0);
  EXPECT_NEAR(short_thighs.targets()[grid.id(10, 3)], kConfig.nominal_height_m + p.thigh_lift_m, 1e-9);
  for (int c = 0; c < grid.cols; ++c)
    EXPECT_NEAR(short_thighs.targets()[grid.id(11, c)], kConfig.nominal_height_m, 1e-9) << c;
  nb::AdaptiveSupportParams flat_thighs = p;
  flat_thighs.thigh_lift_m = 0.0;
  nb::AdaptiveSupport off = support(flat_thighs);
  run(&off, supineSensed(grid), 0.0, 120.0);
  EXPECT_NEAR(off.targets()[grid.id(9, 4)], kConfig.nominal_height_m, 1e-9);
}

TEST(AdaptiveSupport, ReadsTheBodyNetOfWhatAnEmptyCellSenses) {
  // Every cell reads 0.8 N more (the plate's weight, an offset of the estimates): the layout is
  // the same, and an empty cell reads as empty.
  const nb::BedGrid grid;
  nb::SensedCells offset = supineSensed(grid);
  for (double& l : offset.load_n) l += 0.8;
  EXPECT_NEAR(nb::emptyCellLoad(offset.load_n), 0.8, 1e-12);
  const auto plain = nb::inferBodyLayout(grid, supineSensed(grid).load_n, kConfig.adaptive);
  const auto shifted = nb::inferBodyLayout(grid, offset.load_n, kConfig.adaptive);
  ASSERT_TRUE(plain && shifted);
  EXPECT_EQ(shifted->first_row, plain->first_row);
  EXPECT_EQ(shifted->last_row, plain->last_row);
  EXPECT_EQ(shifted->heel_rows, plain->heel_rows);
  EXPECT_EQ(shifted->trunk_rows, plain->trunk_rows);
  EXPECT_EQ(shifted->heel_cells, plain->heel_cells);
  EXPECT_EQ(shifted->thigh_cells, plain->thigh_cells);
  EXPECT_EQ(shifted->trunk_cells, plain->trunk_cells);
}

TEST(AdaptiveSupport, HoldsTheBedLevelWhileSurveyingAndWithoutABody) {
  const nb::BedGrid grid;
  nb::AdaptiveSupport s = support();
  EXPECT_EQ(run(&s, supineSensed(grid), 0.0, kConfig.adaptive.survey_s - 1.0).back(), "surveying");
  for (double h : s.targets()) EXPECT_EQ(h, kConfig.nominal_height_m);
  nb::AdaptiveSupport empty = support();
  nb::SensedCells nothing;
  nothing.load_n.assign(grid.cells(), 0.0);
  EXPECT_EQ(run(&empty, nothing, 0.0, 60.0).back(), "level: no body sensed");
  for (double h : empty.targets()) EXPECT_EQ(h, kConfig.nominal_height_m);
}

TEST(AdaptiveSupport, LevelsTheTrunkButKeepsItAboveTheBottomingOutMargin) {
  // A sacrum carrying far more than its neighbours: levelling lowers it and raises them, but
  // never below the margin height, also while the pelvis is relieved.
  const nb::BedGrid grid;
  nb::SensedCells sensed = supineSensed(grid);
  sensed.load_n[grid.id(8, 4)] = 300.0;
  nb::AdaptiveSupportParams p = kConfig.adaptive;
  p.level_range_m = 0.05;  // levelling alone would go to 0.05 m
  p.relief_budget_s = 900.0;
  nb::AdaptiveSupport s = support(p);
  double lowest_sacrum = 1.0;
  std::string phase;
  for (double t = 0.0; t <= 1200.0; t += kStepS) {
    s.update(t, sensed, &phase);
    lowest_sacrum = std::min(lowest_sacrum, s.targets()[grid.id(8, 4)]);
  }
  EXPECT_NEAR(lowest_sacrum, p.margin_height_m, 1e-9);
  EXPECT_GT(s.targets()[grid.id(8, 3)], kConfig.nominal_height_m);  // its neighbours take the load
  for (int r = 3; r <= 8; ++r)
    for (int c = 0; c < grid.cols; ++c) EXPECT_GE(s.targets()[grid.id(r, c)], p.margin_height_m - 1e-12);
}

TEST(AdaptiveSupport, RelievesThePelvisUpperTrunkAndHeadInTurnWithinTheBudget) {
  const nb::BedGrid grid;
  nb::AdaptiveSupportParams p = kConfig.adaptive;
  p.relief_budget_s = 300.0;
  p.relief_s = 30.0;
  p.level_gain_m_n_s = 0.0;  // relief only
  nb::AdaptiveSupport s = support(p);
  const std::vector<std::string> phases = run(&s, supineSensed(grid), 0.0, 440.0);
  const std::vector<std::string> expected = {
      "surveying", "adapting",       "relieving pelvis", "adapting", "relieving upper trunk",
      "adapting",  "relieving head", "adapting"};
  EXPECT_EQ(phases, expected);
  // During the pelvis's relief its rows are lower, the rows either side higher.
  nb::AdaptiveSupport again = support(p);
  run(&again, supineSensed(grid), 0.0, p.survey_s + p.relief_budget_s / 3.0 + 20.0);
  EXPECT_LT(again.targets()[grid.id(7, 2)], kConfig.nominal_height_m);
  EXPECT_GT(again.targets()[grid.id(9, 2)], kConfig.nominal_height_m);
  EXPECT_GT(again.targets()[grid.id(6, 2)], kConfig.nominal_height_m);
}

TEST(AdaptiveSupport, ARelievedRegionsLoadGoesToItsNeighboursButNeverOntoThePelvis) {
  const nb::BedGrid grid;
  nb::AdaptiveSupportParams p = unlevelled();
  p.relief_budget_s = 300.0;
  p.relief_s = 30.0;
  nb::AdaptiveSupport s = support(p);
  // The pelvis is due at 120 s, the upper trunk (rows 3-6) at 220 s.
  EXPECT_EQ(run(&s, supineSensed(grid), 0.0, 240.0).back(), "relieving upper trunk");
  EXPECT_LT(s.targets()[grid.id(4, 4)], kConfig.nominal_height_m);
  EXPECT_GT(s.targets()[grid.id(2, 4)], kConfig.nominal_height_m);  // the head's last row takes it
  for (int c = 0; c < grid.cols; ++c) EXPECT_EQ(s.targets()[grid.id(7, c)], kConfig.nominal_height_m) << c;
}

TEST(AdaptiveSupport, LevelsEveryCellUnderTheBodyButTheHeelsAndCalves) {
  // Under the legs too, a cell carrying less than its neighbours rises and takes load, one
  // carrying more goes down; the floated heels and the lifted calves stay where they are.
  const nb::BedGrid grid;
  nb::AdaptiveSupport s = support();
  run(&s, supineSensed(grid), 0.0, 300.0);
  const double thigh_m = kConfig.nominal_height_m + kConfig.adaptive.thigh_lift_m;
  EXPECT_GT(s.targets()[grid.id(12, 4)], s.targets()[grid.id(12, 3)]);  // 4.3 N between two of 8 N
  EXPECT_LT(s.targets()[grid.id(11, 3)], thigh_m);                      // 18.2 N beside 10.7 and 0.9 N
  EXPECT_GT(s.targets()[grid.id(5, 1)], kConfig.nominal_height_m);      // an arm's cell beside the chest
  EXPECT_NEAR(s.targets()[grid.id(16, 3)], kConfig.adaptive.heel_height_m, 1e-9);
  const double calf_m = std::min(kConfig.max_height_m, kConfig.nominal_height_m + kConfig.adaptive.calf_lift_m);
  EXPECT_NEAR(s.targets()[grid.id(14, 3)], calf_m, 1e-9);
}

TEST(AdaptiveSupport, RaisesACellThatDoesNotSenseTheBodyOnlyWithinItsReach) {
  // Beside the chest, cell (4, 1) senses nothing while its neighbours carry the arm: levelling
  // raises it by reach_m and no further (raising it moves no load); (5, 1), under the arm,
  // goes up to the levelling range. Once (4, 1) senses the body it may go on rising.
  const nb::BedGrid grid;
  nb::SensedCells sensed = supineSensed(grid);
  sensed.load_n[grid.id(4, 1)] = 0.0;
  const nb::AdaptiveSupportParams& p = kConfig.adaptive;
  ASSERT_LT(p.reach_m, p.level_range_m);
  nb::AdaptiveSupport s = support();
  run(&s, sensed, 0.0, 1000.0);
  EXPECT_NEAR(s.targets()[grid.id(4, 1)], kConfig.nominal_height_m + p.reach_m, 1e-9);
  EXPECT_GT(s.targets()[grid.id(5, 1)], kConfig.nominal_height_m + p.reach_m + 1e-3);
  sensed.load_n[grid.id(4, 1)] = 1.5;
  run(&s, sensed, 1000.1, 1600.0);
  EXPECT_GT(s.targets()[grid.id(4, 1)], kConfig.nominal_height_m + p.reach_m + 1e-3);
}

TEST(AdaptiveSupport, LevellingWaitsWhileARegionIsRelieved) {
  // The relief's load shift is no imbalance to level: the other cells hold still through it.
  const nb::BedGrid grid;
  nb::AdaptiveSupportParams p = kConfig.adaptive;
  p.relief_budget_s = 300.0;
  p.relief_s = 30.0;
  nb::AdaptiveSupport s = support(p);
  EXPECT_EQ(run(&s, supineSensed(grid), 0.0, 125.0).back(), "relieving pelvis");
  const std::vector<double> early = s.targets();
  EXPECT_EQ(run(&s, supineSensed(grid), 125.1, 145.0).back(), "relieving pelvis");
  for (int r : {3, 4, 11, 12})
    for (int c = 0; c < grid.cols; ++c) EXPECT_EQ(s.targets()[grid.id(r, c)], early[grid.id(r, c)]) << r << "," << c;
}

TEST(AdaptiveSupport, RelievesARegionSoonerWhenItsSensedDoseReachesTheLimit) {
  const nb::BedGrid grid;
  nb::AdaptiveSupportParams p = kConfig.adaptive;
  p.relief_budget_s = 1e6;  // only the dose can make a relief due
  p.dose_limit = 0.01;
  nb::SensedCells sensed = supineSensed(grid);
  sensed.load_n[grid.id(1, 4)] = 120.0;  // the occiput at ~90 mmHg over its cell: ~5 h on the curve
  nb::AdaptiveSupport s = support(p);
  const std::vector<std::string> phases = run(&s, sensed, 0.0, p.survey_s + 400.0);
  ASSERT_GE(phases.size(), 3u);
  EXPECT_EQ(phases[2], "relieving head");
  EXPECT_EQ(std::count(phases.begin(), phases.end(), "relieving pelvis"), 0);
}

TEST(AdaptiveSupport, NeverMovesATargetFasterThanItsRate) {
  const nb::BedGrid grid;
  nb::AdaptiveSupport s = support();
  std::vector<double> before = s.targets();
  std::string phase;
  for (double t = 0.0; t <= 300.0; t += kStepS) {
    s.update(t, supineSensed(grid), &phase);
    for (int i = 0; i < grid.cells(); ++i)
      ASSERT_LE(std::fabs(s.targets()[i] - before[i]), kConfig.adaptive.max_rate_m_s * kStepS + 1e-12);
    before = s.targets();
  }
}

TEST(AdaptiveSupport, FloatsTheHeelsOfThreeArticulatedBodiesFromTheirOwnLoadMaps) {
  // Closed loop on the articulated body: the cells reach their targets, and the plan senses
  // the loads the body puts on them plus the plate's weight on every cell. On a small, the
  // default and a heavy body the heels float (their weight goes to the calves), the raised
  // thighs and the levelled trunk keep the sacrum and the trochanters at or below 32 mmHg, the
  // skin stays clear of the bed base, and the levelled cells envelop the body: it touches the
  // bed over at least the flat bed's area although its feet no longer do.
  const nb::BedGrid grid;
  for (const auto& [mass_kg, height_m] : std::vector<std::pair<double, double>>{{50, 1.55}, {70, 1.70}, {110, 1.85}}) {
    nb::PatientParams patient;
    patient.articulated = true;
    patient.mass_kg = mass_kg;
    patient.height_m = height_m;
    nb::BodyModel body(patient, grid);
    nb::AdaptiveSupport s = support();
    std::vector<double> heights(grid.cells(), kConfig.nominal_height_m);
    body.solve(heights);
    const double flat_area_m2 = contactArea(body.contactMap(heights));
    nb::SensedCells sensed;
    std::string phase;
    for (double t = 0.0; t <= 400.0; t += kStepS) {
      sensed.load_n = body.solve(heights).cell_load_n;
      for (double& l : sensed.load_n) l += 0.6;
      heights = s.update(t, sensed, &phase);
    }
    const nb::BodyState state = body.solve(heights);
    EXPECT_LT(nb::paToMmHg(state.peak_pressure_pa.heels), 10.0) << mass_kg << " kg";
    EXPECT_GE(contactArea(body.contactMap(heights)), flat_area_m2) << mass_kg << " kg";
    const auto regions = nb::measureRegions(body.contactMap(heights), nb::defaultTissueRegions(), height_m);
    const auto& names = nb::defaultTissueRegions();
    for (std::size_t k = 0; k < regions.size(); ++k) {
      if (std::isfinite(regions[k].margin_m)) {
        EXPECT_GE(regions[k].margin_m, 0.025) << mass_kg << " kg, " << names[k].name;
      }
      if (names[k].name == "sacrum" || names[k].name.find("trochanter") != std::string::npos) {
        EXPECT_LE(nb::paToMmHg(regions[k].peak_pressure_pa), 32.0) << mass_kg << " kg, " << names[k].name;
      }
    }
  }
}

TEST(AdaptivePlan, IsMadeFromTheRegistryWithItsArguments) {
  std::string why;
  const auto plan = nb::makePlan({"adaptive", {{"heel_height_m", "0.04"}, {"relief_s", "60"}}, {}}, kConfig,
                                 nb::BedGrid{}, nb::BodyFootprint{}, &why);
  ASSERT_TRUE(plan) << why;
  EXPECT_EQ(plan->name(), "adaptive");
  EXPECT_NE(plan->describe().find("heel_height_m=0.04"), std::string::npos);
  EXPECT_NE(plan->describe().find("relief_s=60"), std::string::npos);
}

TEST(AdaptivePlan, CombinedWithATurnTiltsTheBedOnceTheSurveyHasReadTheBody) {
  std::string why;
  const nb::BedGrid grid;
  auto plan = nb::makePlan(
      {"adaptive", {{"side", "left"}, {"angle_deg", "20"}, {"ramp_s", "30"}, {"thigh_length_m", "0.2"}}, {}}, kConfig,
      grid, nb::BodyFootprint{}, &why);
  ASSERT_TRUE(plan) << why;
  EXPECT_NE(plan->describe().find("side=left angle_deg=20 ramp_s=30"), std::string::npos) << plan->describe();
  const nb::SensedCells sensed = supineSensed(grid);
  nb::PlanTargets t;
  for (double s = 0.0; s <= kConfig.adaptive.survey_s; s += kStepS) t = plan->sensedTargets(s, sensed);
  EXPECT_EQ(t.tilt_deg, 0.0);  // level while surveying
  for (int i = 0; i < grid.cells(); ++i) EXPECT_EQ(t.heights_m[i], kConfig.nominal_height_m);
  for (double s = kConfig.adaptive.survey_s; s <= kConfig.adaptive.survey_s + 15.0; s += kStepS)
    t = plan->sensedTargets(s, sensed);
  EXPECT_NEAR(t.tilt_deg, 10.0, 0.1);  // half way up the 30 s ramp
  for (double s = kConfig.adaptive.survey_s + 15.0; s <= 200.0; s += kStepS) t = plan->sensedTargets(s, sensed);
  EXPECT_EQ(t.tilt_deg, 20.0);
  EXPECT_NE(t.phase.find("turned"), std::string::npos) << t.phase;
  // A left turn lowers the patient's left (+y, the higher columns) under the trunk ...
  for (int r = 3; r <= 8; ++r) EXPECT_LT(t.heights_m[grid.id(r, 6)], t.heights_m[grid.id(r, 2)] - 0.05) << r;
  // ... and the heels stay floated below their calves, the thighs above the knees.
  for (int c = 3; c <= 5; ++c) {
    EXPECT_LT(t.heights_m[grid.id(16, c)], t.heights_m[grid.id(14, c)] - 0.05) << c;
    EXPECT_GT(t.heights_m[grid.id(9, c)], t.heights_m[grid.id(12, c)]) << c;
  }
  for (double h : t.heights_m) {
    EXPECT_GE(h, kConfig.min_height_m);
    EXPECT_LE(h, kConfig.max_height_m);
  }
}

TEST(AdaptivePlan, RefusesBadArgumentsWithTheReason) {
  const std::vector<std::pair<std::map<std::string, std::string>, std::string>> bad = {
      {{{"heel_height_m", "0.5"}}, "heel_height_m must lie in"},
      {{{"margin_height_m", "0.001"}}, "margin_height_m must lie in"},
      {{{"calf_lift_m", "0.2"}}, "calf_lift_m must lie in"},
      {{{"calf_length_m", "-0.1"}}, "calf_length_m must be >= 0"},
      {{{"thigh_lift_m", "0.5"}}, "thigh_lift_m must lie in"},
      {{{"side", "left"}}, "needs angle_deg"},
      {{{"side", "up"}, {"angle_deg", "20"}}, "side"},
      {{{"side", "left"}, {"angle_deg", "45"}}, "angle_deg"},
      {{{"side", "left"}, {"angle_deg", "30"}, {"ramp_s", "5"}}, "turns faster than"},
      {{{"relief_s", "nan"}}, "relief_s must be finite"},
      {{{"relief_budget_s", "10"}}, "relief_budget_s must exceed relief_s"},
      {{{"max_rate_m_s", "0"}}, "max_rate_m_s must be positive"},
      {{{"level_range_m", "0.2"}}, "level_range_m must lie in"},
      {{{"bogus", "1"}}, "does not take 'bogus'"},
  };
  for (const auto& [args, reason] : bad) {
    std::string why;
    EXPECT_FALSE(nb::makePlan({"adaptive", args, {}}, kConfig, nb::BedGrid{}, nb::BodyFootprint{}, &why));
    EXPECT_NE(why.find(reason), std::string::npos) << why;
  }
}

TEST(AdaptivePlan, RefusesABadConfigurationNamingTheKey) {
  nb::PlanConfig config;
  config.adaptive.heel_height_m = 0.2;
  config.adaptive.tolerance.exponent = -1.0;
  config.adaptive.reach_m = config.adaptive.level_range_m + 0.01;
  const nb::Status s = config.validate();
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("adaptive/heel_height_m"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("adaptive/reach_m"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("adaptive/tolerance"), std::string::npos) << s.message();
  // Every key is in the parameter table, so YAML and the parameter server reach it.
  int adaptive_keys = 0;
  for (const auto& f : nb::planConfigFields()) adaptive_keys += f.key.rfind("adaptive/", 0) == 0;
  EXPECT_EQ(adaptive_keys, static_cast<int>(nb::adaptiveSupportFields().size()));
}

namespace {

// A supervisor over the 20 x 9 bed whose cells report the supine loads at 0.10 m.
struct SupervisedBed {
  nb::BedGrid grid;
  std::vector<nb::BedCell> cells;
  nb::BedSupervisor sup;
  double now = 100.0;

  static std::vector<nb::BedCell> cellsOf(const nb::BedGrid& g) {
    std::vector<nb::BedCell> out;
    for (int i = 0; i < g.cells(); ++i)
      out.push_back(
          {static_cast<std::uint32_t>(i), "cell_" + std::to_string(i), "link", g.min_height_m, g.max_height_m});
    return out;
  }
  SupervisedBed() : cells(cellsOf(grid)), sup(nb::BedSupervisorParams{}, grid, cellsOf(grid), now) {}
  void report() {
    const nb::SensedCells sensed = supineSensed(grid);
    for (int i = 0; i < grid.cells(); ++i) {
      nb::CellSnapshot s;
      s.id = static_cast<std::uint32_t>(i);
      s.height_m = 0.10;
      s.height_sd_m = 0.001;
      s.gauge_pressure_pa = 3000.0;
      s.external_load_n = sensed.load_n[i];
      s.seen_s = now;
      sup.onCellState(s);
    }
  }
  nb::BedStatus stepFor(double seconds) {
    nb::BedStatus status;
    for (double end = now + seconds; now < end - 1e-9; now += kStepS) {
      report();
      status = sup.step(now);
    }
    return status;
  }
};

}  // namespace

TEST(AdaptivePlan, RunsUnderTheSupervisorAndABadRequestKeepsIt) {
  SupervisedBed bed;
  ASSERT_TRUE(bed.sup.setPosture("adaptive", {}, {}, {}, bed.now).ok);
  nb::BedStatus status = bed.stepFor(60.0);
  EXPECT_EQ(status.plan, nb::PlanKind::kAdaptive);
  EXPECT_EQ(status.phase, "adapting");
  EXPECT_LT(status.target_heights_m[bed.grid.id(17, 3)], bed.sup.params().plans.nominal_height_m);
  const nb::RequestResult refused = bed.sup.setPosture("adaptive", {"heel_height_m"}, {"0.9"}, {}, bed.now);
  EXPECT_FALSE(refused.ok);
  EXPECT_NE(refused.message.find("heel_height_m"), std::string::npos) << refused.message;
  status = bed.stepFor(1.0);
  EXPECT_EQ(status.plan, nb::PlanKind::kAdaptive);
  EXPECT_EQ(status.phase, "adapting");  // the same plan, not restarted
}

TEST(AdaptivePlan, GivesWayToCpr) {
  SupervisedBed bed;
  ASSERT_TRUE(bed.sup.setPosture("adaptive", {}, {}, {}, bed.now).ok);
  bed.stepFor(30.0);
  bed.sup.onCpr(true, bed.now);
  EXPECT_EQ(bed.stepFor(0.2).plan, nb::PlanKind::kCpr);
}
