// A bellows: a chamber of fixed cross-section closed by a plate that a spring holds down (a
// test lung, a spring-return actuator). Selected in a parameter file by `structure/type:
// bellows`, its numbers under `bellows/` (doc/cell_model.md#other-structures-the-bellows).
#pragma once

#include <string>

#include "nursing_bed/core/io/status.h"
#include "nursing_bed/core/physics/cell_structure.h"

namespace nursing_bed {

/// Geometry and spring of a bellows. Defaults: a test lung of 20 mL/cmH2O.
struct BellowsParams {
  double area_m2 = 0.0154;              ///< plate area A (dV/dh) [m^2]
  double compliance_m3_pa = 2.0394e-7;  ///< C = A^2 / k: volume per gauge pressure, unloaded [m^3/Pa]
  double dead_volume_m3 = 1.0e-3;       ///< gas volume at h = 0 (chamber, ports, tubing) [m^3]
  double stroke_m = 0.1;                ///< largest plate travel [m]

  /// Spring rate k = A^2 / C [N/m].
  double springRate() const { return area_m2 * area_m2 / compliance_m3_pa; }
  /// Success when valid, else an error naming what is wrong.
  Status validate() const;
};

/**
 * V = V0 + A h; the plate carries p_gauge A and the spring's -k h (StructureEval::plate_force_n),
 * so at rest under a load L: h = (p A - L) / k and V = V0 + C p - C L / A. No film: one shape
 * coordinate that does not touch the volume and stays at 0. Within limits for 0 <= h <= stroke.
 * Damping of the plate is the cell's plate damping (plate/damping_n_s_m).
 */
class BellowsStructure : public CellStructure {
 public:
  explicit BellowsStructure(const BellowsParams& params);

  int shapeDofs() const override { return 1; }
  std::array<double, kMaxShapeDofs> restShape() const override { return {}; }
  StructureEval evaluate(double height_m, const double* shape) const override;
  double heightLimit(const double* /*shape*/) const override { return params_.stroke_m; }
  bool withinLimits(double height_m, const double* shape) const override;
  std::string describe() const override;

  const BellowsParams& params() const { return params_; }

 private:
  BellowsParams params_;
  double spring_rate_n_m_;
};

}  // namespace nursing_bed
