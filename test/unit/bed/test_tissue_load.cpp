// Tissue-load metrics: the tolerance curve, region snapshots over hand-made contact points,
// the accumulated time above the threshold and dose, the configuration's checks, and the
// metrics over the body model on a flat bed.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "nursing_bed/core/bed/tissue_load.h"
#include "nursing_bed/core/physics/units.h"

namespace nb = nursing_bed;

namespace {

constexpr double kMmHg = nb::kPaPerMmHg;

/// A curve easy to compute by hand: 100 mmHg for 4 h, allowed time ~ 1/p^2, floor 32 mmHg.
nb::TissueLoadParams handParams() {
  nb::TissueLoadParams p;
  p.threshold_pa = 32.0 * kMmHg;
  p.tolerance.reference_pressure_pa = 100.0 * kMmHg;
  p.tolerance.reference_time_s = 4.0 * 3600.0;
  p.tolerance.exponent = 2.0;
  p.tolerance.floor_pressure_pa = 32.0 * kMmHg;
  return p;
}

std::vector<nb::TissueRegion> oneRegion() { return {{"patch", {0}, 0.0, 1.0, -1.0, 1.0}}; }

nb::RegionLoad constantLoad(double pressure_pa, double area_m2) {
  nb::RegionLoad l;
  l.peak_pressure_pa = l.mean_pressure_pa = pressure_pa;
  l.contact_area_m2 = area_m2;
  l.force_n = pressure_pa * area_m2;
  l.margin_m = 0.05;
  return l;
}

nb::ContactPoint point(int segment, double from_vertex_m, double lateral_m, double pressure_pa, double skin_m) {
  nb::ContactPoint p;
  p.segment = segment;
  p.from_vertex_m = from_vertex_m;
  p.lateral_m = lateral_m;
  p.half_width_m = 0.1;
  p.area_m2 = 1e-4;
  p.pressure_pa = pressure_pa;
  p.skin_height_m = skin_m;
  return p;
}

TEST(ToleranceCurve, AllowsTheReferenceTimeAtTheReferencePressureAndLessAbove) {
  const nb::ToleranceCurve c = handParams().tolerance;
  EXPECT_DOUBLE_EQ(c.allowedTimeS(100.0 * kMmHg), 4.0 * 3600.0);
  EXPECT_DOUBLE_EQ(c.allowedTimeS(200.0 * kMmHg), 3600.0);        // (1/2)^2 of 4 h
  EXPECT_DOUBLE_EQ(c.allowedTimeS(50.0 * kMmHg), 16.0 * 3600.0);  // 2^2 times 4 h
  EXPECT_TRUE(std::isinf(c.allowedTimeS(32.0 * kMmHg)));          // at the floor: no limit
  EXPECT_TRUE(std::isinf(c.allowedTimeS(0.0)));
}

TEST(ToleranceCurve, DefaultsPassThroughTheCitedPointsOfTheCurve) {
  const nb::ToleranceCurve c;
  EXPECT_NEAR(c.allowedTimeS(500.0 * kMmHg), 3600.0, 1.0);
  EXPECT_NEAR(c.allowedTimeS(70.0 * kMmHg) / 3600.0, 12.0, 0.1);
}

TEST(TissueLoadMeter, ConstantPressureForAKnownTimeGivesTheKnownDose) {
  nb::TissueLoadMeter meter(handParams(), oneRegion());
  // 100 mmHg over 20 cm^2 for 2 h, sampled every second: half of the 4 h allowed.
  for (int i = 0; i < 7200; ++i) meter.sample({constantLoad(100.0 * kMmHg, 0.002)}, 1.0);
  const nb::RegionDose& d = meter.doses()[0];
  EXPECT_NEAR(d.dose, 0.5, 1e-9);
  EXPECT_NEAR(d.time_above_s, 7200.0, 1e-6);
  EXPECT_NEAR(meter.observedS(), 7200.0, 1e-6);
  EXPECT_DOUBLE_EQ(d.now.contact_area_m2, 0.002);
  EXPECT_NEAR(d.now.force_n, 100.0 * kMmHg * 0.002, 1e-9);
  EXPECT_DOUBLE_EQ(d.max_peak_pressure_pa, 100.0 * kMmHg);
  EXPECT_DOUBLE_EQ(d.min_margin_m, 0.05);
}

TEST(TissueLoadMeter, ARegionAboveTheThresholdHalfTheTimeCountsHalfTheTime) {
  nb::TissueLoadMeter meter(handParams(), oneRegion());
  // 10 s at 200 mmHg, 10 s at 20 mmHg, five times: 50 s of 100 above, and only the 200 mmHg
  // intervals add dose (50 s of the 1 h allowed there).
  for (int cycle = 0; cycle < 5; ++cycle) {
    for (int i = 0; i < 10; ++i) meter.sample({constantLoad(200.0 * kMmHg, 0.001)}, 1.0);
    for (int i = 0; i < 10; ++i) meter.sample({constantLoad(20.0 * kMmHg, 0.001)}, 1.0);
  }
  const nb::RegionDose& d = meter.doses()[0];
  EXPECT_NEAR(d.time_above_s / meter.observedS(), 0.5, 1e-12);
  EXPECT_NEAR(d.dose, 50.0 / 3600.0, 1e-12);
  EXPECT_DOUBLE_EQ(d.now.peak_pressure_pa, 20.0 * kMmHg);
  EXPECT_DOUBLE_EQ(d.max_peak_pressure_pa, 200.0 * kMmHg);
  EXPECT_NEAR(d.peak_integral_pa_s / meter.observedS(), 110.0 * kMmHg, 1e-9);  // the time-mean peak
}

TEST(TissueLoadMeter, TheMeanPeakDoesNotJumpWhereThePeakCrossesTheThreshold) {
  // A peak a hair above the threshold and one a hair below: share and dose jump from all to
  // nothing, the time-mean peak moves by the hair.
  nb::TissueLoadMeter above(handParams(), oneRegion()), below(handParams(), oneRegion());
  const double threshold_pa = handParams().threshold_pa;
  for (int i = 0; i < 600; ++i) {
    above.sample({constantLoad(threshold_pa + 10.0, 0.001)}, 1.0);
    below.sample({constantLoad(threshold_pa - 10.0, 0.001)}, 1.0);
  }
  EXPECT_NEAR(above.doses()[0].time_above_s, 600.0, 1e-9);
  EXPECT_EQ(below.doses()[0].time_above_s, 0.0);
  EXPECT_NEAR((above.doses()[0].peak_integral_pa_s - below.doses()[0].peak_integral_pa_s) / 600.0, 20.0, 1e-9);
}

TEST(TissueLoadMeter, ResetClearsTheAccumulatedDose) {
  nb::TissueLoadMeter meter(handParams(), oneRegion());
  meter.sample({constantLoad(100.0 * kMmHg, 0.001)}, 3600.0);
  EXPECT_GT(meter.doses()[0].dose, 0.0);
  meter.reset();
  EXPECT_EQ(meter.doses()[0].dose, 0.0);
  EXPECT_EQ(meter.doses()[0].time_above_s, 0.0);
  EXPECT_EQ(meter.observedS(), 0.0);
  EXPECT_TRUE(std::isnan(meter.doses()[0].min_margin_m));
}

TEST(TissueLoadMeter, RefusesABadSampleAndKeepsItsState) {
  nb::TissueLoadMeter meter(handParams(), oneRegion());
  meter.sample({constantLoad(100.0 * kMmHg, 0.001)}, 60.0);
  const double dose = meter.doses()[0].dose;
  try {
    meter.sample({constantLoad(1.0, 1.0), constantLoad(1.0, 1.0)}, 1.0);
    FAIL() << "two loads for one region accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("2 region loads for 1 regions"), std::string::npos) << e.what();
  }
  EXPECT_THROW(meter.sample({constantLoad(100.0 * kMmHg, 0.001)}, -1.0), std::invalid_argument);
  EXPECT_THROW(meter.sample({constantLoad(100.0 * kMmHg, 0.001)}, NAN), std::invalid_argument);
  EXPECT_EQ(meter.doses()[0].dose, dose);
  EXPECT_EQ(meter.observedS(), 60.0);
}

TEST(TissueLoadParams, RefusesBadValuesNamingEach) {
  nb::TissueLoadParams p = handParams();
  p.threshold_pa = -1.0;
  p.tolerance.exponent = 0.0;
  p.tolerance.reference_time_s = NAN;
  const nb::Status s = p.validate();
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("threshold_pa"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("tolerance/exponent"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("tolerance/reference_time_s"), std::string::npos) << s.message();

  nb::TissueLoadParams floor_high = handParams();
  floor_high.tolerance.floor_pressure_pa = 200.0 * kMmHg;  // above the reference point
  EXPECT_NE(floor_high.validate().message().find("tolerance/floor_pressure_pa"), std::string::npos);
  try {
    nb::TissueLoadMeter meter(floor_high, oneRegion());
    FAIL() << "a floor above the reference pressure accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("tolerance/floor_pressure_pa"), std::string::npos) << e.what();
  }
  EXPECT_THROW(nb::TissueLoadMeter(handParams(), {}), std::invalid_argument);
  EXPECT_TRUE(nb::TissueLoadParams{}.validate().ok());
}

TEST(TissueLoadParams, YamlWithAnUnknownOrNonNumericKeyIsRefusedByName) {
  nb::TissueLoadParams p;
  try {
    nb::applyFlatParams(nb::flattenYamlText("tolerance:\n  exponnt: 2\n", "test.yaml"), "test.yaml",
                        nb::tissueLoadParamFields(), &p);
    FAIL() << "unknown key accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("tolerance/exponnt"), std::string::npos) << e.what();
  }
  try {
    nb::applyFlatParams(nb::flattenYamlText("threshold_pa: high\n", "test.yaml"), "test.yaml",
                        nb::tissueLoadParamFields(), &p);
    FAIL() << "non-numeric value accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("threshold_pa"), std::string::npos) << e.what();
  }
  nb::applyFlatParams(nb::flattenYamlText("tolerance:\n  exponent: 2\n", "test.yaml"), "test.yaml",
                      nb::tissueLoadParamFields(), &p);
  EXPECT_EQ(p.tolerance.exponent, 2.0);
}

TEST(TissueLoadParams, ShippedConfigurationIsValidAndMatchesTheDefaults) {
  nb::TissueLoadParams p;
  p.threshold_pa = 0.0;  // every key must be in the file
  p.tolerance = nb::ToleranceCurve{0.0, 0.0, 0.0, 0.0};
  const std::string path = std::string(NURSING_BED_SOURCE_DIR) + "/config/tissue_load.yaml";
  nb::applyFlatParams(nb::flattenYamlFile(path), path, nb::tissueLoadParamFields(), &p);
  EXPECT_TRUE(p.validate().ok()) << p.validate().message();
  const nb::TissueLoadParams d;
  EXPECT_EQ(p.threshold_pa, d.threshold_pa);
  EXPECT_EQ(p.tolerance.reference_pressure_pa, d.tolerance.reference_pressure_pa);
  EXPECT_EQ(p.tolerance.reference_time_s, d.tolerance.reference_time_s);
  EXPECT_EQ(p.tolerance.exponent, d.tolerance.exponent);
  EXPECT_EQ(p.tolerance.floor_pressure_pa, d.tolerance.floor_pressure_pa);
}

TEST(MeasureRegions, TakesPeakMeanAreaAndMarginOverTheRegionsPointsOnly) {
  // Region: segment 3 from 0.5 to 1.0 m along a 1 m body, the middle of its width.
  const std::vector<nb::TissueRegion> regions = {{"r", {3}, 0.5, 1.0, -0.5, 0.5}};
  const std::vector<nb::ContactPoint> points = {
      point(3, 0.6, 0.00, 1000.0, 0.04), point(3, 0.7, 0.02, 2000.0, 0.03),
      point(3, 0.8, -0.02, 0.0, 0.02),                                       // in the region, no contact: margin only
      point(3, 0.9, 0.00, 3000.0, 0.05), point(3, 0.4, 0.00, 9000.0, 0.00),  // before the window along the body
      point(3, 0.7, 0.08, 9000.0, 0.00),  // outside the middle half (0.8 of the half width)
      point(2, 0.7, 0.00, 9000.0, 0.00),  // another segment
  };
  const std::vector<nb::RegionLoad> loads = nb::measureRegions(points, regions, 1.0);
  ASSERT_EQ(loads.size(), 1u);
  EXPECT_DOUBLE_EQ(loads[0].peak_pressure_pa, 3000.0);
  EXPECT_NEAR(loads[0].contact_area_m2, 3e-4, 1e-15);
  EXPECT_NEAR(loads[0].force_n, 0.6, 1e-12);
  EXPECT_NEAR(loads[0].mean_pressure_pa, 2000.0, 1e-9);
  EXPECT_DOUBLE_EQ(loads[0].margin_m, 0.02);
}

TEST(MeasureRegions, ARegionWithoutPointsHasNoLoadAndNoMargin) {
  const std::vector<nb::TissueRegion> regions = {{"r", {5}, 0.0, 1.0, -1.0, 1.0}};
  const std::vector<nb::RegionLoad> loads = nb::measureRegions({point(3, 0.5, 0.0, 1000.0, 0.05)}, regions, 1.0);
  EXPECT_EQ(loads[0].peak_pressure_pa, 0.0);
  EXPECT_EQ(loads[0].contact_area_m2, 0.0);
  EXPECT_EQ(loads[0].mean_pressure_pa, 0.0);
  EXPECT_TRUE(std::isnan(loads[0].margin_m));
}

int regionIndex(const std::string& name) {
  const auto& r = nb::defaultTissueRegions();
  for (std::size_t i = 0; i < r.size(); ++i)
    if (r[i].name == name) return static_cast<int>(i);
  return -1;
}

TEST(MeasureRegions, OnTheBodyModelAgreesWithItsRegionalPeaks) {
  nb::BedGrid g;
  nb::BodyModel body(nb::PatientParams{}, g);
  const std::vector<double> heights(g.cells(), 0.10);
  const nb::BodyState s = body.solve(heights);
  const std::vector<nb::ContactPoint> map = body.contactMap(heights);
  const std::vector<nb::RegionLoad> loads = nb::measureRegions(map, nb::defaultTissueRegions(), 1.70);
  for (const auto& r : nb::defaultTissueRegions()) {
    ASSERT_GE(regionIndex(r.name), 0);
    for (int seg : r.segments) ASSERT_GE(seg, 0) << r.name;
  }
  const auto& L = [&](const char* name) { return loads[regionIndex(name)]; };
  EXPECT_NEAR(L("sacrum").peak_pressure_pa, s.peak_pressure_pa.sacrum, 1e-9);
  EXPECT_NEAR(L("occiput").peak_pressure_pa, s.peak_pressure_pa.occiput, 1e-9);
  EXPECT_NEAR(std::max(L("right_heel").peak_pressure_pa, L("left_heel").peak_pressure_pa), s.peak_pressure_pa.heels,
              1e-9);
  // The whole map carries the weight; the regions a part of it.
  double total = 0.0, regions = 0.0;
  for (const nb::ContactPoint& p : map) total += p.pressure_pa * p.area_m2;
  for (const nb::RegionLoad& l : loads) regions += l.force_n;
  EXPECT_NEAR(total, body.weightN(), 1e-6 * body.weightN());
  EXPECT_LT(regions, total);
  // The head rests on the occiput alone: its region carries the head and neck's weight.
  EXPECT_NEAR(L("occiput").force_n, 0.081 * body.weightN(), 1e-6 * body.weightN());
  // Symmetric, loaded, and the skin above the base but below the cell tops.
  EXPECT_NEAR(L("right_heel").force_n, L("left_heel").force_n, 1e-9);
  EXPECT_NEAR(L("right_trochanter").force_n, L("left_trochanter").force_n, 1e-9);
  for (const nb::RegionLoad& l : loads) {
    EXPECT_GT(l.contact_area_m2, 0.0);
    EXPECT_GT(l.margin_m, 0.0);
    EXPECT_LE(l.margin_m, 0.10 + 1e-12);
  }
}

TEST(MeasureRegions, ABodyOnEmptyCellsHasBottomedOut) {
  nb::BedGrid g;
  nb::BodyModel body(nb::PatientParams{}, g);
  std::vector<double> heights(g.cells(), 0.10);
  for (int r : body.pelvisRows())
    for (int c = 0; c < g.cols; ++c) heights[g.id(r, c)] = 0.0;
  body.solve(heights);
  const std::vector<nb::RegionLoad> loads =
      nb::measureRegions(body.contactMap(heights), nb::defaultTissueRegions(), 1.70);
  EXPECT_GT(loads[regionIndex("occiput")].margin_m, 0.05);
  // Over the empty rows the sacrum rests on the bed base.
  EXPECT_NEAR(loads[regionIndex("sacrum")].margin_m, 0.0, 1e-12);
}

}  // namespace
