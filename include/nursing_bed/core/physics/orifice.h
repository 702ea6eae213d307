// Compressible isentropic flow through an orifice or valve (paper eq. 18-23, completed with the
// choked branch the paper leaves out).
#pragma once

#include "nursing_bed/core/physics/gas.h"

namespace nursing_bed {

/// Mass flow through an orifice.
struct OrificeFlow {
  double mass_flow_kg_s = 0.0;          ///< positive from side a to side b [kg/s]
  double upstream_temperature_k = 0.0;  ///< stagnation temperature the flow carries [K]
  bool choked = false;
  /// d(mass_flow)/d(pressure_a) and d(mass_flow)/d(pressure_b) [kg/(s Pa)]; the flow scales
  /// with 1/sqrt(upstream_temperature_k), so its temperature slope is -flow / (2 T_up).
  double d_flow_d_pa = 0.0;
  double d_flow_d_pb = 0.0;
};

/**
 * Isentropic nozzle law for an effective area Cd*A between two absolute pressures.
 *
 * Upstream is whichever side has the higher pressure; flow carries the upstream stagnation
 * temperature. For p_down/p_up <= the critical ratio the flow is choked (sonic throat):
 *   mdot = Cd A p_up sqrt(gamma/(R T_up)) (2/(gamma+1))^((gamma+1)/(2(gamma-1))).
 * Above it the subsonic law (eq. 21-22 written for mass flow):
 *   mdot = Cd A p_up sqrt(2 gamma/((gamma-1) R T_up) (r^(2/gamma) - r^((gamma+1)/gamma))).
 * The subsonic law has an infinite slope as the pressure difference goes to zero, which makes
 * any integrator chatter around equalisation. Within `linear_band_pa` of zero difference the
 * flow is replaced by an odd cubic a x + b x^3 (x = dp / band) matching value and slope at the
 * band edge: monotone, C1, and exactly the isentropic law outside the band.
 */
OrificeFlow orificeFlow(const GasProperties& gas, double effective_area_m2, double pressure_a_pa,
                        double temperature_a_k, double pressure_b_pa, double temperature_b_k, double linear_band_pa);

/// The unsmoothed isentropic law from upstream (p_up, T_up) to p_down <= p_up [kg/s].
double isentropicMassFlow(const GasProperties& gas, double effective_area_m2, double p_up_pa, double t_up_k,
                          double p_down_pa);

/// Reference density and temperature of ISO 6358's standard reference atmosphere (ANR).
constexpr double kIso6358ReferenceDensityKgM3 = 1.185;
constexpr double kIso6358ReferenceTemperatureK = 293.15;

/**
 * Mass flow of a pneumatic component rated after ISO 6358 (sonic conductance C, critical
 * pressure ratio b), from the absolute pressure p_up at t_up to p_down [kg/s]; 0 when
 * p_down >= p_up or C <= 0:
 *   mdot = C rho0 p_up sqrt(T0 / T_up)                             for p_down / p_up <= b (choked),
 *   mdot = C rho0 p_up sqrt(T0 / T_up) sqrt(1 - ((r - b)/(1 - b))^2)  above it (r = p_down / p_up).
 */
double iso6358MassFlow(double sonic_conductance_m3_s_pa, double critical_ratio, double p_up_pa, double t_up_k,
                       double p_down_pa);

}  // namespace nursing_bed
