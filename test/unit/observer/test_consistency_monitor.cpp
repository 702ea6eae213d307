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
  expectRefused("response_min_pa", &nb::ConsistencyMonitorParams::response_min_pa, -1.0);
  expectRefused("response_sds", &nb::ConsistencyMonitorParams::response_sds, 0.0);
  expectRefused("response_silent_sum_pa", &nb::ConsistencyMonitorParams::response_silent_sum_pa, -1.0);
  expectRefused("response_single_pa", &nb::ConsistencyMonitorParams::response_single_pa, NAN);
  expectRefused("response_steady_s", &nb::ConsistencyMonitorParams::response_steady_s, -0.1);
  expectRefused("response_steady_sds", &nb::ConsistencyMonitorParams::response_steady_sds, 0.0);
  expectRefused("response_steady_single_pa", &nb::ConsistencyMonitorParams::response_steady_single_pa, INFINITY);
  nb::ConsistencyMonitorParams none;
  none.response_silent_pulses = 0;
  EXPECT_NE(none.validate().message().find("response_silent_pulses"), std::string::npos);
  expectRefused("response_window_s", &nb::ConsistencyMonitorParams::response_window_s, INFINITY);
  expectRefused("response_min_period_s", &nb::ConsistencyMonitorParams::response_min_period_s, -0.01);
  expectRefused("max_load_n", &nb::ConsistencyMonitorParams::max_load_n, std::nan(""));
  expectRefused("load_rate_pa_s", &nb::ConsistencyMonitorParams::load_rate_pa_s, -1.0);
  expectRefused("landed_height_m", &nb::ConsistencyMonitorParams::landed_height_m, -0.01);
  expectRefused("landed_time_s", &nb::ConsistencyMonitorParams::landed_time_s, 0.0);
  expectRefused("progress_inlet_m", &nb::ConsistencyMonitorParams::progress_inlet_m, -0.01);
  expectRefused("progress_vent_m", &nb::ConsistencyMonitorParams::progress_vent_m, std::nan(""));
  expectRefused("progress_rel", &nb::ConsistencyMonitorParams::progress_rel, 0.0);
  expectRefused("progress_rel", &nb::ConsistencyMonitorParams::progress_rel, 1.0);
  expectRefused("progress_min_pa", &nb::ConsistencyMonitorParams::progress_min_pa, 0.0);
  expectRefused("progress_window_s", &nb::ConsistencyMonitorParams::progress_window_s, -1.0);
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

TEST(ConsistencyMonitor, UnderConstantLoadsAPressureStepUnderASettledPlateIsFlaggedWithinASecond) {
  nb::ConsistencyMonitorParams constant_loads;
  constant_loads.load_rate_pa_s = 0.0;                 // the hold's mean alone
  for (const double step : {1100.0, -900.0, 400.0}) {  // below the jump test: the CUSUM
    nb::ConsistencyMonitor monitor(constant_loads);
    Sensor sensor(3);
    ASSERT_LT(runHolds(&monitor, &sensor, 5.0, 1500.0, 100.0), 0.0);
    const double flagged_at = runHolds(&monitor, &sensor, 5.0, 1500.0 + step, 100.0, 5.0);
    ASSERT_GE(flagged_at, 5.0) << step << " Pa";
    EXPECT_LE(flagged_at - 5.0, 1.0) << step << " Pa";
    EXPECT_NE(monitor.reason().find("departs from the hold"), std::string::npos) << monitor.reason();
  }
}

