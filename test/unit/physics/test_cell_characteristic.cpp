// The tabulated characteristic: the resting height inverts the equilibria's adiabatic
// invariant, and the relaxed cell gives the load and volume its two queries give.
#include <gtest/gtest.h>

#include <cmath>

#include "nursing_bed/core/physics/cell_characteristic.h"

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
  double stretch = 0.0;  // no warm start yet
  for (double h : {0.0, 0.03, 0.08, 0.13}) {
    for (double p : {500.0, 3000.0, 9000.0}) {
      const nb::CellCharacteristic::RelaxedCell r = c.relaxedAt(h, p);
      EXPECT_EQ(r.load_n, c.loadAt(h, p)) << h << " " << p;
      EXPECT_EQ(r.volume_m3, c.relaxedVolume(h, p)) << h << " " << p;
      // A warm start from the previous state's stretch finds the same film.
      const nb::CellCharacteristic::RelaxedCell warm = c.relaxedAt(h, p, &stretch);
      EXPECT_NEAR(warm.volume_m3, r.volume_m3, 1e-9 * r.volume_m3) << h << " " << p;
      EXPECT_NEAR(warm.load_n, r.load_n, 1e-6 * r.load_n + 1e-9) << h << " " << p;
      EXPECT_GT(stretch, 0.0);
    }
  }
}

}  // namespace
