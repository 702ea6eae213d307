// Physical constants and unit conversions. Everything inside nursing_bed is SI
// (Pa, m, m^3, kg, K, s, N); conversions to the paper's MPa, mm, ms or to bar and
// mmHg happen only at the edges, through these helpers.
#pragma once

namespace nursing_bed {

/// Standard gravity [m/s^2].
constexpr double kGravity = 9.80665;
/// Standard atmosphere [Pa].
constexpr double kAtmosphericPressurePa = 101325.0;
/// Room temperature used by the paper's rig [K] (20 degC).
constexpr double kRoomTemperatureK = 293.15;
constexpr double kPi = 3.14159265358979323846;

constexpr double mmToM(double mm) { return mm * 1e-3; }
constexpr double mToMm(double m) { return m * 1e3; }
constexpr double mpaToPa(double mpa) { return mpa * 1e6; }
constexpr double paToMpa(double pa) { return pa * 1e-6; }
constexpr double barToPa(double bar) { return bar * 1e5; }
constexpr double paToBar(double pa) { return pa * 1e-5; }
constexpr double kPaPerMmHg = 133.322387415;
constexpr double paToMmHg(double pa) { return pa / kPaPerMmHg; }
constexpr double mmHgToPa(double mmhg) { return mmhg * kPaPerMmHg; }
/// Standard litre per minute (ANR, 20 degC, 1 atm) of air to kg/s.
constexpr double kAirDensityAnrKgM3 = 1.2041;
constexpr double slpmToKgS(double slpm) { return slpm * 1e-3 / 60.0 * kAirDensityAnrKgM3; }

}  // namespace nursing_bed
