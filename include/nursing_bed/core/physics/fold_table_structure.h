// A CellStructure with a fold state: two FE tables of gas volume and plate force, one for the
// bag with its middle faces folded inward beside the middle connection and one with them flipped
// out, and the pressures at which the fold snaps open (rising) and closed again (falling).
// Built from the FE bag's loaded h(p) curves, rising and falling (scripts/fold_table.py).
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "nursing_bed/core/io/status.h"
#include "nursing_bed/core/physics/tabulated_structure.h"

namespace nursing_bed {

struct FoldTableData {
  std::string description;
  StructureTableData folded;         ///< middle faces folded in (before the snap)
  StructureTableData open;           ///< middle faces flipped out (after the snap)
  std::vector<double> snap_loads_n;  ///< plate loads of the snap pressures, strictly increasing
  std::vector<double> open_pa;       ///< the folded bag under this load snaps open above this gauge pressure
  std::vector<double> close_pa;      ///< the open bag under this load folds again below this gauge pressure
  double fold_time_s = 0.02;         ///< time scale of the snap [s]
  double snap_width_pa = 200.0;      ///< pressure band over which a snap sets in [Pa]

  /// Success when consistent, else what is wrong (names the field).
  Status validate() const;
};

/**
 * Shape coordinates: q0 the gauge pressure the film is relaxed to (in 10 kPa, as
 * TabulatedStructure's) and q1 the fold state s in [0, 1] (0 folded, 1 open). V, A_eff and dV/dq0
 * blend the two tables by s. The snap pressures depend on the load (not monotonically on the
 * height): the load is read as the plate force of the branch the bag would leave, F_folded(h, q0)
 * for opening and F_open(h, q0) for closing. The fold is bistable between close_pa(F) and
 * open_pa(F) (both states stay), opens above open_pa and closes below close_pa: ds/dt = g / fold_time_s
 * with g = a_open (1 - s) - a_close s + 4 s (1 - s)(s - 1/2), a_* logistic in the pressure's
 * distance past the threshold. Hysteresis of a folding membrane, as the FE bag shows it.
 * The snap's volume change dV/ds = V_open - V_folded is p dV work of the gas (its energy follows
 * the blended volume), balanced in the fold's own equation by q0 dV/ds, so the fold still moves
 * at the rate above.
 */
class FoldTableStructure : public CellStructure {
 public:
  /// Throws std::invalid_argument naming the field when the data are inconsistent.
  FoldTableStructure(FoldTableData data, double film_relaxation_time_s, double dead_volume_m3,
                     double fold_fraction = PillowParams{}.fold_fraction);
  /// Reads the YAML file; throws std::runtime_error naming the file and the key.
  static FoldTableData load(const std::string& path);

  int shapeDofs() const override { return 2; }
  std::array<double, kMaxShapeDofs> restShape() const override;
  StructureEval evaluate(double height_m, const double* shape) const override;
  double heightLimit(const double* shape) const override;
  bool withinLimits(double height_m, const double* shape) const override;
  std::string describe() const override;
  /// The film's pressure as TabulatedStructure's; the fold at the stable state its flow
  /// ds/dt = foldRate reaches from the initial s (so the side it was on between the snap
  /// pressures), found by a bracketed search rather than a Newton step across the cubic.
  std::array<double, kMaxShapeDofs> relaxedShape(double height_m, double gauge_pressure_pa,
                                                 const double* initial_shape = nullptr) const override;
  /// The film relaxed as relaxedShape's; the fold moved by ds/dt = foldRate over dt_s
  /// (midpoint steps of a fifth of fold_time_s), never past the state relaxedShape reaches.
  std::array<double, kMaxShapeDofs> shapeAfter(double height_m, double gauge_pressure_pa, const double* initial_shape,
                                               double dt_s) const override;
  /// Branch 0 enters the fold shut (s = 0), branch 1 open (s = 1); branchOf reads s >= 1/2 as open.
  int branchCount() const override { return 2; }
  void enterBranch(int branch, double* shape) const override;
  int branchOf(const double* shape) const override;

  /// The fold's rate ds/dt at fold state s, film pressure p and plate height h [1/s].
  double foldRate(double s, double gauge_pressure_pa, double height_m) const;
  const FoldTableData& data() const { return data_; }

 private:
  FoldTableData data_;
  TabulatedStructure folded_;
  TabulatedStructure open_;
};

}  // namespace nursing_bed
