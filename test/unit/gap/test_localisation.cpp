// Where in time: re-anchored windows and the events found from them.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>

#include "nursing_bed/core/gap/localisation.h"
#include "nursing_bed/core/gap/log_import.h"
#include "nursing_bed/core/gap/replay.h"
#include "nursing_bed/core/physics/cell_params_io.h"

namespace nb = nursing_bed;

namespace {

const std::string kSource = NURSING_BED_SOURCE_DIR;
constexpr double kAirDensity = 1.2;  // [kg/m^3]
constexpr double kNoisePa = 30.0;

/// The test lung without its airway and with a heavier, more damped plate (0.1 kg, 100 N s/m):
/// the sensor at the chamber, since the windows restart from the measured pressure as the
/// chamber's (a series resistor's drop is not taken out of it).
nb::CellParams lungParams() {
  nb::CellParams p = nb::loadCellParamsYaml(kSource + "/config/lung_quicklung_c10.yaml");
  p.airway = nb::AirwayParams{};
  p.plate_mass_kg = 0.1;
  p.plate_damping_n_s_m = 100.0;
  return p;
}

/// A test lung ventilated in 3 s breaths (1 s in at 200 mL/s, 1 s out, 1 s still), the
/// setpoint high while gas goes in. Its pressure is the model's, plus 30 Pa of noise; the
/// recorded flow carries `bias_m3_s` more than went in from `on_s` to `off_s` (gas lost
/// between the meter and the lung).
nb::RunData plantedRun(double bias_m3_s, double on_s, double off_s) {
  nb::RunData run;
  run.name = "planted.csv";
  run.load_n = 0.0;
  for (int i = 0; i <= 1500; ++i) {
    const double t = 0.01 * i, phase = std::fmod(t, 3.0);
    const double q = phase < 1.0 ? 2e-4 : (phase < 2.0 ? -2e-4 : 0.0);
    run.t_s.push_back(t);
    run.mdot_in_kg_s.push_back(kAirDensity * q);
    run.p_gauge_pa.push_back(500.0);  // at rest at PEEP: where the replay starts
    run.h_m.push_back(NAN);
    run.p_setpoint_gauge_pa.push_back(phase < 1.0 ? 1500.0 : 500.0);
  }
  const nb::Replay truth = nb::replayRun(run, lungParams(), {});
  EXPECT_TRUE(truth.ok) << truth.message;
  std::mt19937 rng(11);
  std::normal_distribution<double> noise(0.0, kNoisePa);
  for (std::size_t i = 0; i < run.size(); ++i) {
    run.p_gauge_pa[i] = truth.p_gauge_pa[i] + noise(rng);
    if (run.t_s[i] >= on_s && run.t_s[i] < off_s) run.mdot_in_kg_s[i] += kAirDensity * bias_m3_s;
  }
  return run;
}

/// The longest event of `signal`, or one with onset NaN.
nb::GapEvent longest(const std::vector<nb::GapEvent>& events, const std::string& signal) {
  nb::GapEvent best;
  best.onset_s = best.end_s = NAN;
  for (const nb::GapEvent& e : events)
    if (e.signal == signal && !(e.end_s - e.onset_s <= best.end_s - best.onset_s)) best = e;
  return best;
}

}  // namespace

TEST(GapLocalisation, CycleStartsAreTheSetpointsRisingEdges) {
  const nb::RunData run = plantedRun(0.0, 0.0, 0.0);
  const std::vector<double> starts = nb::cycleStarts(run);
  // The run starts inside a breath (its start counts) and ends on a rising edge at 15 s.
  ASSERT_EQ(starts.size(), 6u);
  for (std::size_t k = 0; k < starts.size(); ++k) EXPECT_NEAR(starts[k], 3.0 * k, 0.011);
  nb::RunData flat = run;
  flat.p_setpoint_gauge_pa.clear();
  EXPECT_EQ(nb::cycleStarts(flat), std::vector<double>{0.0});
}

TEST(GapLocalisation, ACleanRunHasNoEvent) {
  const nb::RunData run = plantedRun(0.0, 0.0, 0.0);
  const std::vector<nb::GapEvent> events = nb::localiseInTime(run, lungParams(), {}, kNoisePa, 0.0);
  EXPECT_TRUE(events.empty()) << events.size() << " events, the first at " << events.front().onset_s << " s";
}

TEST(GapLocalisation, APlantedEventIsFoundWhereItWasSwitchedOnAndOff) {
  const double on_s = 4.6, off_s = 10.3;
  const nb::RunData run = plantedRun(2e-4, on_s, off_s);
  const std::vector<nb::GapEvent> events = nb::localiseInTime(run, lungParams(), {}, kNoisePa, 0.0);
  const nb::GapEvent e = longest(events, "pressure");
  EXPECT_NEAR(e.onset_s, on_s, 0.5);
  EXPECT_NEAR(e.end_s, off_s, 1.0);
  EXPECT_GT(e.peak_rms, 3.0);
  // Re-anchored: the error made inside the event does not carry past it.
  for (const nb::GapEvent& other : events) EXPECT_LT(other.end_s, off_s + 1.0);
}

TEST(GapLocalisation, BadOptionsAreRefusedByName) {
  const nb::RunData run = plantedRun(0.0, 0.0, 0.0);
  nb::LocalisationOptions options;
  options.window_s = 0.0;
  try {
    nb::localiseInTime(run, lungParams(), {}, kNoisePa, 0.0, options);
    FAIL() << "no error for a zero window";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("window_s"), std::string::npos) << e.what();
  }
}

TEST(GapLocalisation, TheObstructionRecordingIsLocalisedInTime) {
  // The lung's resistor turned to Off and back. In the trace the pressure's |second difference|
  // (median over 0.1 s) is about 0.2 cmH2O in normal breaths, above 5 times that for 0.35 s at
  // each breath's start, and for 4.98-13.38 s without a break: the obstruction, up to the
  // release of the lung's trapped gas (-120 to -230 mL/s at PEEP, over at 13.45 s).
  const nb::ImportMapping m = nb::loadImportMapping(kSource + "/config/import/respiraworks_obstruction.yaml");
  const nb::ImportedLog log = nb::importLog(m, kSource + "/test/data/respiraworks/2020-06-18-obstruction.dat");
  ASSERT_EQ(log.runs.size(), 1u);
  const nb::RunData& run = log.runs[0];
  const std::vector<nb::GapEvent> events =
      nb::localiseInTime(run, lungParams(), {}, nb::estimateNoise(run.p_gauge_pa), 0.0);
  // Every event lies within the obstruction, and its end is found within 1 s. Its onset is
  // found late: at the first breath's rise under obstruction (6.27 s), not where the ringing
  // at PEEP starts (4.98 s), which stays within 3 times the floor at PEEP.
  ASSERT_FALSE(events.empty());
  for (const nb::GapEvent& e : events) {
    EXPECT_GE(e.onset_s, 4.98 - 0.5);
    EXPECT_LE(e.end_s, 13.38 + 1.0);
  }
  EXPECT_NEAR(events.back().end_s, 13.38, 1.0);
  EXPECT_LT(events.front().onset_s, 6.5);
}
