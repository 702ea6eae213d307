// The articulated patient: joined segments agree with the free ones on a flat bed and a tilted
// plane (the joints' rest pose), keep the supine references, and carry a foot whose cells are
// lowered from the leg (its load moves to the calves).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "nursing_bed/core/bed/body_model.h"
#include "nursing_bed/core/physics/units.h"

namespace nb = nursing_bed;

namespace {

nb::PatientParams articulated() {
  nb::PatientParams p;
  p.articulated = true;
  return p;
}

double mmhg(double pa) { return nb::paToMmHg(pa); }

double supportOf(const nb::BodyState& s, const char* name) {
  return s.segments[nb::BodyModel::segmentIndex(name)].support_n;
}

/// Cells tilted about the bed's long axis: h = centre + tan(angle) y, within the cells' range.
std::vector<double> tilted(const nb::BedGrid& g, double angle_rad, double centre_m) {
  std::vector<double> h(g.cells());
  for (int r = 0; r < g.rows; ++r)
    for (int c = 0; c < g.cols; ++c)
      h[g.id(r, c)] = std::clamp(centre_m + std::tan(angle_rad) * g.y(c), g.min_height_m, g.max_height_m);
  return h;
}

TEST(ArticulatedBody, RestsOnAFlatBedAsTheFreeSegmentsDo) {
  nb::BedGrid g;
  nb::BodyModel free_body(nb::PatientParams{}, g), joined(articulated(), g);
  const std::vector<double> flat(g.cells(), 0.10);
  const nb::BodyState a = free_body.solve(flat), b = joined.solve(flat);
  ASSERT_TRUE(b.converged);
  EXPECT_NEAR(b.total_load_n, joined.weightN(), 1e-6 * joined.weightN());
  for (std::size_t i = 0; i < a.segments.size(); ++i) {
    EXPECT_NEAR(b.segments[i].z_m, a.segments[i].z_m, 1e-6) << a.segments[i].name;
    EXPECT_NEAR(b.segments[i].pitch_rad, 0.0, 1e-6) << a.segments[i].name;
  }
  // The supine references on foam (sacrum 36-44, heels 46-59, occiput 43-63 mmHg), within 10 %.
  EXPECT_GE(mmhg(b.peak_pressure_pa.sacrum), 0.9 * 36.0);
  EXPECT_LE(mmhg(b.peak_pressure_pa.sacrum), 1.1 * 44.0);
  EXPECT_GE(mmhg(b.peak_pressure_pa.heels), 0.9 * 46.0);
  EXPECT_LE(mmhg(b.peak_pressure_pa.heels), 1.1 * 59.0);
  EXPECT_GE(mmhg(b.peak_pressure_pa.occiput), 0.9 * 43.0);
  EXPECT_LE(mmhg(b.peak_pressure_pa.occiput), 1.1 * 63.0);
  EXPECT_NEAR(b.peak_pressure_pa.sacrum, a.peak_pressure_pa.sacrum, 0.01 * a.peak_pressure_pa.sacrum);
}

TEST(ArticulatedBody, RollsWithATwentyDegreeTurnWithinOneDegree) {
  nb::BedGrid g;
  nb::BodyModel joined(articulated(), g);
  const double angle = 20.0 * nb::kPi / 180.0;
  const nb::BodyState s = joined.solve(tilted(g, angle, 0.075));
  ASSERT_TRUE(s.converged);
  EXPECT_NEAR(s.roll_rad, angle, 1.0 * nb::kPi / 180.0);
  EXPECT_NEAR(s.total_load_n, joined.weightN(), 1e-6 * joined.weightN());
}

TEST(ArticulatedBody, LoweringTheHeelRowsMovesTheFootsLoadToTheCalves) {
  nb::BedGrid g;
  nb::BodyModel free_body(nb::PatientParams{}, g), joined(articulated(), g);
  std::vector<double> heights(g.cells(), 0.10);
  const nb::BodyState before = joined.solve(heights);
  const std::vector<int> heel_rows = joined.heelRows();
  for (int r : heel_rows)
    for (int c = 0; c < g.cols; ++c) heights[g.id(r, c)] = 0.02;
  const nb::BodyState after = joined.solve(heights), free_after = free_body.solve(heights);
  ASSERT_TRUE(after.converged);
  const double foot_n = 0.0145 * joined.weightN();
  for (const char* side : {"right", "left"}) {
    const std::string foot = std::string(side) + "_foot", leg = std::string(side) + "_leg";
    // Free segments: the foot follows its cells down and still bears its own weight.
    EXPECT_NEAR(supportOf(free_after, foot.c_str()), foot_n, 1e-6) << side;
    // Joined: the foot hangs from the ankle, its weight carried by the leg's calf (which,
    // levered about the calf by the foot, also takes some of the thigh's weight at the knee,
    // and the thigh some of the pelvis's at the hip).
    const double foot_lost = supportOf(before, foot.c_str()) - supportOf(after, foot.c_str());
    EXPECT_GT(foot_lost, 0.9 * foot_n) << side;
    EXPECT_GT(supportOf(after, leg.c_str()) - supportOf(before, leg.c_str()), foot_lost) << side;
  }
  // The lowered heel rows lose their load; the three calf rows above them take it.
  double heel_rows_before = 0.0, heel_rows_after = 0.0, calf_rows_before = 0.0, calf_rows_after = 0.0;
  for (int r = 0; r < g.rows; ++r)
    for (int c = 0; c < g.cols; ++c) {
      const bool heel = std::find(heel_rows.begin(), heel_rows.end(), r) != heel_rows.end();
      const bool calf = !heel && r >= heel_rows.front() - 3 && r < heel_rows.front();
      if (heel) {
        heel_rows_before += before.cell_load_n[g.id(r, c)];
        heel_rows_after += after.cell_load_n[g.id(r, c)];
      } else if (calf) {
        calf_rows_before += before.cell_load_n[g.id(r, c)];
        calf_rows_after += after.cell_load_n[g.id(r, c)];
      }
    }
  EXPECT_LT(heel_rows_after, 0.5 * heel_rows_before);
  EXPECT_GT(calf_rows_after - calf_rows_before, heel_rows_before - heel_rows_after);
  EXPECT_LT(mmhg(after.peak_pressure_pa.heels), 0.2 * mmhg(before.peak_pressure_pa.heels));
  EXPECT_NEAR(after.total_load_n, joined.weightN(), 1e-6 * joined.weightN());
}

TEST(ArticulatedBody, ConvergesOnRoughCellsAndCarriesTheWeight) {
  nb::BedGrid g;
  nb::BodyModel joined(articulated(), g);
  std::vector<double> heights(g.cells());
  unsigned state = 12345u;  // a fixed linear congruential sequence: cells 0.02-0.15 m
  for (int step = 0; step < 5; ++step) {
    for (double& h : heights) {
      state = state * 1664525u + 1013904223u;
      h = 0.02 + 0.13 * (state >> 8) / double(1u << 24);
    }
    const nb::BodyState s = joined.solve(heights);
    ASSERT_TRUE(s.converged) << "step " << step;
    EXPECT_NEAR(s.total_load_n, joined.weightN(), 1e-6 * joined.weightN()) << "step " << step;
    for (const nb::SegmentPose& seg : s.segments) {
      EXPECT_TRUE(std::isfinite(seg.z_m)) << seg.name;
      EXPECT_LT(std::abs(seg.pitch_rad), 1.0) << seg.name;
    }
  }
}

TEST(ArticulatedBody, RefusesABadJointStiffnessByName) {
  nb::PatientParams p = articulated();
  p.joint_stiffness_n_m = 0.0;
  const nb::Status s = p.validate();
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("joint_stiffness_n_m"), std::string::npos) << s.message();
}

}  // namespace
