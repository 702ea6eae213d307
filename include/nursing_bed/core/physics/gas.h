// Ideal gas with constant heat capacities (paper eq. 12-16).
#pragma once

#include <string>

#include "nursing_bed/core/io/status.h"

namespace nursing_bed {

/// Calorically perfect gas. Defaults: dry air (R = 287.05 J/(kg K), gamma = 1.40).
struct GasProperties {
  double gas_constant_j_kg_k = 287.05;  ///< specific gas constant R [J/(kg K)]
  double heat_capacity_ratio = 1.40;    ///< gamma = cp/cv [-]

  double cv() const { return gas_constant_j_kg_k / (heat_capacity_ratio - 1.0); }
  double cp() const { return heat_capacity_ratio * cv(); }
  /// Critical (choking) pressure ratio (2/(gamma+1))^(gamma/(gamma-1)), 0.528 for air.
  double criticalPressureRatio() const;
  /// Success when valid, else an error naming what is wrong.
  Status validate() const;
};

/// Absolute pressure of gas with internal energy U in volume V: p = (gamma-1) U / V (eq. 16).
inline double pressureFromEnergy(const GasProperties& gas, double internal_energy_j, double volume_m3) {
  return (gas.heat_capacity_ratio - 1.0) * internal_energy_j / volume_m3;
}

/// Temperature of gas of mass m with internal energy U: T = U / (m cv) (eq. 14).
inline double temperatureFromEnergy(const GasProperties& gas, double internal_energy_j, double mass_kg) {
  return internal_energy_j / (mass_kg * gas.cv());
}

/// Mass of gas at absolute pressure p, temperature T in volume V (ideal gas law).
inline double massFromState(const GasProperties& gas, double pressure_pa, double temperature_k, double volume_m3) {
  return pressure_pa * volume_m3 / (gas.gas_constant_j_kg_k * temperature_k);
}

}  // namespace nursing_bed
