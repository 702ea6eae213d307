// The observer's parts on their own: the valve delay line, the flat-cell test and the plate's
// weight bound.
#include <gtest/gtest.h>

#include <cmath>

#include "nursing_bed/core/observer/reanchor_detector.h"
#include "nursing_bed/core/observer/valve_delay_line.h"
#include "nursing_bed/core/observer/weight_bound.h"
#include "nursing_bed/core/physics/cell_model.h"

namespace nb = nursing_bed;

namespace {

nb::ObserverInputs openings(double inlet, double vent) {
  nb::ObserverInputs in;
  in.valves.inlet = inlet;
  in.valves.vent = vent;
  return in;
}

}  // namespace

TEST(ValveDelayLine, ACommandActsTheDeadTimeLaterOverTheSameSpan) {
  nb::ValveDelayLine none;
  EXPECT_EQ(none.delayed(openings(0.7, 0.0), 0.005).valves.inlet, 0.7) << "no dead time: as given";
  nb::ValveDelayLine line(0.01);
  EXPECT_EQ(line.delayed(openings(1.0, 0.0), 0.005).valves.inlet, 0.0) << "shut before the first command";
  EXPECT_EQ(line.delayed(openings(0.0, 1.0), 0.005).valves.inlet, 0.0);
  EXPECT_NEAR(line.delayed(openings(0.0, 0.0), 0.005).valves.inlet, 1.0, 1e-12);
  // A late tick (10 ms) spans the vent's 5 ms command and the shut one after it.
  const nb::ObserverInputs late = line.delayed(openings(0.0, 0.0), 0.01);
  EXPECT_NEAR(late.valves.vent, 0.5, 1e-12);
  line.reset();
  EXPECT_EQ(line.delayed(openings(1.0, 1.0), 0.005).valves.vent, 0.0) << "a reset forgets the commands held";
}

TEST(ReanchorDetector, FindsAFlatCellOnlyWithItsInletShutForTheTestsTime) {
  const double dt = 0.01;
  nb::ReanchorDetector test(0.5, dt, 40.0);
  double mean = 1e9;
  double t = 0.0;
  for (; t < 1.0; t += dt) EXPECT_FALSE(test.update(t, openings(0.3, 0.0), 5.0, &mean)) << "the inlet passes gas";
  bool found = false;
  const double start = t;
  for (; t < 2.0 && !found; t += dt) found = test.update(t, openings(0.0, 1.0), 5.0, &mean);
  EXPECT_TRUE(found);
  EXPECT_NEAR(t - start, 0.1 + 0.5, 2 * dt) << "the vent's opening edge settles 0.1 s, then the test's time";
  EXPECT_NEAR(mean, 5.0, 1e-9);
  nb::ObserverInputs vacuum = openings(0.0, 1.0);
  vacuum.vent_back_pressure_pa = -5000.0;
  nb::ReanchorDetector to_vacuum(0.5, dt, 40.0);
  for (t = 0.0; t < 1.0; t += dt) EXPECT_FALSE(to_vacuum.update(t, vacuum, 5.0, &mean)) << "venting into a vacuum";
}

TEST(ReanchorDetector, AVentOpenedAndShutInTurnNeverFindsALiftedLightPlateFlat) {
  // A light plate lifted reads 25 Pa, and each vent edge rings it below ambient for 40 ms: a
  // vent a lossy link opens and shuts every 0.2 s (the terminal's watchdog shutting what a
  // write opened) would hold the test's mean under the flat pressure. The test waits out each
  // edge; the same plate vented steadily to flat (0 Pa) is found.
  const double dt = 0.01, flat_pa = 10.0;
  nb::ReanchorDetector test(0.5, dt, flat_pa);
  test.expectFlatUntil(100.0);
  double mean = 0.0, since_edge = 0.0;
  bool found = false, open = false;
  for (double t = 0.0; t < 10.0 && !found; t += dt, since_edge += dt) {
    if (since_edge >= 0.2 - 1e-9) open = !open, since_edge = 0.0;
    const double p = since_edge < 0.04 ? -60.0 : 25.0;
    found = test.update(t, openings(0.0, open ? 1.0 : 0.0), p, &mean);
  }
  EXPECT_FALSE(found) << "a lifted plate rung by vent edges is not flat (mean " << mean << " Pa)";
  double t = 10.0;
  for (; t < 12.0 && !found; t += dt) found = test.update(t, openings(0.0, 1.0), t < 10.3 ? 25.0 : 0.0, &mean);
  EXPECT_TRUE(found) << "vented steadily to flat";
}

TEST(ReanchorDetector, BelowAmbientCountsOnlyWhileAFlatCellIsExpected) {
  const double dt = 0.01;
  nb::ReanchorDetector test(0.5, dt, 40.0);
  double mean = 0.0;
  bool found = false;
  for (double t = 0.0; t < 2.0; t += dt) found = found || test.update(t, openings(0.0, 0.0), -100.0, &mean);
  EXPECT_FALSE(found) << "-100 Pa is no flat cell unless the cell is being tested";
  test.expectFlatUntil(5.0);
  for (double t = 2.0; t < 3.0 && !found; t += dt) found = test.update(t, openings(0.0, 0.0), -100.0, &mean);
  EXPECT_TRUE(found);
  EXPECT_EQ(test.flatPressure(), 40.0);
}

TEST(WeightBound, ThePlateAloneRestsHigherAtHigherPressureAndWindowsEndOnTime) {
  const nb::CellParams cell;
  const auto structure = nb::makeCellStructure(cell);
  nb::WeightBound bound(0.5);
  bound.tabulate(*structure, cell.plate_mass_kg * nb::kGravity, structure->heightLimit(structure->restShape().data()));
  const double lowest = bound.lowestLiftedPressure();
  ASSERT_TRUE(std::isfinite(lowest));
  EXPECT_GT(lowest, 0.0);
  EXPECT_LE(bound.plateAloneHeight(lowest), bound.plateAloneHeight(2.0 * lowest));
  EXPECT_TRUE(std::isinf(bound.plateAloneHeight(1e7))) << "beyond the table's top: no bound";

  nb::ReadingNoise noise(10.0, 20.0, 24000.0);
  const double dt = 0.01;
  double mean = 0.0, se = 0.0;
  int windows = 0;
  double t = 0.0;
  // A settling window, then a mean at the first reading after it and one per window after.
  for (; t < 1.2 - 1e-9; t += dt) windows += bound.quietMean(100.0, true, true, dt, noise, &mean, &se);
  EXPECT_EQ(windows, 2);
  EXPECT_NEAR(mean, 100.0, 1e-9);
  EXPECT_GT(se, 0.0);
  EXPECT_FALSE(bound.quietMean(100.0, true, false, dt, noise, &mean, &se)) << "a valve opened: the window restarts";
  for (t = 0.0; t < 0.9; t += dt) windows += bound.quietMean(100.0, true, true, dt, noise, &mean, &se);
  EXPECT_EQ(windows, 3) << "settled again after the opening: one mean so far";
}
