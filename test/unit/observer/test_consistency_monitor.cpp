// The consistency monitor (ConsistencyMonitor) on synthetic readings in simulated time: quiet
// holds and valve pulses pass, a step, a frozen sensor and a large weight-bound correction
// are flagged within their times, and clear() starts it again.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <stdexcept>
#include <string>

#include "nursing_bed/core/observer/consistency_monitor.h"

namespace nb = nursing_bed;

namespace {

constexpr double kPeriod = 0.005;
constexpr double kAdcStepPa = 12.2;

/// Readings of a 12-bit sensor (noise 10 Pa, then the ADC step) around a pressure.
class Sensor {
 public:
  explicit Sensor(unsigned seed) : rng_(seed) {}
  double read(double pressure_pa) { return kAdcStepPa * std::round((pressure_pa + noise_(rng_)) / kAdcStepPa); }

 private:
  std::mt19937 rng_;
  std::normal_distribution<double> noise_{0.0, 10.0};
};

nb::ConsistencySample sample(double pressure_pa, bool shut) {
  nb::ConsistencySample s;
  s.gauge_pressure_pa = pressure_pa;
  s.noise_sd_pa = 10.0;
  s.valves_shut = shut;
  return s;
}

/// Runs `seconds` of holds (valves shut) at `pressure_pa` with a valve pulse every
/// `pulse_every_s`; returns the time of the first inconsistency (-1: none).
double runHolds(nb::ConsistencyMonitor* monitor, Sensor* sensor, double seconds, double pressure_pa,
                double pulse_every_s, double t0 = 0.0) {
  for (double t = t0; t < t0 + seconds; t += kPeriod) {
    const bool pulse = std::fmod(t, pulse_every_s) < 0.02;
    if (monitor->update(sample(sensor->read(pressure_pa), !pulse), kPeriod)) return t;
  }
  return -1.0;
}

}  // namespace

TEST(ConsistencyMonitorParams, RefusesBadValuesNamingThem) {
  auto expectRefused = [](const char* key, double nb::ConsistencyMonitorParams::*field, double value) {
    nb::ConsistencyMonitorParams p;
    p.*field = value;
    EXPECT_NE(p.validate().message().find(key), std::string::npos) << key << " " << value;
    EXPECT_THROW(nb::ConsistencyMonitor{p}, std::invalid_argument) << key;
  };
  expectRefused("frozen_s", &nb::ConsistencyMonitorParams::frozen_s, -1.0);
  expectRefused("reference_time_s", &nb::ConsistencyMonitorParams::reference_time_s, 0.0);
  expectRefused("cusum_threshold_pa_s", &nb::ConsistencyMonitorParams::cusum_threshold_pa_s, std::nan(""));
  expectRefused("surprise_m", &nb::ConsistencyMonitorParams::surprise_m, -0.001);
  EXPECT_TRUE(nb::ConsistencyMonitorParams{}.validate().ok());
}

TEST(ConsistencyMonitor, TenMinutesOfNoisyHoldsAndValvePulsesRaiseNothing) {
  for (const double pressure : {0.0, 550.0, 3000.0, 15000.0}) {
    nb::ConsistencyMonitor monitor;
    Sensor sensor(7);
    EXPECT_LT(runHolds(&monitor, &sensor, 600.0, pressure, 3.0), 0.0) << pressure << " Pa: " << monitor.reason();
    EXPECT_FALSE(monitor.inconsistent());
  }
}

TEST(ConsistencyMonitor, APressureStepUnderASettledPlateIsFlaggedWithinASecond) {
  for (const double step : {1100.0, -900.0, 400.0}) {  // below the jump test: the CUSUM
    nb::ConsistencyMonitor monitor;
    Sensor sensor(3);
    ASSERT_LT(runHolds(&monitor, &sensor, 5.0, 1500.0, 100.0), 0.0);
    const double flagged_at = runHolds(&monitor, &sensor, 5.0, 1500.0 + step, 100.0, 5.0);
    ASSERT_GE(flagged_at, 5.0) << step << " Pa";
    EXPECT_LE(flagged_at - 5.0, 1.0) << step << " Pa";
    EXPECT_NE(monitor.reason().find("departs from the hold"), std::string::npos) << monitor.reason();
  }
}

