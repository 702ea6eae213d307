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
  /// The structure's own force on the plate besides the gas's, + upward (a bellows' spring, an
  /// FE bag's film tension) [N]
  double plate_force_n = 0.0;

  /// Everything the structure puts on the plate at gauge pressure p: p A_eff + plate_force_n [N].
  double plateForce(double gauge_pressure_pa) const { return gauge_pressure_pa * effective_area_m2 + plate_force_n; }
};

/**
 * The folded flat cell below h = 0: the plate presses the flat films onto the bed, and the gas
 * left in the folds under it (`fold_volume_m3`, part of the dead volume) is squeezed out over a
 * depth delta = fold_volume / flat_area, so that dV/dh is continuous at flat and vanishes below:
 *   V(h) = V(0) - V_fold (1 - exp(h / delta)),   A_eff = dV/dh = A_flat exp(h / delta).
 * The gas does work only as the volume changes (p dV), its plate force is p_gauge dV/dh, and it
 * never falls below V(0) - V_fold > 0; the films and the bed carry the rest of the load
 * (CellParams' bed contact). A contact stiffness k with k delta above a load lets the gas lift
 * that load off smoothly: the pressure that holds the plate rises monotonically up to flat.
 */
class FlatFold {
 public:
  /// Throws std::invalid_argument unless both are positive and finite.
  FlatFold(double fold_volume_m3, double flat_area_m2);
  /// `at_flat`, the evaluation at h = 0, carried to `height_m` < 0 (unchanged at h >= 0).
  StructureEval below(double height_m, StructureEval at_flat) const;
  double depth() const { return depth_m_; }

 private:
  double volume_m3_;
  double area_m2_;
  double depth_m_;
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

  /// Number of quasi-static branches: a structure with a bistable fold has two (0 rising: the
  /// fold stays shut while it can, 1 falling: it stays open while it can); a plain film one.
  virtual int branchCount() const { return 1; }
  /// Puts `shape` on the branch's side of its bistable coordinates (the film's are kept).
  virtual void enterBranch(int /*branch*/, double* /*shape*/) const {}
  /// The branch a relaxed `shape` lies on.
  virtual int branchOf(const double* /*shape*/) const { return 0; }

  /// Film shape that balances gauge pressure p at fixed plate height h (dW/dq = p dV/dq),
  /// reached from `initial_shape` (the rest shape if null). A damped Newton solve; a structure
  /// whose coordinates have a closed-form or bistable balance may solve it itself.
  virtual std::array<double, kMaxShapeDofs> relaxedShape(double height_m, double gauge_pressure_pa,
                                                         const double* initial_shape = nullptr) const;
  /// The shape `dt_s` after `initial_shape` at height h and pressure p: each coordinate as far
  /// towards relaxedShape as its own equation moves it in that time. By default the film
  /// relaxes within a period; a structure with a slower coordinate (a fold) integrates it.
  virtual std::array<double, kMaxShapeDofs> shapeAfter(double height_m, double gauge_pressure_pa,
                                                       const double* initial_shape, double /*dt_s*/) const {
    return relaxedShape(height_m, gauge_pressure_pa, initial_shape);
  }
  /// Height and shape at which pressure p and the structure's own plate force carry the load
  /// (plate at rest): the cell's
  /// h(p, load) characteristic (the paper's section 5 relation, from our model). Not converged
  /// when the film would have to leave its limits.
  StructureEquilibrium equilibriumAtPressure(double gauge_pressure_pa, double load_n) const;
  /// Pressure and shape that hold the plate at height h under the load (with the structure's
  /// own plate force), on `branch` (each trial pressure's shape entered on it, see enterBranch).
  StructureEquilibrium equilibriumAtHeight(double height_m, double load_n, int branch = 0) const;
};

}  // namespace nursing_bed
