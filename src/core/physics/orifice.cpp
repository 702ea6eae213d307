#include "nursing_bed/core/physics/orifice.h"

#include <algorithm>
#include <cmath>

namespace nursing_bed {
namespace {

// Subsonic flow function and its derivative with respect to the upstream pressure at fixed
// downstream pressure; used to fit the smoothing cubic at the band edge.
struct SubsonicEdge {
  double flow;
  double d_flow_d_pup;
};

SubsonicEdge subsonicWithSlope(const GasProperties& gas, double area, double p_up, double t_up, double p_down) {
  const double g = gas.heat_capacity_ratio;
  const double k = area * std::sqrt(2.0 * g / ((g - 1.0) * gas.gas_constant_j_kg_k * t_up));
  // Phi = p_up^2 (r^(2/g) - r^((g+1)/g)), r = p_down/p_up.
  const double r = p_down / p_up;
  const double r_inv_g = std::pow(r, 1.0 / g);
  const double term1 = p_up * p_up * r_inv_g * r_inv_g;  // p_up^(2-2/g) p_down^(2/g)
  const double term2 = p_up * p_up * r * r_inv_g;        // p_up^((g-1)/g) p_down^((g+1)/g)
  const double phi = std::max(term1 - term2, 1e-300);
  const double d_phi = ((2.0 - 2.0 / g) * term1 - ((g - 1.0) / g) * term2) / p_up;
  const double flow = k * std::sqrt(phi);
  return {flow, k * d_phi / (2.0 * std::sqrt(phi))};
}

}  // namespace

double isentropicMassFlow(const GasProperties& gas, double effective_area_m2, double p_up_pa, double t_up_k,
                          double p_down_pa) {
  if (effective_area_m2 <= 0.0 || p_up_pa <= 0.0 || p_down_pa >= p_up_pa) return 0.0;
  const double g = gas.heat_capacity_ratio;
  const double r = std::max(p_down_pa, 0.0) / p_up_pa;
  if (r <= gas.criticalPressureRatio()) {
    return effective_area_m2 * p_up_pa * std::sqrt(g / (gas.gas_constant_j_kg_k * t_up_k)) *
           std::pow(2.0 / (g + 1.0), (g + 1.0) / (2.0 * (g - 1.0)));
  }
  return subsonicWithSlope(gas, effective_area_m2, p_up_pa, t_up_k, p_down_pa).flow;
}

OrificeFlow orificeFlow(const GasProperties& gas, double effective_area_m2, double pressure_a_pa,
                        double temperature_a_k, double pressure_b_pa, double temperature_b_k, double linear_band_pa) {
  OrificeFlow out;
  const double dp = pressure_a_pa - pressure_b_pa;
  const double sign = dp >= 0.0 ? 1.0 : -1.0;
  const double p_up = sign > 0 ? pressure_a_pa : pressure_b_pa;
  const double p_down = sign > 0 ? pressure_b_pa : pressure_a_pa;
  out.upstream_temperature_k = sign > 0 ? temperature_a_k : temperature_b_k;
  if (effective_area_m2 <= 0.0 || dp == 0.0) return out;

  const double adp = std::fabs(dp);
  if (adp >= linear_band_pa || linear_band_pa <= 0.0) {
    out.choked = p_down / p_up <= gas.criticalPressureRatio();
    out.mass_flow_kg_s = sign * isentropicMassFlow(gas, effective_area_m2, p_up, out.upstream_temperature_k, p_down);
    return out;
  }
  // Inside the band: odd cubic matching the isentropic value M and slope S at |dp| = band.
  const SubsonicEdge edge =
      subsonicWithSlope(gas, effective_area_m2, p_down + linear_band_pa, out.upstream_temperature_k, p_down);
  const double x = adp / linear_band_pa;
  const double slope_x = edge.d_flow_d_pup * linear_band_pa;
  const double a = 0.5 * (3.0 * edge.flow - slope_x);
  const double b = 0.5 * (slope_x - edge.flow);
  out.mass_flow_kg_s = sign * (a * x + b * x * x * x);
  return out;
}

double iso6358MassFlow(double sonic_conductance_m3_s_pa, double critical_ratio, double p_up_pa, double t_up_k,
                       double p_down_pa) {
  if (sonic_conductance_m3_s_pa <= 0.0 || p_up_pa <= 0.0 || p_down_pa >= p_up_pa) return 0.0;
  const double choked = sonic_conductance_m3_s_pa * kIso6358ReferenceDensityKgM3 * p_up_pa *
                        std::sqrt(kIso6358ReferenceTemperatureK / t_up_k);
  const double r = std::max(p_down_pa, 0.0) / p_up_pa;
  if (r <= critical_ratio) return choked;
  const double x = (r - critical_ratio) / (1.0 - critical_ratio);
  return choked * std::sqrt(std::max(0.0, 1.0 - x * x));
}

}  // namespace nursing_bed