TEST(ConsistencyMonitor, ASensorJumpIsFlaggedWhenTheNextReadingStaysThereALoadsStepIsNot) {
  nb::ConsistencyMonitor monitor;
  Sensor sensor(9);
  ASSERT_LT(runHolds(&monitor, &sensor, 3.0, 1500.0, 100.0), 0.0);
  // A load of 36 N dropped onto the plate: the pressure rises 3.6 kPa over a quarter of the
  // loaded plate's period (~20 ms), then the hold goes on at the new pressure.
  for (int i = 1; i <= 4; ++i)
    EXPECT_FALSE(monitor.update(sample(sensor.read(1500.0 + 900.0 * i), true), kPeriod)) << monitor.reason();
  monitor.clear();
  // A stiff cell under a light plate (the FE fold-table cell at 100 mm, 35 N stepping off):
  // 1.2 kPa in the first reading, more in the next ones.
  ASSERT_LT(runHolds(&monitor, &sensor, 3.0, 13310.0, 100.0), 0.0);
  for (const double p : {12102.0, 11212.0, 10455.0, 9858.0})
    EXPECT_FALSE(monitor.update(sample(sensor.read(p), true), kPeriod)) << monitor.reason();
  monitor.clear();
  ASSERT_LT(runHolds(&monitor, &sensor, 3.0, 5100.0, 100.0), 0.0);
  // The same sensor offset by 2 kPa at once: flagged as the next reading stays there.
  EXPECT_FALSE(monitor.update(sample(sensor.read(7100.0), true), kPeriod));
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

namespace {

/// A pulse of `periods` periods of one valve (+1 inlet, -1 vent), each counted to move the
/// pressure by `step_pa` at fixed volume, then 40 periods of hold, at `pressure_pa`; the readings
/// move `response_pa` its way during it, the plate swinging with `plate_period_s`. Returns
/// whether the monitor flagged it.
bool pulseOn(nb::ConsistencyMonitor* monitor, Sensor* sensor, double pressure_pa, int direction, double step_pa,
             int periods, double response_pa, double plate_period_s = 0.05) {
  for (int i = 0; i < periods + 40; ++i) {
    nb::ConsistencySample s =
        sample(sensor->read(pressure_pa + direction * (i < periods ? response_pa : 0.0)), i >= periods);
    s.counted_step_pa = i < periods ? direction * step_pa : 0.0;
    s.plate_period_s = plate_period_s;
    if (monitor->update(s, kPeriod)) return true;
  }
  return false;
}

/// The same pulse after half a second of hold, on a fresh monitor.
bool pulse(double pressure_pa, int direction, double step_pa, int periods, double response_pa,
           double plate_period_s = 0.05) {
  nb::ConsistencyMonitor monitor;
  Sensor sensor(13);
  runHolds(&monitor, &sensor, 0.5, pressure_pa, 100.0);
  return pulseOn(&monitor, &sensor, pressure_pa, direction, step_pa, periods, response_pa, plate_period_s);
}

}  // namespace

TEST(ConsistencyMonitor, AValvePulseThatMovesNoPressureIsFlaggedOneThatDoesIsNot) {
  for (const int direction : {1, -1}) {
    EXPECT_FALSE(pulse(8000.0, direction, 350.0, 10, 300.0)) << direction << ": a working valve";
    EXPECT_TRUE(pulse(8000.0, direction, 350.0, 10, 0.0)) << direction << ": a valve stuck shut";
    // From steady readings, counted within a quarter of a 0.2 s swing: 1.5 kPa is enough.
    EXPECT_TRUE(pulse(8000.0, direction, 150.0, 10, 0.0, 0.2)) << direction << ": 1.5 kPa, steady";
    EXPECT_FALSE(pulse(8000.0, direction, 80.0, 10, 0.0, 0.2)) << direction << ": 0.8 kPa, steady";
    // The same 1.5 kPa over four quarters of a 0.05 s swing: the plate takes it up as it comes.
    EXPECT_FALSE(pulse(8000.0, direction, 150.0, 10, 0.0)) << direction << ": 1.5 kPa slower than the plate";
    EXPECT_FALSE(pulse(8000.0, direction, 15.0, 10, 0.0)) << direction << ": too small a pulse to judge";
  }
  // A plate resting at a few sds of pressure has no room to show its vent.
  EXPECT_FALSE(pulse(40.0, -1, 1000.0, 10, 0.0));
  // A light plate follows the gas at once: its pulses are not judged.
  EXPECT_FALSE(pulse(900.0, 1, 1000.0, 10, 0.0, 0.01));
  nb::ConsistencyMonitorParams off;
  off.response_min_pa = 0.0;
  nb::ConsistencyMonitor monitor(off);
  Sensor sensor(13);
  runHolds(&monitor, &sensor, 0.5, 900.0, 100.0);
  nb::ConsistencySample s = sample(sensor.read(900.0), false);
  s.counted_step_pa = 5000.0;
  s.plate_period_s = 0.05;
  for (int i = 0; i < 50; ++i) EXPECT_FALSE(monitor.update(i < 10 ? s : sample(sensor.read(900.0), true), kPeriod));
}

TEST(ConsistencyMonitor, ASilentPulseBelowTheSingleWorthNeedsSteadyReadingsBeforeIt) {
  // A body's part swaying on the plate (the readings +-150 Pa at 3 Hz) can hide a working
  // valve's 1.5 kPa pulse; the same pulse after the readings stood still shows a valve stuck shut.
  for (const double sway_pa : {150.0, 0.0}) {
    nb::ConsistencyMonitor monitor;
    Sensor sensor(17);
    for (double t = 0.0; t < 0.5; t += kPeriod) {
      monitor.update(sample(sensor.read(8000.0 + sway_pa * std::sin(2.0 * M_PI * 3.0 * t)), true), kPeriod);
    }
    EXPECT_EQ(pulseOn(&monitor, &sensor, 8000.0, 1, 150.0, 10, 0.0, 0.2), sway_pa == 0.0)
        << sway_pa << ": " << monitor.reason();
    if (sway_pa == 0.0) {
      EXPECT_NE(monitor.reason().find("from steady readings"), std::string::npos);
    }
  }
  nb::ConsistencyMonitorParams off;
  off.response_steady_s = 0.0;
  nb::ConsistencyMonitor monitor(off);
  Sensor sensor(17);
  runHolds(&monitor, &sensor, 0.5, 8000.0, 100.0);
  EXPECT_FALSE(pulseOn(&monitor, &sensor, 8000.0, 1, 150.0, 10, 0.0, 0.2)) << "the steady test off";
}

TEST(ConsistencyMonitor, AnInletHeldOpenThatMovesNoPressureIsFlaggedBeforeItsMoveEnds) {
  // A move's full flow: the inlet open 2 s, each period counted worth 100 Pa at fixed volume.
  // Stuck shut, it is flagged once worth 3 kPa and open 0.1 s, not at the move's end (the
  // plate, swinging in 0.05 s, could take up its flow as it comes).
  auto flagged_at = [](double response_pa, int direction) {
    nb::ConsistencyMonitor monitor;
    Sensor sensor(13);
    runHolds(&monitor, &sensor, 0.5, 2000.0, 100.0);
    for (int i = 0; i < 400; ++i) {
      nb::ConsistencySample s = sample(sensor.read(2000.0 + direction * std::min(i * 20.0, response_pa)), false);
      s.counted_step_pa = direction * 100.0;
      s.plate_period_s = 0.05;
      if (monitor.update(s, kPeriod)) return i * kPeriod;
    }
    return -1.0;
  };
  const double stuck = flagged_at(0.0, 1);
  EXPECT_GT(stuck, 0.1);
  EXPECT_LT(stuck, 0.2);
  EXPECT_LT(flagged_at(300.0, 1), 0.0) << "a working inlet raising the pressure";
  EXPECT_LT(flagged_at(0.0, -1), 0.0) << "a vent is judged at its pulse's end";
}

namespace {
/// The silent-pulse rows on, as a rig with rigid loads runs them (the steady single pulse off,
/// so that the rows alone are seen).
nb::ConsistencyMonitorParams rowsOn() {
  nb::ConsistencyMonitorParams p;
  p.response_silent_sum_pa = 1000.0;
  p.response_steady_s = 0.0;
  return p;
}
}  // namespace

TEST(ConsistencyMonitor, OneValvesSmallSilentPulsesInARowAreFlaggedOnceTheySumToTheLimit) {
  // A slow ramp's pulses, 300 Pa each at fixed volume: three silent ones (900 Pa) are not yet
  // a stuck valve, the fourth (1200 Pa) is.
  for (const int direction : {1, -1}) {
    nb::ConsistencyMonitor monitor(rowsOn());
    Sensor sensor(17);
    runHolds(&monitor, &sensor, 0.5, 2000.0, 100.0);
    for (int i = 0; i < 3; ++i) EXPECT_FALSE(pulseOn(&monitor, &sensor, 2000.0, direction, 100.0, 3, 0.0)) << i;
    EXPECT_TRUE(pulseOn(&monitor, &sensor, 2000.0, direction, 100.0, 3, 0.0)) << direction;
    EXPECT_NE(monitor.reason().find(direction > 0 ? "inlet" : "vent"), std::string::npos) << monitor.reason();
  }
  // Two silent pulses of 1.25 kPa are not enough, a third is.
  nb::ConsistencyMonitor two(rowsOn());
  Sensor two_sensor(29);
  runHolds(&two, &two_sensor, 0.5, 2000.0, 100.0);
  EXPECT_FALSE(pulseOn(&two, &two_sensor, 2000.0, +1, 250.0, 5, 0.0));
  EXPECT_FALSE(pulseOn(&two, &two_sensor, 2000.0, +1, 250.0, 5, 0.0));
  EXPECT_TRUE(pulseOn(&two, &two_sensor, 2000.0, +1, 250.0, 5, 0.0));
  // A pulse that shows starts its valve's sum again; the other valve's pulses do not.
  nb::ConsistencyMonitor monitor(rowsOn());
  Sensor sensor(19);
  runHolds(&monitor, &sensor, 0.5, 2000.0, 100.0);
  for (int i = 0; i < 12; ++i) {
    const bool shows = i % 3 == 2;
    EXPECT_FALSE(pulseOn(&monitor, &sensor, 2000.0, +1, 100.0, 3, shows ? 80.0 : 0.0)) << i;
  }
  for (int i = 0; i < 3; ++i) EXPECT_FALSE(pulseOn(&monitor, &sensor, 2000.0, +1, 100.0, 3, 0.0)) << i;
  EXPECT_FALSE(pulseOn(&monitor, &sensor, 2000.0, -1, 100.0, 3, 80.0));
  EXPECT_TRUE(pulseOn(&monitor, &sensor, 2000.0, +1, 100.0, 3, 0.0));
  // Small vent pulses count only where the plate rests at twice their worth or more.
  nb::ConsistencyMonitor low(rowsOn());
  Sensor low_sensor(23);
  runHolds(&low, &low_sensor, 0.5, 500.0, 100.0);
  for (int i = 0; i < 8; ++i) EXPECT_FALSE(pulseOn(&low, &low_sensor, 500.0, -1, 100.0, 3, 0.0)) << i;
  // Off by default (a body's part moves with its plate): no row flags.
  nb::ConsistencyMonitor off;
  Sensor off_sensor(31);
  runHolds(&off, &off_sensor, 0.5, 2000.0, 100.0);
  for (int i = 0; i < 12; ++i) EXPECT_FALSE(pulseOn(&off, &off_sensor, 2000.0, +1, 100.0, 3, 0.0)) << i;
}

TEST(ConsistencyMonitor, ALoadAboveAnyACellCarriesIsFlagged) {
  nb::ConsistencyMonitor monitor;
  nb::ConsistencySample s = sample(900.0, false);
  s.load_n = 150.0;
  EXPECT_FALSE(monitor.update(s, kPeriod));
  s.load_n = 350.0;
  EXPECT_TRUE(monitor.update(s, kPeriod));
  EXPECT_NE(monitor.reason().find("350 N"), std::string::npos) << monitor.reason();
}

TEST(ConsistencyMonitor, ALoadShiftingOrSteppingOnAHeldCellIsNotFlagged) {
  // A patient turning over a held cell: its pressure ramps up 3 kPa in 1.5 s, holds, falls
  // 2.5 kPa in 1 s, then a quick shift of 2 kPa in 0.2 s, with breathing (+-200 Pa at
  // 0.25 Hz) throughout.
  auto patient = [](double t) {
    double shift = 0.0;
    if (t >= 3.0) shift = std::min(3000.0, 2000.0 * (t - 3.0));
    if (t >= 7.0) shift = 3000.0 - std::min(2500.0, 2500.0 * (t - 7.0));
    if (t >= 10.0) shift = 500.0 + std::min(2000.0, 10000.0 * (t - 10.0));
    return 1500.0 + shift + 200.0 * std::sin(2.0 * M_PI * 0.25 * t);
  };
  nb::ConsistencyMonitorParams constant_loads;
  constant_loads.load_rate_pa_s = 0.0;
  for (const bool load_aware : {true, false}) {
    nb::ConsistencyMonitor monitor(load_aware ? nb::ConsistencyMonitorParams{} : constant_loads);
    Sensor sensor(17);
    double t = 0.0;
    for (; t < 14.0 && !monitor.update(sample(sensor.read(patient(t)), true), kPeriod); t += kPeriod) {
    }
    if (load_aware) {
      EXPECT_GE(t, 14.0) << t << " s: " << monitor.reason();
    } else {
      EXPECT_LT(t, 14.0) << "the hold's mean alone takes a patient's shifts for faults";
    }
  }
  // A leg dropped onto the cell: 4.5 kPa in 50 ms, as fast as the plate rings on its gas spring.
  // Gas passing a valve stuck open under a plate at the bag's top rises as fast; the load bound
  // finds that (ALoadAboveAnyACellCarriesIsFlagged), the innovation cannot.
  nb::ConsistencyMonitor monitor;
  Sensor sensor(23);
  runHolds(&monitor, &sensor, 3.0, 1500.0, 100.0);
  double t = 0.0;
  for (; t < 3.0 && !monitor.update(sample(sensor.read(1500.0 + std::min(4500.0, 90000.0 * t)), true), kPeriod);
       t += kPeriod) {
  }
  EXPECT_GE(t, 3.0) << "a body's load step flagged: " << monitor.reason();
}

namespace {

/// A sample of a lifted estimate at `height_m` with the observer's flat pressure 20 Pa.
nb::ConsistencySample lifted(double pressure_pa, double height_m, bool shut) {
  nb::ConsistencySample s = sample(pressure_pa, shut);
  s.height_m = height_m;
  s.flat_pressure_pa = 20.0;
  return s;
}

}  // namespace

TEST(ConsistencyMonitor, FlatReadingsUnderALiftedEstimateAreFlaggedThePlateAloneLiftedIsNot) {
  Sensor sensor(19);
  {
    // The plate alone lifted reads at least twice the flat pressure, venting (the vent open) or not.
    nb::ConsistencyMonitor monitor;
    for (double t = 0.0; t < 20.0; t += kPeriod)
      ASSERT_FALSE(monitor.update(lifted(sensor.read(45.0), 0.08, std::fmod(t, 2.0) > 0.3), kPeriod))
          << t << " s: " << monitor.reason();
  }
  {
    // A flat cell whose estimate is near flat: a re-anchor's few millimetres, not a fault.
    nb::ConsistencyMonitor monitor;
    for (double t = 0.0; t < 5.0; t += kPeriod)
      ASSERT_FALSE(monitor.update(lifted(sensor.read(0.0), 0.01, false), kPeriod)) << monitor.reason();
  }
  // The plate landed on a stuck-open vent under an estimate at 88 mm: its pressure collapses
  // from 480 Pa within 0.1 s while the controller vents to bring the estimate down.
  nb::ConsistencyMonitor monitor;
  for (double t = 0.0; t < 2.0; t += kPeriod)
    ASSERT_FALSE(monitor.update(lifted(sensor.read(480.0), 0.088, true), kPeriod)) << monitor.reason();
  double t = 0.0;
  for (; t < 2.0 && !monitor.update(lifted(sensor.read(480.0 * std::exp(-t / 0.02)), 0.089, t > 0.1), kPeriod);
       t += kPeriod) {
  }
  EXPECT_LT(t, 0.6) << "a plate that landed under a lifted estimate not flagged";
  EXPECT_NE(monitor.reason().find("reads a flat cell"), std::string::npos) << monitor.reason();
  nb::ConsistencyMonitorParams off;
  off.landed_height_m = 0.0;
  nb::ConsistencyMonitor quiet(off);
  for (t = 0.0; t < 2.0; t += kPeriod)
    EXPECT_FALSE(quiet.update(lifted(sensor.read(0.0), 0.089, false), kPeriod)) << quiet.reason();
}

TEST(ConsistencyMonitor, AHoldsSmallCorrectionsDoNotKeepTheHoldTestFromRunning) {
  // A plate sinking on a vent stuck open under a constant load: its pressure falls 1 kPa in
  // 0.4 s while the controller nudges its estimate with a vent pulse worth 20 Pa every 0.1 s.
  nb::ConsistencyMonitorParams constant_loads;
  constant_loads.load_rate_pa_s = 0.0;
  for (const double corrections_pa : {50.0, 0.0}) {
    nb::ConsistencyMonitorParams p = constant_loads;
    p.hold_correction_pa = corrections_pa;
    nb::ConsistencyMonitor monitor(p);
    Sensor sensor(29);
    bool flagged = false;
    for (double t = 0.0; t < 6.0 && !flagged; t += kPeriod) {
      const double pressure = t < 4.0 ? 1500.0 : 1500.0 - std::min(1000.0, 2500.0 * (t - 4.0));
      nb::ConsistencySample s = sample(sensor.read(pressure), true);
      if (std::fmod(t, 0.1) < kPeriod) {
        s.valves_shut = false;
        s.counted_step_pa = -20.0;
      }
      flagged = monitor.update(s, kPeriod);
      if (t < 4.0) {
        ASSERT_FALSE(flagged) << t << " s: " << monitor.reason();
      }
    }
    EXPECT_EQ(flagged, corrections_pa > 0.0) << "hold_correction_pa " << corrections_pa << ": " << monitor.reason();
  }
}

TEST(ConsistencyMonitor, AValvePulseThatALoadShiftOutweighsIsNotJudged) {
  // A patient's load on the plate rising 4 kPa/s as the vent opens (falling as the inlet
  // does), from 50 ms before the pulse: the readings move against the pulse all along; a
  // valve stuck shut under a steady load leaves them where they were.
  for (const int direction : {1, -1}) {
    for (const double rate_pa_s : {-4000.0, 0.0}) {
      nb::ConsistencyMonitor monitor;
      Sensor sensor(31);
      runHolds(&monitor, &sensor, 0.5, 900.0, 100.0);
      bool flagged = false;
      for (int i = -10; i < 50 && !flagged; ++i) {
        const double shift_pa = direction * std::max(-400.0, rate_pa_s * kPeriod * (i + 10));
        nb::ConsistencySample s = sample(sensor.read(900.0 + shift_pa), i < 0 || i >= 10);
        s.counted_step_pa = i >= 0 && i < 10 ? direction * 1000.0 : 0.0;
        s.plate_period_s = 0.05;
        flagged = monitor.update(s, kPeriod);
      }
      EXPECT_EQ(flagged, rate_pa_s == 0.0) << direction << " " << rate_pa_s << ": " << monitor.reason();
    }
  }
}

namespace {

/// A move up of small inlet pulses (every other period, `inlet_s` of opening in all) that turns
/// at once into a ramp down of vent pulses, never resting in between, the pressure rising by
/// `rise_pa` over the move; returns the progress test's verdict ("" none).
std::string moveUpThenRampDown(double inlet_s, double rise_pa) {
  nb::ConsistencyMonitorParams p;
  p.progress_inlet_m = 0.005;
  p.progress_vent_m = 0.004;
  p.response_min_pa = 0.0;  // the progress test alone
  nb::ValveProgressCheck check;
  Sensor sensor(7);
  const double start_pa = 1500.0;
  for (int i = 0; i < 200; ++i) check.update(sample(sensor.read(start_pa), true), kPeriod, p);
  const int pulses = static_cast<int>(inlet_s / (0.5 * kPeriod));
  std::string why;
  for (int i = 0; i < 2 * pulses && why.empty(); ++i) {
    nb::ConsistencySample s = sample(sensor.read(start_pa + rise_pa * i / (2.0 * pulses)), false);
    s.inlet_opening = i % 2 ? 0.0 : 0.5;
    s.counted_height_m = 0.1 * s.inlet_opening * kPeriod;  // 0.1 m per second open
    why = check.update(s, kPeriod, p);
  }
  for (int i = 0; i < 40 && why.empty(); ++i) {
    nb::ConsistencySample s = sample(sensor.read(start_pa + rise_pa), false);
    s.vent_opening = i % 4 ? 0.0 : 0.05;
    why = check.update(s, kPeriod, p);
  }
  return why;
}

}  // namespace

TEST(ValveProgressCheck, AnInletThatMovedNoPressureIsJudgedWhenTheVentTakesOverWithoutARest) {
  const std::string stuck = moveUpThenRampDown(0.08, 0.0);
  EXPECT_NE(stuck.find("failure to reach target: the inlet"), std::string::npos) << stuck;
  EXPECT_EQ(moveUpThenRampDown(0.08, 0.08 * 1500.0), "") << "a working inlet raised the pressure 8 %";
  EXPECT_EQ(moveUpThenRampDown(0.02, 0.0), "") << "below the limit the sum is dropped unjudged";
}

TEST(ConsistencyMonitor, AFailureToReachTargetDoubtsTheValvesGasInsteadOfFlaggingTheCell) {
  // A vent counted open in pulses (1e-5 kg, 0.2 mm each) at 3 kPa while the pressure stays: a
  // valve stuck shut, or a load that grew meanwhile. The pressure cannot tell which, so the gas
  // counted through it is the count's doubt, and the cell is not inconsistent.
  nb::ConsistencyMonitorParams p;
  p.response_min_pa = 0.0;  // the progress test alone
  nb::ConsistencyMonitor monitor(p);
  Sensor sensor(11);
  const double held_pa = 3000.0;
  for (int i = 0; i < 200; ++i) ASSERT_FALSE(monitor.update(sample(sensor.read(held_pa), true), kPeriod));
  int open_periods = 0;
  for (int i = 0; i < 80; ++i) {  // a pulse every other period, then a rest
    nb::ConsistencySample s = sample(sensor.read(held_pa), i % 2 == 1 || i >= 80 - 30);
    if (!s.valves_shut) {
      s.vent_opening = 1.0;
      s.counted_gas_kg = 1e-5;
      s.counted_height_m = 2e-4;  // 5 mm over the pulses
      ++open_periods;
    }
    ASSERT_FALSE(monitor.update(s, kPeriod)) << monitor.reason();
  }
  for (int i = 0; i < 40; ++i) ASSERT_FALSE(monitor.update(sample(sensor.read(held_pa), true), kPeriod));
  EXPECT_EQ(monitor.progress().failures(), 1);
  EXPECT_NE(monitor.progress().lastFailure().find("failure to reach target: the vent"), std::string::npos)
      << monitor.progress().lastFailure();
  EXPECT_NEAR(monitor.takeDoubtKg(), 1e-5 * open_periods, 1e-12);
  EXPECT_EQ(monitor.takeDoubtKg(), 0.0) << "taken once";
  EXPECT_FALSE(monitor.inconsistent());

  // A working vent: the same pulses lowering the pressure 10 % (its mean lags).
  nb::ConsistencyMonitor working(p);
  for (int i = 0; i < 200; ++i) working.update(sample(sensor.read(held_pa), true), kPeriod);
  double now_pa = held_pa;
  for (int i = 0; i < 80; ++i) {
    nb::ConsistencySample s = sample(sensor.read(now_pa), i % 2 == 1 || i >= 80 - 30);
    if (!s.valves_shut) {
      s.vent_opening = 1.0;
      s.counted_gas_kg = 1e-5;
      s.counted_height_m = 2e-4;
      now_pa -= 0.1 * held_pa / open_periods;
    }
    working.update(s, kPeriod);
  }
  for (int i = 0; i < 40; ++i) working.update(sample(sensor.read(now_pa), true), kPeriod);
  EXPECT_EQ(working.progress().failures(), 0) << working.progress().lastFailure();
  EXPECT_EQ(working.takeDoubtKg(), 0.0);
}
