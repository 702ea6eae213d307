// A CellStructure from a table of gas volume and plate force over plate height and gauge
// pressure, computed by the FE membrane model (fe_airbag --mode table; doc/fe_membrane.md).
// Physics reads the file only: it does not depend on the FE code.
#pragma once

#include <string>
#include <vector>

#include "nursing_bed/core/io/status.h"
#include "nursing_bed/core/physics/cell_structure.h"
#include "nursing_bed/core/physics/pillow_structure.h"

namespace nursing_bed {

struct StructureTableData {
  std::string description;
  std::vector<double> heights_m;                   ///< strictly increasing, > 0
  std::vector<double> pressures_pa;                ///< strictly increasing, > 0
  std::vector<std::vector<double>> volume_m3;      ///< [height][pressure], > 0
  std::vector<std::vector<double>> plate_force_n;  ///< [height][pressure]

  /// Success when consistent, else what is wrong (names the field).
  Status validate() const;
};

/**
 * One shape coordinate q: the gauge pressure the film is relaxed to, in units of 10 kPa.
 * evaluate(h, q) gives V(h, q) by bilinear interpolation, A_eff = dV/dh of that volume (the gas
 * works through its own volume, paper eq. 14) and the film's own plate force
 * q (F(h, q) / q - A_eff), so that at p = q the plate carries the FE bag's force F(h, p) and the
 * cell's quasi-static h(p, load) is the FE's. The film balance dW/dq = q dV/dq makes q relax to
 * the gas gauge pressure in film_relaxation_time_s.
 * Below the lowest tabulated pressure the force per pressure is the lowest column's and each
 * row's volume follows its first two columns towards q = 0 (the film going slack); below the
 * lowest height the lowest row's force per pressure is used and V follows the lowest rows' dV/dh
 * down to the dead volume, joined to it smoothly, with dV/dq the slope of that volume; below
 * h = 0 the plate presses the folded cell (FlatFold, over the lowest row's area, the film's own
 * force then the bed contact's); above the highest height, or with the film relaxed to a
 * pressure above the highest tabulated one (the force is extrapolated there), the cell is
 * outside its limits (withinLimits false): no equilibrium is taken from beyond the FE.
 */
class TabulatedStructure : public CellStructure {
 public:
  /// Throws std::invalid_argument naming the field when the table is inconsistent.
  /// `dead_volume_m3`: the gas volume left at zero height (fitting, tube, folds) [m^3]; the
  /// cell's structure parameter, whichever structure it runs on. `fold_fraction`: the part of it
  /// squeezed out of the folds by a plate pressing the flat cell, in (0, 1).
  TabulatedStructure(StructureTableData table, double film_relaxation_time_s = PillowParams{}.film_relaxation_time_s,
                     double dead_volume_m3 = PillowParams{}.dead_volume_m3,
                     double fold_fraction = PillowParams{}.fold_fraction);
  /// Reads the YAML table; throws std::runtime_error naming the file and the key.
  static StructureTableData load(const std::string& path);

  int shapeDofs() const override { return 1; }
  std::array<double, kMaxShapeDofs> restShape() const override;
  StructureEval evaluate(double height_m, const double* shape) const override;
  double heightLimit(const double* shape) const override;
  bool withinLimits(double height_m, const double* shape) const override;
  std::string describe() const override;

  const StructureTableData& table() const { return table_; }

 private:
  /// Bilinear value of grid g at (h, p), h and p clamped to the table.
  double interpolate(const std::vector<std::vector<double>>& g, double h, double p) const;
  /// The cell's gas volume at plate height h >= 0 with the film at pressure q, extended below
  /// the lowest row and the lowest pressure and joined to the dead volume, and its slopes.
  struct VolumeAt {
    double volume_m3 = 0.0;
    double dvdh_m2 = 0.0;
    double dvdq_m3_pa = 0.0;
  };
  VolumeAt volumeAt(double height_m, double q_pa) const;

  StructureTableData table_;
  double relaxation_time_s_;
  double dead_volume_m3_;
  FlatFold fold_;  // below h = 0
};

}  // namespace nursing_bed
