// The tabulated characteristic: the resting height inverts the equilibria's adiabatic
// invariant, and the relaxed cell gives the load and volume its two queries give.
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "nursing_bed/core/physics/cell_characteristic.h"
#include "nursing_bed/core/physics/cell_params_io.h"

namespace nb = nursing_bed;

namespace {

const nb::CellCharacteristic& characteristic() {
  static const auto c = nb::CellCharacteristic::shared(nb::CellParams{});
  return *c;
}

// The invariant of the tabulated rest at (h, load).
double restInvariant(double height_m, double load_n) {
  const nb::CellCharacteristic& c = characteristic();
  return c.invariant(c.pressureAt(height_m, load_n), c.volumeAt(height_m, load_n));
}

TEST(CellCharacteristic, RestingHeightInvertsTheInvariantOfTheRests) {
  const nb::CellCharacteristic& c = characteristic();
  const double step = c.heightStep();
  // At the table's heights and loads the rest's invariant is a node of the table: exact to
  // rounding.
  for (double load : {1.0, 10.0, 15.0, 35.0}) {
    const int top = static_cast<int>(std::lround(c.maxHeight(load) / step));
    ASSERT_GT(top, 100) << load;
    for (int i = 1; i < top; i += 7)
      EXPECT_NEAR(c.restingHeight(restInvariant(i * step, load), load), i * step, 1e-12) << load << " N, node " << i;
  }
  // Between them the table interpolates the invariant, not pressure and volume apart: close
  // where the invariant is smooth, below the film's stiffening in the top 15 steps.
  for (double load : {0.6, 10.6, 15.6, 35.3}) {
    const double top = c.maxHeight(load);
    for (double h = 10.4 * step; h < top - 15 * step; h += 13 * step)
      EXPECT_NEAR(c.restingHeight(restInvariant(h, load), load), h, 0.02 * step) << load << " N, h " << h;
  }
}

TEST(CellCharacteristic, RestingHeightStaysWithinTheTable) {
  const nb::CellCharacteristic& c = characteristic();
  const double load = 10.6;
  const double flat = restInvariant(0.0, load), top = c.maxHeight(load);
  EXPECT_EQ(c.restingHeight(0.5 * flat, load), 0.0);  // less gas than the flat rest holds
  EXPECT_EQ(c.restingHeight(flat, load), 0.0);
  EXPECT_DOUBLE_EQ(c.restingHeight(10.0 * restInvariant(top, load), load), top);  // more than the top's
  EXPECT_DOUBLE_EQ(c.restingHeight(std::nan(""), load), top);                     // nothing bounds an unknown one
  // More gas never rests lower.
  double last = 0.0;
  for (double k = flat; k < restInvariant(top, load); k *= 1.01) {
    const double h = c.restingHeight(k, load);
    EXPECT_GE(h, last) << k;
    last = h;
  }
}

TEST(CellCharacteristic, RelaxedCellIsTheLoadAndVolumeOfOneSolve) {
  const nb::CellCharacteristic& c = characteristic();
  nb::CellCharacteristic::Shape shape = c.restShape();
  for (double h : {0.0, 0.03, 0.08, 0.13}) {
    for (double p : {500.0, 3000.0, 9000.0}) {
      const nb::CellCharacteristic::RelaxedCell r = c.relaxedAt(h, p);
      EXPECT_EQ(r.load_n, c.loadAt(h, p)) << h << " " << p;
      EXPECT_EQ(r.volume_m3, c.relaxedVolume(h, p)) << h << " " << p;
      // A warm start from the previous state's shape finds the same film.
      const nb::CellCharacteristic::RelaxedCell warm = c.relaxedAt(h, p, &shape);
      EXPECT_NEAR(warm.volume_m3, r.volume_m3, 1e-9 * r.volume_m3) << h << " " << p;
      EXPECT_NEAR(warm.load_n, r.load_n, 1e-6 * r.load_n + 1e-9) << h << " " << p;
      EXPECT_GT(shape[0], 0.0);
      EXPECT_EQ(warm.branch, 0);
    }
  }
}

// The shipped FE cell's fold (doc/cell_geometry.md): under 10.6 N at 4.87 kPa the FE bag rests
// at 84.4 mm on the way up (fold shut) and at 100.5 mm on the way down (still open). The
// characteristic has both branches, and a film carried between calls stays on its side.
TEST(CellCharacteristic, AFoldedCellHasARisingAndAFallingBranchAndKeepsItsSide) {
  const auto c = nb::CellCharacteristic::shared(
      nb::loadCellParamsYaml(std::string(NURSING_BED_SOURCE_DIR) + "/config/airbag_tpu_double_100_fe3d.yaml"));
  ASSERT_EQ(c->branches(), 2);
  EXPECT_EQ(characteristic().branches(), 1);  // the pillow has no fold
  const double load = 10.6, p = 1e3 * (1.0 + 29.0 * 2 / 15);
  // Each branch rests within 3 mm of the FE's height (the branch's p(h) brackets the pressure).
  EXPECT_LT(c->pressureAt(0.0814, load, 0), p);
  EXPECT_GT(c->pressureAt(0.0874, load, 0), p);
  EXPECT_LT(c->pressureAt(0.0975, load, 1), p);
  EXPECT_GT(c->pressureAt(0.1035, load, 1), p);

  // Up to 20 kPa at 120 mm (the fold opens), then back to 4.87 kPa at 100.5 mm: still open.
  nb::CellCharacteristic::Shape shape = c->restShape();
  EXPECT_EQ(c->relaxedAt(0.0844, p, &shape).branch, 0);
  EXPECT_EQ(c->relaxedAt(0.12, 20e3, &shape).branch, 1);
  const nb::CellCharacteristic::RelaxedCell open = c->relaxedAt(0.1005, p, &shape);
  EXPECT_EQ(open.branch, 1);
  EXPECT_NEAR(open.load_n, load, 1.0);
  EXPECT_EQ(c->relaxedAt(0.1005, p).branch, 0);  // from the rest shape: shut
  // Closed there, the open cell rests where it is; the rising branch would put it elsewhere.
  const double k = c->invariant(p, open.volume_m3);
  EXPECT_NEAR(c->restingHeight(k, load, 1), 0.1005, 2e-3);
  EXPECT_GT(std::fabs(c->restingHeight(k, load, 0) - 0.1005), 3e-3);
  // Far below the fold's band it shuts again.
  EXPECT_EQ(c->relaxedAt(0.03, 500.0, &shape).branch, 0);
}

// Under 14 N the rising fold has no closed rest between about 105 and 107 mm (its invariant
// dips there: the plate snaps over it); the pillow has none at the bed's heights.
TEST(CellCharacteristic, GapBetweenFindsTheFoldsSnapAndNothingElse) {
  const auto c = nb::CellCharacteristic::shared(
      nb::loadCellParamsYaml(std::string(NURSING_BED_SOURCE_DIR) + "/config/airbag_tpu_double_100_fe3d.yaml"));
  EXPECT_TRUE(c->gapBetween(0.104, 0.108, 14.0, 0));
  EXPECT_TRUE(c->gapBetween(0.108, 0.104, 14.0, 0));  // either order
  EXPECT_FALSE(c->gapBetween(0.095, 0.103, 14.0, 0));
  EXPECT_FALSE(c->gapBetween(0.110, 0.130, 14.0, 0));
  EXPECT_FALSE(c->gapBetween(0.100, 0.110, 14.0, 1));  // the open side rises through it
  for (double load : {0.6, 10.6, 20.6, 30.0}) EXPECT_FALSE(characteristic().gapBetween(0.02, 0.15, load));
}

}  // namespace
