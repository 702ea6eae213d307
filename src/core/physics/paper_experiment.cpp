#include "nursing_bed/core/physics/paper_experiment.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace nursing_bed {

double paperEq24HeightM(double gauge_pressure_pa) {
  return mmToM(polyval({kPaperQuarticMmVsBar.begin(), kPaperQuarticMmVsBar.end()}, paToBar(gauge_pressure_pa)));
}

TimeSeries paperShapedInflow(double total_mass_kg, double peak_time_s, double end_time_s, double sample_s) {
  if (!(end_time_s > peak_time_s && peak_time_s > 0.0 && sample_s > 0.0))
    throw std::invalid_argument("paperShapedInflow: need 0 < peak_time_s < end_time_s and sample_s > 0");
  // t^a (T-t)^b peaks at a T / (a + b); a = 1.5 gives a rounded start like the measured curve.
  const double a = 1.5;
  const double b = a * (end_time_s - peak_time_s) / peak_time_s;
  std::vector<double> t, f;
  const int n = static_cast<int>(std::ceil(end_time_s / sample_s - 1e-9));
  for (int i = 0; i <= n; ++i) {
    const double tc = i == n ? end_time_s : i * sample_s;
    t.push_back(tc);
    f.push_back(std::pow(tc / end_time_s, a) * std::pow(std::max(0.0, 1.0 - tc / end_time_s), b));
  }
  const TimeSeries raw(t, f);
  const double scale = total_mass_kg / raw.integral();
  for (double& v : f) v *= scale;
  return TimeSeries(t, f);
}

double InflationTrace::maxPressurePa() const {
  double p = -1e300;
  for (const auto& s : samples) p = std::max(p, s.gauge_pressure_pa);
  return p;
}

double InflationTrace::peakInflowTimeS() const {
  double best = -1e300, t = 0.0;
  for (const auto& s : samples)
    if (s.inflow_kg_s > best) {
      best = s.inflow_kg_s;
      t = s.time_s;
    }
  return t;
}

InflationTrace runInflation(const CellParams& params, const InflationSetup& setup) {
  InflationTrace trace;
  trace.setup = setup;
  CellParams p = params;
  p.supply_pressure_pa = setup.valve_pressure_pa;
  CellModel model(p);
  model.reset(setup.load_n);
  CellInputs in;
  in.load_n = setup.load_n;
  in.prescribed_inflow = setup.prescribed_inflow;
  auto record = [&]() {
    const CellVariables& v = model.variables();
    trace.samples.push_back(
        {v.time_s, v.inflow_kg_s, v.gauge_pressure_pa, v.height_m, v.structure.volume_m3, v.mass_kg, v.temperature_k});
  };
  record();
  const int n = static_cast<int>(std::lround(setup.duration_s / setup.sample_s));
  for (int i = 1; i <= n; ++i) {
    const double t_next = i * setup.sample_s;
    const bool inflating = t_next <= setup.inflation_end_s + 1e-9;
    in.inlet_opening = inflating ? 1.0 : 0.0;
    in.prescribed_inflow = inflating ? setup.prescribed_inflow : nullptr;
    model.advance(t_next - model.time(), in);
    record();
  }
  return trace;
}

std::vector<double> polyfit(const std::vector<double>& x, const std::vector<double>& y, int degree) {
  const int n = static_cast<int>(x.size());
  if (degree < 0 || n != static_cast<int>(y.size()) || n <= degree)
    throw std::invalid_argument("polyfit: need equal sizes and more points than the degree");
  Eigen::MatrixXd a(n, degree + 1);
  Eigen::VectorXd b(n);
  for (int i = 0; i < n; ++i) {
    double power = 1.0;
    for (int k = degree; k >= 0; --k) {
      a(i, k) = power;
      power *= x[i];
    }
    b[i] = y[i];
  }
  const Eigen::VectorXd c = a.colPivHouseholderQr().solve(b);
  return std::vector<double>(c.data(), c.data() + c.size());
}

double polyval(const std::vector<double>& coefficients, double x) {
  double y = 0.0;
  for (double c : coefficients) y = y * x + c;
  return y;
}

void risingHeightVsPressure(const InflationTrace& trace, std::vector<double>* pressure_bar,
                            std::vector<double>* height_mm) {
  pressure_bar->clear();
  height_mm->clear();
  for (const auto& s : trace.samples) {
    if (s.time_s > trace.setup.inflation_end_s + 1e-9) break;
    pressure_bar->push_back(paToBar(s.gauge_pressure_pa));
    height_mm->push_back(mToMm(s.height_m));
  }
}

double eq24RmsMm(const InflationTrace& trace, double p_min_pa, double p_max_pa, int* points_used,
                 std::vector<double>* squared_errors) {
  // Height on the rising branch as a function of pressure: the first time each pressure is
  // reached (the running maximum makes the branch single-valued).
  std::vector<double> p, h;
  double p_run = -1e300;
  for (const auto& s : trace.samples) {
    if (s.time_s > trace.setup.inflation_end_s + 1e-9) break;
    if (s.gauge_pressure_pa > p_run) {
      p_run = s.gauge_pressure_pa;
      p.push_back(s.gauge_pressure_pa);
      h.push_back(s.height_m);
    }
  }
  const int grid = 181;
  double sum = 0.0;
  int used = 0;
  for (int i = 0; i < grid; ++i) {
    const double pg = p_min_pa + (p_max_pa - p_min_pa) * i / (grid - 1);
    if (p.size() < 2 || pg < p.front() || pg > p.back()) continue;
    const auto it = std::upper_bound(p.begin(), p.end(), pg);
    const std::size_t k = std::min<std::size_t>(std::max<std::ptrdiff_t>(it - p.begin(), 1), p.size() - 1);
    const double f = (pg - p[k - 1]) / (p[k] - p[k - 1]);
    const double h_model = h[k - 1] + f * (h[k] - h[k - 1]);
    const double e = mToMm(h_model - paperEq24HeightM(pg));
    sum += e * e;
    if (squared_errors) squared_errors->push_back(e * e);
    ++used;
  }
  if (points_used) *points_used = used;
  return used > 0 ? std::sqrt(sum / used) : std::nan("");
}

}  // namespace nursing_bed
