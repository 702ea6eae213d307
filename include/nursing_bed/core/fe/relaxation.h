// Quasi-static states of the membrane bag by dynamic relaxation (explicit steps with kinetic
// damping), under a prescribed pressure or a prescribed volume.
#pragma once

#include <Eigen/Dense>
#include <limits>
#include <string>

#include "nursing_bed/core/fe/membrane_model.h"
#include "nursing_bed/core/io/status.h"

namespace nursing_bed {
namespace fe {

/// How the gas acts during a relaxation. Pressure control: p = gauge_pressure_pa. Volume
/// control (target_volume_m3 finite): a stiff gas p = gauge_pressure_pa + K (1 - V / V_target)
/// that can follow the film through pressure limit points; the reported (p, V) pair is an
/// exact equilibrium whatever K is (K only has to exceed the film's softening).
struct PressureControl {
  double gauge_pressure_pa = 0.0;
  double target_volume_m3 = std::numeric_limits<double>::quiet_NaN();
  double volume_stiffness_pa = 0.0;                              ///< K
  Eigen::Vector3d volume_axes = Eigen::Vector3d(1.0, 0.0, 0.0);  ///< enclosedVolume weights

  bool volumeControlled() const { return std::isfinite(target_volume_m3); }
  double pressureAt(double volume_m3) const;
};

struct RelaxOptions {
  double tolerance = 2.0e-4;         ///< RMS nodal residual / (p_scale * mean nodal area) [-]
  double pressure_floor_pa = 500.0;  ///< p_scale = max(|p|, this) [Pa]
  int max_iterations = 200000;
  int min_iterations = 100;
  /// Plate mass during the relaxation, times the film mass (a fictitious mass: only the
  /// equilibrium counts, and a light plate converges fastest) [-].
  double plate_mass_ratio = 1.0;
  /// 0: kinetic damping (velocities zeroed at kinetic-energy peaks); > 0: viscous damping at
  /// this rate instead (near the slowest mode's critical damping 2 omega_1) [1/s].
  double damping_per_s = 0.0;

  /// Success, or what is wrong (names the field).
  Status validate() const;
};

struct RelaxResult {
  bool converged = false;
  std::string message;  ///< why it stopped (always set)
  int iterations = 0;
  double gauge_pressure_pa = 0.0;
  double volume_m3 = 0.0;
  double plate_height_m = 0.0;
  double plate_force_n = 0.0;  ///< film on plate
  double residual = 0.0;       ///< final relative residual
  ForceSummary forces;
};

/// Relaxes the model from its current positions. Never throws for non-convergence: the
/// result says so (converged = false, message). Throws std::invalid_argument for bad options.
RelaxResult relax(MembraneModel* model, const PressureControl& control, const RelaxOptions& options = RelaxOptions{});

}  // namespace fe
}  // namespace nursing_bed
