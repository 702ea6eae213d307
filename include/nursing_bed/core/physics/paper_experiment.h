// The paper's inflation experiments (sections 2.2, 4.2, 5) run on our cell model, and the
// paper's own numbers to compare with.
#pragma once

#include <array>
#include <string>
#include <vector>

#include "nursing_bed/core/physics/cell_model.h"

namespace nursing_bed {

/// The paper's eq. 24-29 quartic h = p1 x^4 + ... + p5 [mm]. The paper says x is in MPa, but
/// then h lies between -790 and -600 mm over its 10-22 kPa range; read with x in bar it gives
/// h = 0 at 10 kPa and ~92 mm at 28 kPa, matching its fig. 4. We use the bar reading.
constexpr std::array<double, 5> kPaperQuarticMmVsBar{-4.603e5, 4.099e5, -1.349e5, 1.955e4, -9.741e2};
/// Paper eq. 24 height [m] at gauge pressure [Pa] (x read as bar).
double paperEq24HeightM(double gauge_pressure_pa);
/// Load of the paper's eq. 24 experiment: 9.8 N weight + 0.6 N plate (paper section 2.2).
constexpr double kPaperEq24LoadN = 10.4;

/// Loads studied by the paper (10, 15, 20 N plus the 0.6 N plate; unloaded = plate only).
constexpr std::array<double, 4> kPaperLoadsN{0.6, 10.6, 15.6, 20.6};

/// A smooth inflow pulse shaped like the paper's measured curve: zero at 0, peak at
/// `peak_time_s`, back to zero at `end_time_s`, integrating to `total_mass_kg`
/// (f ~ t^a (T - t)^b with a/(a+b) = peak/T). Sampled every `sample_s`.
TimeSeries paperShapedInflow(double total_mass_kg, double peak_time_s = 1.0, double end_time_s = 5.5,
                             double sample_s = 0.01);

/// One inflation run: the inlet open to the regulator (or a prescribed inflow) until
/// `inflation_end_s`, then closed.
struct InflationSetup {
  double load_n = 0.6;
  double valve_pressure_pa = 20.0e3;              ///< regulator setting, gauge
  double inflation_end_s = 5.5;                   ///< inlet closes here (paper: inflation ends at 5.5 s)
  double duration_s = 5.5;                        ///< simulated time
  double sample_s = 0.01;                         ///< trace sampling
  const TimeSeries* prescribed_inflow = nullptr;  ///< drive with a given curve instead
};

struct InflationSample {
  double time_s, inflow_kg_s, gauge_pressure_pa, height_m, volume_m3, mass_kg, temperature_k;
};

struct InflationTrace {
  InflationSetup setup;
  std::vector<InflationSample> samples;
  double maxPressurePa() const;
  double finalHeightM() const { return samples.back().height_m; }
  /// Time of the largest inflow [s].
  double peakInflowTimeS() const;
};

InflationTrace runInflation(const CellParams& params, const InflationSetup& setup);

/// Least-squares polynomial y = c[0] x^n + ... + c[n] (highest power first, as MATLAB's
/// polyfit and the paper's eq. 24). Throws std::invalid_argument if underdetermined.
std::vector<double> polyfit(const std::vector<double>& x, const std::vector<double>& y, int degree);
double polyval(const std::vector<double>& coefficients, double x);

/// Samples of a trace's rising part (inlet open, height still growing) as pressure [bar] and
/// height [mm]: the paper's h(p) axes for eq. 24.
void risingHeightVsPressure(const InflationTrace& trace, std::vector<double>* pressure_bar,
                            std::vector<double>* height_mm);

/// RMS [mm] between a trace's rising h(p) and eq. 24 over [p_min, p_max] Pa, on a uniform
/// pressure grid (where the trace reaches it). Returns NaN if the trace never enters the range.
/// `points_used` gets the number of grid points inside the trace's range.
double eq24RmsMm(const InflationTrace& trace, double p_min_pa, double p_max_pa, int* points_used = nullptr,
                 std::vector<double>* squared_errors = nullptr);

}  // namespace nursing_bed