TEST(ConsistencyMonitor, ASensorJumpIsFlaggedAtItsFirstReadingAPhysicalRiseIsNot) {
  nb::ConsistencyMonitor monitor;
  Sensor sensor(9);
  ASSERT_LT(runHolds(&monitor, &sensor, 3.0, 1500.0, 100.0), 0.0);
  // A load of 36 N dropped onto the plate: the pressure rises 3.6 kPa over a quarter of the
  // loaded plate's period (~20 ms), then the hold goes on at the new pressure.
  for (int i = 1; i <= 4; ++i)
    EXPECT_FALSE(monitor.update(sample(sensor.read(1500.0 + 900.0 * i), true), kPeriod)) << monitor.reason();
  monitor.clear();
  ASSERT_LT(runHolds(&monitor, &sensor, 3.0, 5100.0, 100.0), 0.0);
  // The same sensor offset by 2 kPa at once.
  EXPECT_TRUE(monitor.update(sample(sensor.read(7100.0), true), kPeriod));
  EXPECT_NE(monitor.reason().find("in one reading"), std::string::npos) << monitor.reason();
}

TEST(ConsistencyMonitor, AStepWhileTheValvesMoveGasIsNotCounted) {
  nb::ConsistencyMonitor monitor;
  Sensor sensor(5);
  // A fill: the pressure climbs 2 kPa with the inlet open, then the plate settles there.
  for (double t = 0.0; t < 2.0; t += kPeriod)
    EXPECT_FALSE(monitor.update(sample(sensor.read(500.0 + 1000.0 * t), false), kPeriod));
  EXPECT_LT(runHolds(&monitor, &sensor, 30.0, 2500.0, 100.0), 0.0) << monitor.reason();
}

TEST(ConsistencyMonitor, AFrozenReadingIsFlaggedAfterFrozenS) {
  nb::ConsistencyMonitor monitor;
  double t = 0.0;
  for (; t < 0.99; t += kPeriod) ASSERT_FALSE(monitor.update(sample(1234.0, false), kPeriod)) << t;
  for (; t < 1.05 && !monitor.inconsistent(); t += kPeriod) monitor.update(sample(1234.0, false), kPeriod);
  EXPECT_TRUE(monitor.inconsistent());
  EXPECT_NE(monitor.reason().find("frozen at 1234 Pa"), std::string::npos) << monitor.reason();
}

TEST(ConsistencyMonitor, ALargeWeightBoundCorrectionIsFlaggedASmallOneIsNot) {
  nb::ConsistencyMonitor monitor;
  nb::ConsistencySample s = sample(500.0, true);
  s.correction_m = -0.004;
  EXPECT_FALSE(monitor.update(s, kPeriod));
  s.correction_m = -0.012;
  EXPECT_TRUE(monitor.update(s, kPeriod));
  EXPECT_NE(monitor.reason().find("-12 mm"), std::string::npos) << monitor.reason();
}

TEST(ConsistencyMonitor, StaysInconsistentUntilClearedThenStartsAgain) {
  nb::ConsistencyMonitor monitor;
  Sensor sensor(11);
  nb::ConsistencySample s = sample(500.0, true);
  s.correction_m = 0.02;
  ASSERT_TRUE(monitor.update(s, kPeriod));
  EXPECT_LT(runHolds(&monitor, &sensor, 2.0, 500.0, 100.0), 0.0) << "no new event while inconsistent";
  EXPECT_TRUE(monitor.inconsistent());
  monitor.clear();
  EXPECT_FALSE(monitor.inconsistent());
  EXPECT_EQ(monitor.reason(), "");
  EXPECT_LT(runHolds(&monitor, &sensor, 10.0, 500.0, 100.0), 0.0);
}

TEST(ConsistencyMonitor, AMissingReadingStartsTheTestsAgain) {
  nb::ConsistencyMonitor monitor;
  double t = 0.0;
  for (; t < 0.8; t += kPeriod) monitor.update(sample(1234.0, false), kPeriod);
  EXPECT_FALSE(monitor.update(sample(std::nan(""), false), kPeriod));
  for (t = 0.0; t < 0.8; t += kPeriod) EXPECT_FALSE(monitor.update(sample(1234.0, false), kPeriod));
}
