// The patient body model: segment table, equilibrium (force and roll moment), loads on a flat
// and a tilted bed, calibration against the interface-pressure references, parameter checks.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <deque>
#include <memory>
#include <stdexcept>
#include <string>

#include "nursing_bed/core/bed/body_model.h"
#include "nursing_bed/core/control/airbag_cell.h"
#include "nursing_bed/core/control/airbag_params_io.h"
#include "nursing_bed/core/physics/units.h"

namespace nb = nursing_bed;

namespace {

std::vector<double> flatBed(const nb::BedGrid& g, double h = 0.10) { return std::vector<double>(g.cells(), h); }

double deg(double rad) { return rad * 180.0 / nb::kPi; }

TEST(BodyModel, MassFractionsSumToOne) {
  double sum = 0.0;
  for (const nb::SegmentSpec& s : nb::segmentTable()) sum += s.mass_fraction;
  EXPECT_NEAR(sum, 1.0, 1e-9);
  EXPECT_EQ(nb::segmentTable().size(), 16u);
  // Left and right limbs mirror each other.
  for (const nb::SegmentSpec& s : nb::segmentTable()) {
    const std::string name = s.name;
    if (name.rfind("right_", 0) != 0) continue;
    const int left = nb::BodyModel::segmentIndex("left_" + name.substr(6));
    ASSERT_GE(left, 0) << name;
    const nb::SegmentSpec& l = nb::segmentTable()[left];
    EXPECT_EQ(l.mass_fraction, s.mass_fraction) << name;
    EXPECT_EQ(l.lateral_fraction, -s.lateral_fraction) << name;
  }
}

TEST(BodyModel, FlatBedCarriesTheWholeWeight) {
  nb::BedGrid g;
  nb::BodyModel body(nb::PatientParams{}, g);
  const nb::BodyState s = body.solve(flatBed(g));
  EXPECT_TRUE(s.converged);
  const double mg = 70.0 * nb::kGravity;
  EXPECT_NEAR(body.weightN(), mg, 1e-12);
  EXPECT_NEAR(s.total_load_n, mg, 1e-6);
  double sum = 0.0;
  for (std::size_t i = 0; i < s.cell_load_n.size(); ++i) {
    EXPECT_GE(s.cell_load_n[i], 0.0);
    EXPECT_NEAR(s.cell_pressure_pa[i], s.cell_load_n[i] / g.cellAreaM2(), 1e-9);
    sum += s.cell_load_n[i];
  }
  EXPECT_NEAR(sum, mg, 1e-6);
  for (const nb::SegmentPose& seg : s.segments) {
    EXPECT_TRUE(seg.on_bed) << seg.name;
    EXPECT_NEAR(seg.support_n, seg.mass_kg * nb::kGravity, 1e-7) << seg.name;
    EXPECT_LT(seg.z_m, 0.10) << seg.name << " sinks into the tissue";
  }
  // Nothing outside the footprint rows is loaded.
  const std::vector<int> rows = body.footprintRows();
  for (int r = 0; r < g.rows; ++r) {
    if (std::find(rows.begin(), rows.end(), r) != rows.end()) continue;
    for (int c = 0; c < g.cols; ++c) EXPECT_EQ(s.cell_load_n[g.id(r, c)], 0.0) << r << "," << c;
  }
}

TEST(BodyModel, FlatBedLoadsAreSymmetric) {
  nb::BedGrid g;
  nb::BodyModel body(nb::PatientParams{}, g);
  const nb::BodyState s = body.solve(flatBed(g));
  for (int r = 0; r < g.rows; ++r)
    for (int c = 0; c < g.cols / 2; ++c)
      EXPECT_NEAR(s.cell_load_n[g.id(r, c)], s.cell_load_n[g.id(r, g.cols - 1 - c)], 1e-9) << r << "," << c;
  EXPECT_NEAR(s.roll_rad, 0.0, 1e-9);
  for (const nb::SegmentPose& seg : s.segments) EXPECT_NEAR(seg.roll_rad, 0.0, 1e-9) << seg.name;
}

TEST(BodyModel, FlatBedPeaksMatchSupineReferences) {
  // doc/paper_targets.md: supine peaks on foam, sacrum 36-44, heels 46-59, occiput 43-63 mmHg.
  nb::BedGrid g;
  nb::BodyModel body(nb::PatientParams{}, g);
  const nb::BodyState s = body.solve(flatBed(g));
  const double sacrum = nb::paToMmHg(s.peak_pressure_pa.sacrum);
  const double heels = nb::paToMmHg(s.peak_pressure_pa.heels);
  const double occiput = nb::paToMmHg(s.peak_pressure_pa.occiput);
  EXPECT_GE(sacrum, 36.0);
  EXPECT_LE(sacrum, 44.0);
  EXPECT_GE(heels, 46.0);
  EXPECT_LE(heels, 59.0);
  EXPECT_GE(occiput, 43.0);
  EXPECT_LE(occiput, 63.0);
  // A 100 mm cell averages over its face: the cell pressures are lower than the point peaks.
  EXPECT_LT(s.peak_cell_pressure_pa.sacrum, s.peak_pressure_pa.sacrum);
  EXPECT_LT(s.peak_cell_pressure_pa.heels, s.peak_pressure_pa.heels);
  EXPECT_LT(s.peak_cell_pressure_pa.occiput, s.peak_pressure_pa.occiput);
}

TEST(BodyModel, TiltedCellsRollTheTrunk) {
  nb::BedGrid g;
  nb::BodyModel body(nb::PatientParams{}, g);
  for (double theta_deg : {5.0, 10.0, 15.0, 20.0, 25.0, 30.0, -15.0, -30.0}) {
    const double theta = theta_deg * nb::kPi / 180.0;
    std::vector<double> h(g.cells());
    for (int r = 0; r < g.rows; ++r)
      for (int c = 0; c < g.cols; ++c) h[g.id(r, c)] = 0.30 + std::tan(theta) * g.y(c);
    const nb::BodyState s = body.solve(h);
    EXPECT_TRUE(s.converged) << theta_deg;
    EXPECT_NEAR(deg(s.roll_rad), theta_deg, 1.0) << theta_deg;
    for (const char* trunk : {"thorax", "abdomen", "pelvis"})
      EXPECT_NEAR(deg(s.segments[nb::BodyModel::segmentIndex(trunk)].roll_rad), theta_deg, 1.0) << trunk;
    EXPECT_NEAR(s.total_load_n, body.weightN(), 1e-6) << theta_deg;
  }
}

TEST(BodyModel, RaisingACellUnderThePelvisRaisesItsLoad) {
  nb::BedGrid g;
  nb::BodyModel body(nb::PatientParams{}, g);
  std::vector<double> h = flatBed(g);
  const nb::BodyState flat = body.solve(h);
  // The cell carrying most of the pelvis.
  const nb::SegmentPose& pelvis = flat.segments[nb::BodyModel::segmentIndex("pelvis")];
  std::uint32_t cell = 0;
  double most = 0.0;
  for (const auto& cl : pelvis.cell_loads_n)
    if (cl.second > most) most = cl.second, cell = cl.first;
  ASSERT_GT(most, 0.0);
  const std::vector<int> rows = body.pelvisRows();
  EXPECT_NE(std::find(rows.begin(), rows.end(), g.row(cell)), rows.end());
  h[cell] += 0.01;
  const nb::BodyState raised = body.solve(h);
  EXPECT_GT(raised.cell_load_n[cell], flat.cell_load_n[cell] + 1.0);
  EXPECT_NEAR(raised.total_load_n, body.weightN(), 1e-6);
  h[cell] -= 0.03;  // and lowering it offloads it
  const nb::BodyState lowered = body.solve(h);
  EXPECT_LT(lowered.cell_load_n[cell], flat.cell_load_n[cell] - 1.0);
  EXPECT_NEAR(lowered.total_load_n, body.weightN(), 1e-6);
}

TEST(BodyModel, RollMomentBalancesPerSegment) {
  // An uneven bed: every segment's cell forces must still balance its weight and have no
  // moment about its long axis (cell centres as lever arms: the cover's bilinear shares
  // reproduce the sub-point positions exactly inside the grid).
  nb::BedGrid g;
  nb::BodyModel body(nb::PatientParams{}, g);
  std::vector<double> h(g.cells());
  for (int r = 0; r < g.rows; ++r)
    for (int c = 0; c < g.cols; ++c)
      h[g.id(r, c)] = 0.09 + 0.02 * std::sin(1.3 * r + 0.7 * c) + 0.015 * std::cos(2.1 * c - 0.4 * r);
  const nb::BodyState s = body.solve(h);
  ASSERT_TRUE(s.converged);
  EXPECT_NEAR(s.total_load_n, body.weightN(), 1e-6);
  for (const nb::SegmentPose& seg : s.segments) {
    double force = 0.0, moment = 0.0;
    for (const auto& cl : seg.cell_loads_n) {
      force += cl.second;
      moment += cl.second * (g.y(g.col(cl.first)) - seg.y_c_m);
    }
    EXPECT_NEAR(force, seg.mass_kg * nb::kGravity, 1e-7) << seg.name;
    EXPECT_NEAR(moment, 0.0, 1e-7) << seg.name;
    EXPECT_NEAR(seg.moment_residual_nm, 0.0, 1e-7) << seg.name;
    EXPECT_FALSE(seg.at_roll_limit) << seg.name;
  }
}

TEST(BodyModel, BridgesADeflatedRowUnderThePelvis) {
  // The row under the middle of the pelvis down to 30 mm, the rest at 120 mm (as an
  // alternating pattern does): the pelvis is only partly supported, the solver still finds its
  // equilibrium, and the low row is largely offloaded onto its neighbours.
  nb::BedGrid g;
  nb::BodyModel body(nb::PatientParams{}, g);
  std::vector<double> h = flatBed(g, 0.12);
  const nb::BodyState before = body.solve(h);
  const std::vector<int> rows = body.pelvisRows();
  ASSERT_EQ(rows.size(), 3u);
  const int low = rows[1];
  for (int c = 0; c < g.cols; ++c) h[g.id(low, c)] = 0.03;
  const nb::BodyState after = body.solve(h);
  EXPECT_TRUE(after.converged);
  EXPECT_NEAR(after.total_load_n, body.weightN(), 1e-6);
  double row_before = 0.0, row_after = 0.0;
  for (int c = 0; c < g.cols; ++c) {
    row_before += before.cell_load_n[g.id(low, c)];
    row_after += after.cell_load_n[g.id(low, c)];
  }
  EXPECT_LT(row_after, 0.5 * row_before);
  const nb::SegmentPose& pelvis = after.segments[nb::BodyModel::segmentIndex("pelvis")];
  EXPECT_NEAR(pelvis.support_n, pelvis.mass_kg * nb::kGravity, 1e-7);
  EXPECT_GT(after.peak_pressure_pa.sacrum, before.peak_pressure_pa.sacrum);  // on two rows, not three
}

TEST(BodyModel, WarmStartGivesTheSameAnswer) {
  nb::BedGrid g;
  nb::BodyModel body(nb::PatientParams{}, g);
  const nb::BodyState a = body.solve(flatBed(g));
  const nb::BodyState b = body.solve(flatBed(g));
  EXPECT_LE(b.iterations, static_cast<int>(b.segments.size()));  // at most one check each
  for (std::size_t i = 0; i < a.cell_load_n.size(); ++i) EXPECT_NEAR(a.cell_load_n[i], b.cell_load_n[i], 1e-9);
  body.reset();
  const nb::BodyState c = body.solve(flatBed(g));
  for (std::size_t i = 0; i < a.cell_load_n.size(); ++i) EXPECT_NEAR(a.cell_load_n[i], c.cell_load_n[i], 1e-9);
}

TEST(BodyModel, BarePlatesAlsoCarryTheWeight) {
  nb::BedGrid g;
  nb::PatientParams p;
  p.smooth_cover = false;
  nb::BodyModel body(p, g);
  std::vector<double> h(g.cells());
  for (int r = 0; r < g.rows; ++r)
    for (int c = 0; c < g.cols; ++c) h[g.id(r, c)] = 0.2 + std::tan(0.3) * g.y(c);
  const nb::BodyState s = body.solve(h);
  EXPECT_TRUE(s.converged);
  EXPECT_NEAR(s.total_load_n, body.weightN(), 1e-6);
  EXPECT_NEAR(s.roll_rad, 0.3, 0.05);  // the staircase rolls the trunk about as far
}

TEST(BodyModel, FeetOffTheBedAreCarriedByTheLegs) {
  nb::BedGrid g;
  g.rows = 16;  // a 1.6 m bed: a 1.70 m patient's feet hang off
  nb::BodyModel body(nb::PatientParams{}, g);
  const nb::BodyState s = body.solve(flatBed(g));
  EXPECT_TRUE(s.converged);
  EXPECT_NEAR(s.total_load_n, body.weightN(), 1e-6);
  const nb::SegmentPose& foot = s.segments[nb::BodyModel::segmentIndex("right_foot")];
  const nb::SegmentPose& leg = s.segments[nb::BodyModel::segmentIndex("right_leg")];
  EXPECT_FALSE(foot.on_bed);
  EXPECT_NEAR(leg.support_n, (leg.mass_kg + foot.mass_kg) * nb::kGravity, 1e-7);
  EXPECT_TRUE(body.heelRows().empty());
}

TEST(BodyModel, FootprintHelpersFollowTheBody) {
  nb::BedGrid g;
  nb::BodyModel body(nb::PatientParams{}, g);
  const std::vector<int> all = body.footprintRows(), trunk = body.trunkRows(), head = body.headRows();
  ASSERT_FALSE(all.empty());
  ASSERT_FALSE(trunk.empty());
  ASSERT_FALSE(head.empty());
  EXPECT_EQ(head.front(), 0);  // head at row 0 (5 cm clearance)
  EXPECT_LT(head.back(), trunk.front() + 1);
  EXPECT_LE(all.back(), g.rows - 1);
  for (int r : trunk) EXPECT_NE(std::find(all.begin(), all.end(), r), all.end());
  // A 1.70 m patient from 5 cm below the head edge ends 1.75 m down: row 17.
  EXPECT_EQ(all.back(), 17);
  const std::vector<int> cols = body.footprintCols();
  EXPECT_EQ(cols.front(), g.cols - 1 - cols.back());  // centred
  // Shifting the body shifts the columns.
  nb::PatientParams shifted;
  shifted.lateral_offset_m = 0.1;
  nb::BodyModel right(shifted, g);
  EXPECT_EQ(right.footprintCols().back(), cols.back() + 1);
}

// The coupling the simulator node runs, without ROS: cells (the shipped parameters) with their
// gas held at 120 mm, where they are softest, under the body; loads under-relaxed by the
// first-order filter and delayed two 20 ms steps, as the topics delay them. The loads must settle.
double coupledLoadChangeAtEnd(double filter_time_s) {
  nb::FlatParams values = nb::flattenYamlFile(std::string(NURSING_BED_SOURCE_DIR) + "/config/airbag_controller.yaml");
  for (const auto& kv : nb::flattenYamlFile(std::string(NURSING_BED_SOURCE_DIR) + "/config/airbag_tpu_double_100.yaml"))
    values["cell/" + kv.first] = kv.second;
  nb::AirbagCellParams cell_params = nb::airbagParamsFrom(values, "shipped configuration");
  cell_params.safety.command_timeout_s = 0.05;  // no commands: the cells hold their gas (mode SAFE)
  nb::BedGrid g;
  nb::BodyModel body(nb::PatientParams{}, g);
  std::vector<std::unique_ptr<nb::AirbagCell>> cells;
  for (int i = 0; i < g.cells(); ++i) {
    cells.emplace_back(new nb::AirbagCell(cell_params));
    cells.back()->resetToHeight(0.12, 10.6);
  }
  const double dt = 0.02;
  const double alpha = filter_time_s > 0.0 ? 1.0 - std::exp(-dt / filter_time_s) : 1.0;
  std::vector<double> filtered(g.cells(), 10.6), previous = filtered;
  std::deque<std::vector<double>> in_flight;
  double change_at_end = 0.0;
  const int steps = 300;  // 6 s
  for (int n = 0; n < steps; ++n) {
    std::vector<double> h(g.cells());
    for (int i = 0; i < g.cells(); ++i) h[i] = cells[i]->measurement().height_m;
    const nb::BodyState s = body.solve(h);
    for (int i = 0; i < g.cells(); ++i) filtered[i] += alpha * (0.6 + s.cell_load_n[i] - filtered[i]);
    in_flight.push_back(filtered);
    if (in_flight.size() > 2) {
      for (int i = 0; i < g.cells(); ++i) cells[i]->setLoad(in_flight.front()[i]);
      in_flight.pop_front();
    }
    for (auto& c : cells) c->advanceTo((n + 1) * dt);
    double change = 0.0;
    for (int i = 0; i < g.cells(); ++i) change = std::max(change, std::abs(filtered[i] - previous[i]));
    previous = filtered;
    if (n >= steps - 50) change_at_end = std::max(change_at_end, change);  // the last second
  }
  return change_at_end;
}

TEST(BodyModel, CoupledToHeldCellsTheFilteredLoadsSettle) {
  EXPECT_LT(coupledLoadChangeAtEnd(0.1), 1e-3);  // N per step, the simulator's default filter
  // (Without the filter the same loop rings for ever, ~2 N per step: doc/simulator.md.)
}

TEST(BodyModel, BadParametersAreRefusedWithAMessage) {
  nb::BedGrid g;
  auto refused = [&](nb::PatientParams p, const std::string& field) {
    EXPECT_NE(p.validate().message().find(field), std::string::npos) << p.validate().message();
    try {
      nb::BodyModel body(p, g);
      ADD_FAILURE() << "accepted bad " << field;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
    }
  };
  nb::PatientParams p;
  EXPECT_TRUE(p.validate().ok());
  p.mass_kg = -70.0;
  refused(p, "mass_kg");
  p = nb::PatientParams{};
  p.height_m = std::nan("");
  refused(p, "height_m");
  p = nb::PatientParams{};
  p.tissue_stiffness_pa_m = 0.0;
  refused(p, "tissue_stiffness_pa_m");
  p = nb::PatientParams{};
  p.head_clearance_m = -0.1;
  refused(p, "head_clearance_m");
  p = nb::PatientParams{};
  p.contact_resolution_m = 0.2;
  refused(p, "contact_resolution_m");
  p = nb::PatientParams{};
  p.max_roll_rad = 0.0;
  refused(p, "max_roll_rad");
  // A body whose trunk is off the bed.
  nb::BedGrid short_bed;
  short_bed.rows = 5;
  try {
    nb::BodyModel body(nb::PatientParams{}, short_bed);
    ADD_FAILURE() << "a 0.5 m bed accepted a 1.70 m patient";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("does not lie on the bed"), std::string::npos) << e.what();
  }
  // Wrong number of heights, non-finite height.
  nb::BodyModel body(nb::PatientParams{}, g);
  EXPECT_THROW(body.solve(std::vector<double>(10, 0.1)), std::invalid_argument);
  std::vector<double> h = flatBed(g);
  h[3] = std::nan("");
  EXPECT_THROW(body.solve(h), std::invalid_argument);
}

}  // namespace
