#include "nursing_bed/core/physics/orifice.h"

#include <algorithm>
#include <cmath>

namespace nursing_bed {
namespace {

// The constants of the nozzle law that depend only on the gas, computed once per gas (the
// right-hand side evaluates the law several times per call, and each constant costs a pow).
struct NozzleConstants {
  double heat_capacity_ratio = 0.0;
  double gas_constant = 0.0;
  double critical_ratio = 0.0;   // (2/(g+1))^(g/(g-1))
  double choked_factor = 0.0;    // sqrt(g/R) (2/(g+1))^((g+1)/(2(g-1)))
  double subsonic_factor = 0.0;  // sqrt(2 g/((g-1) R))
  double inverse_ratio = 0.0;    // 1/g
};

NozzleConstants computeNozzleConstants(const GasProperties& gas) {
  const double g = gas.heat_capacity_ratio;
  const double r = gas.gas_constant_j_kg_k;
  NozzleConstants c;
  c.heat_capacity_ratio = g;
  c.gas_constant = r;
  c.critical_ratio = gas.criticalPressureRatio();
  c.choked_factor = std::sqrt(g / r) * std::pow(2.0 / (g + 1.0), (g + 1.0) / (2.0 * (g - 1.0)));
  c.subsonic_factor = std::sqrt(2.0 * g / ((g - 1.0) * r));
  c.inverse_ratio = 1.0 / g;
  return c;
}

const NozzleConstants& nozzleConstants(const GasProperties& gas) {
  // The default gas's constants are shared and immutable; another gas's are kept per thread.
  static const NozzleConstants kDefaultGas = computeNozzleConstants(GasProperties{});
  if (gas.heat_capacity_ratio == kDefaultGas.heat_capacity_ratio && gas.gas_constant_j_kg_k == kDefaultGas.gas_constant)
    return kDefaultGas;
  thread_local NozzleConstants c;
  if (c.heat_capacity_ratio != gas.heat_capacity_ratio || c.gas_constant != gas.gas_constant_j_kg_k)
    c = computeNozzleConstants(gas);
  return c;
}

// Subsonic flow function and its derivatives with respect to the upstream pressure (at fixed
// downstream pressure) and the downstream pressure (at fixed upstream pressure).
struct SubsonicEdge {
  double flow;
  double d_flow_d_pup;
  double d_flow_d_pdown;
};

SubsonicEdge subsonicWithSlope(const NozzleConstants& c, double area, double p_up, double t_up, double p_down) {
  const double g = c.heat_capacity_ratio;
  const double k = area * c.subsonic_factor / std::sqrt(t_up);
  // Phi = p_up^2 (r^(2/g) - r^((g+1)/g)), r = p_down/p_up.
  const double r = p_down / p_up;
  const double r_inv_g = std::pow(r, c.inverse_ratio);
  const double term1 = p_up * p_up * r_inv_g * r_inv_g;  // p_up^(2-2/g) p_down^(2/g)
  const double term2 = p_up * p_up * r * r_inv_g;        // p_up^((g-1)/g) p_down^((g+1)/g)
  const double phi = std::max(term1 - term2, 1e-300);
  const double d_phi_up = ((2.0 - 2.0 / g) * term1 - ((g - 1.0) / g) * term2) / p_up;
  const double d_phi_down = ((2.0 / g) * term1 - ((g + 1.0) / g) * term2) / p_down;
  const double flow = k * std::sqrt(phi);
  const double root = 2.0 * std::sqrt(phi);
  return {flow, k * d_phi_up / root, k * d_phi_down / root};
}

}  // namespace

namespace {

double isentropicMassFlow(const NozzleConstants& c, double effective_area_m2, double p_up_pa, double t_up_k,
                          double p_down_pa) {
  if (effective_area_m2 <= 0.0 || p_up_pa <= 0.0 || p_down_pa >= p_up_pa) return 0.0;
  const double r = std::max(p_down_pa, 0.0) / p_up_pa;
  if (r <= c.critical_ratio) return effective_area_m2 * p_up_pa * c.choked_factor / std::sqrt(t_up_k);
  return subsonicWithSlope(c, effective_area_m2, p_up_pa, t_up_k, p_down_pa).flow;
}

}  // namespace

double isentropicMassFlow(const GasProperties& gas, double effective_area_m2, double p_up_pa, double t_up_k,
                          double p_down_pa) {
  return isentropicMassFlow(nozzleConstants(gas), effective_area_m2, p_up_pa, t_up_k, p_down_pa);
}

OrificeFlow orificeFlow(const GasProperties& gas, double effective_area_m2, double pressure_a_pa,
                        double temperature_a_k, double pressure_b_pa, double temperature_b_k, double linear_band_pa) {
  OrificeFlow out;
  const double dp = pressure_a_pa - pressure_b_pa;
  const double sign = dp >= 0.0 ? 1.0 : -1.0;
  const double p_up = sign > 0 ? pressure_a_pa : pressure_b_pa;
  const double p_down = sign > 0 ? pressure_b_pa : pressure_a_pa;
  out.upstream_temperature_k = sign > 0 ? temperature_a_k : temperature_b_k;
  const bool in_band = linear_band_pa > 0.0 && std::fabs(dp) < linear_band_pa;
  if (effective_area_m2 <= 0.0 || (dp == 0.0 && !in_band)) return out;

  const NozzleConstants& c = nozzleConstants(gas);
  // The magnitude q of the flow and its slopes with respect to p_up and p_down.
  double q = 0.0, dq_up = 0.0, dq_down = 0.0;
  if (!in_band) {
    out.choked = p_down / p_up <= c.critical_ratio;
    if (p_up <= 0.0) return out;
    if (out.choked || p_down <= 0.0) {
      q = isentropicMassFlow(c, effective_area_m2, p_up, out.upstream_temperature_k, p_down);
      dq_up = q / p_up;
    } else {
      const SubsonicEdge e = subsonicWithSlope(c, effective_area_m2, p_up, out.upstream_temperature_k, p_down);
      q = e.flow;
      dq_up = e.d_flow_d_pup;
      dq_down = e.d_flow_d_pdown;
    }
  } else {
    // Inside the band: odd cubic matching the isentropic value M and slope S at |dp| = band.
    // Its coefficients follow the edge's level with the common pressure (to first order).
    const SubsonicEdge edge =
        subsonicWithSlope(c, effective_area_m2, p_down + linear_band_pa, out.upstream_temperature_k, p_down);
    const double x = std::fabs(dp) / linear_band_pa;
    const double slope_x = edge.d_flow_d_pup * linear_band_pa;
    const double a = 0.5 * (3.0 * edge.flow - slope_x);
    const double b = 0.5 * (slope_x - edge.flow);
    q = a * x + b * x * x * x;
    const double dq_ddp = (a + 3.0 * b * x * x) / linear_band_pa;
    const double common = q * (edge.d_flow_d_pup + edge.d_flow_d_pdown) / edge.flow;
    dq_up = dq_ddp;
    dq_down = common - dq_ddp;
  }
  out.mass_flow_kg_s = sign * q;
  out.d_flow_d_pa = sign * (sign > 0 ? dq_up : dq_down);
  out.d_flow_d_pb = sign * (sign > 0 ? dq_down : dq_up);
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
