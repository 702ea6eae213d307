// The structure of one airbag cell: how plate height and film shape set the gas volume, the
// force on the plate and the film's elastic forces. The reduced-order pillow model implements
// it; a finer model (an FE membrane) can replace it behind the same interface.
#pragma once

#include <array>
#include <string>

namespace nursing_bed {

/// Upper bound on the number of film shape coordinates a structure may use.
constexpr int kMaxShapeDofs = 4;

/**
 * Everything the cell model needs from the structure at one configuration (plate height h,
 * film shape coordinates q). Energy-consistent by construction: the gas does work
 * p_gauge dV = p_gauge (A_eff dh + sum_i dV/dq_i dq_i), the plate receives p_gauge A_eff dh and
 * the film stores sum_i dW/dq_i dq_i.
 */
struct StructureEval {
  double volume_m3 = 0.0;                              ///< gas volume, dead volume included (paper eq. 11)
  double effective_area_m2 = 0.0;                      ///< dV/dh at fixed shape; plate force = p_gauge * this
  std::array<double, kMaxShapeDofs> dvolume_dshape{};  ///< dV/dq_i [m^3 per unit q_i]
  std::array<double, kMaxShapeDofs> elastic_force{};   ///< dW/dq_i of the film energy [J per unit q_i]
  std::array<double, kMaxShapeDofs> shape_damping{};   ///< viscous resistance of q_i [J s per unit q_i^2]
  double contact_area_m2 = 0.0;                        ///< flat film area pressed against the plate
  double surface_area_m2 = 0.0;                        ///< wetted inner film area (heat exchange)
  double film_stretch = 1.0;                           ///< representative film stretch [-]
  double film_tension_n_m = 0.0;                       ///< film tension per unit current length [N/m]
  /// The structure's own force on the plate besides the gas's, + upward (a bellows' spring) [N]
  double plate_force_n = 0.0;
};

/// Quasi-static equilibrium of the structure: film shape relaxed, plate force balancing a load.
struct StructureEquilibrium {
  bool converged = false;
  double height_m = 0.0;
  double gauge_pressure_pa = 0.0;
  std::array<double, kMaxShapeDofs> shape{};
  StructureEval eval;
};

class CellStructure {
 public:
  virtual ~CellStructure() = default;

  /// Number of film shape coordinates q (1..kMaxShapeDofs).
  virtual int shapeDofs() const = 0;
  /// Film shape of the flat, unstretched cell.
  virtual std::array<double, kMaxShapeDofs> restShape() const = 0;
  /// Geometry and film forces at plate height h [m] and shape q.
  virtual StructureEval evaluate(double height_m, const double* shape) const = 0;
  /// Height above which the model is no longer meaningful (film taken as fully round) [m].
  virtual double heightLimit(const double* shape) const = 0;
  /// False when the configuration lies outside what the model or the film can take (past the
  /// film's rupture stretch, or a height its geometry cannot describe).
  virtual bool withinLimits(double /*height_m*/, const double* /*shape*/) const { return true; }
  /// Short description for logs and reports.
  virtual std::string describe() const = 0;

  /// Film shape that balances gauge pressure p at fixed plate height h (dW/dq = p dV/dq).
  std::array<double, kMaxShapeDofs> relaxedShape(double height_m, double gauge_pressure_pa,
                                                 const double* initial_shape = nullptr) const;
  /// Height and shape at which pressure p and the structure's own plate force carry the load
  /// (plate at rest): the cell's
  /// h(p, load) characteristic (the paper's section 5 relation, from our model). Not converged
  /// when the film would have to leave its limits.
  StructureEquilibrium equilibriumAtPressure(double gauge_pressure_pa, double load_n) const;
  /// Pressure and shape that hold the plate at height h under the load (with the structure's
  /// own plate force).
  StructureEquilibrium equilibriumAtHeight(double height_m, double load_n) const;
};

}  // namespace nursing_bed
