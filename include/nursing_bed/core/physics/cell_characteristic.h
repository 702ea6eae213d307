// The cell's quasi-static characteristic, tabulated once: equilibrium gauge pressure and gas
// volume for every (plate height, load), per branch of a bistable structure. It is the paper's
// section-5 idea (set the height through the pressure) made load-aware, and what the height
// controller predicts with.
#pragma once

#include <array>
#include <memory>
#include <vector>

#include "nursing_bed/core/physics/cell_model.h"
#include "nursing_bed/core/physics/cell_structure.h"

namespace nursing_bed {

class CellCharacteristic {
 public:
  /// Tabulates the structure `params` select (makeCellStructure: the pillow model or an FE
  /// table; the controller must predict with the structure the cell has) on a grid of heights
  /// 0..height_max and loads 0..load_max, each branch. Costly (0.1-4 s); use shared() to build it
  /// once per parameter set.
  CellCharacteristic(const CellParams& params, double height_max_m = 0.20, double height_step_m = 0.001,
                     double load_max_n = 60.0, double load_step_n = 1.0);

  /// One table per distinct parameter set, built on first use and shared by every user in the
  /// process for its lifetime (thread-safe).
  static std::shared_ptr<const CellCharacteristic> shared(const CellParams& params);

  /// A film shape (CellStructure's coordinates), carried between calls as a warm start.
  using Shape = std::array<double, kMaxShapeDofs>;

  /// The structure's quasi-static branches (two for a bistable fold, else one) and the one a
  /// relaxed shape lies on; every query below takes the branch it is asked about (0: rising).
  int branches() const { return static_cast<int>(tables_.size()); }
  int branchOf(const Shape& shape) const { return structure_->branchOf(shape.data()); }
  /// The flat, unstretched cell's shape (a warm start for relaxedAt).
  Shape restShape() const { return structure_->restShape(); }

  /// Equilibrium gauge pressure [Pa] that holds `load_n` at `height_m`; NaN out of reach.
  double pressureAt(double height_m, double load_n, int branch = 0) const;
  /// Gas volume [m^3] at that equilibrium; NaN out of reach.
  double volumeAt(double height_m, double load_n, int branch = 0) const;
  /// Load [N] that gauge pressure p carries at rest at height h (inverse in the load).
  double loadAt(double height_m, double gauge_pressure_pa) const;
  /// The cell at plate height h and gauge pressure p with the film relaxed to p: its gas volume
  /// (relaxedVolume), the load p carries there at rest (loadAt) and the branch the film is on,
  /// from one solve of the film.
  struct RelaxedCell {
    double volume_m3;
    double load_n;
    int branch;
  };
  /// `shape` carries the film's shape between calls as a warm start (may be null: the rest
  /// shape). Carried, it also keeps a bistable fold on the side it was on (hysteresis).
  RelaxedCell relaxedAt(double height_m, double gauge_pressure_pa, Shape* shape = nullptr) const;
  /// Height [m] where the cell comes to rest if the valves close now: the gas keeps its
  /// adiabatic invariant K = p_abs V^gamma while the plate settles under `load_n` on `branch`.
  double restingHeight(double adiabatic_invariant, double load_n, int branch = 0) const;
  /// Whether a snap's gap on `branch` lies between the two heights under `load_n`: a closed cell
  /// that moves between them passes it as a snap, not as a swing about its rest.
  bool gapBetween(double height_a_m, double height_b_m, double load_n, int branch = 0) const;
  /// The invariant of the rest at `height_m` (clamped to the branch's reach) under `load_n`:
  /// restingHeight's inverse, non-decreasing in the height.
  double restInvariant(double height_m, double load_n, int branch = 0) const;
  /// Gas volume at plate height h and gauge pressure p with the film relaxed to that pressure
  /// (the film is fast: this is the cell's volume while the plate moves) [m^3].
  double relaxedVolume(double height_m, double gauge_pressure_pa, Shape* shape = nullptr) const;
  /// Small-oscillation stiffness of the plate on the closed cell around its rest at
  /// `height_m` under `load_n` (adiabatic gas spring and shrinking effective area) [N/m]; NaN
  /// where the rests do not rise as the load lightens (out of reach, a snap's unstable side).
  double plateStiffness(double height_m, double load_n, int branch = 0) const;
  /// Rate of change of the adiabatic invariant [Pa m^(3 gamma)/s] when mass flows in at
  /// `mass_flow_kg_s` (negative: out) at temperature `temperature_k` into volume V.
  double invariantRate(double volume_m3, double mass_flow_kg_s, double temperature_k) const;
  /// Adiabatic invariant p_abs V^gamma of a state.
  double invariant(double gauge_pressure_pa, double volume_m3) const;
  /// Largest height the table reaches for this load on `branch` (film limits, table range) [m].
  double maxHeight(double load_n, int branch = 0) const;

  double heightStep() const { return height_step_m_; }
  const CellParams& params() const { return params_; }

 private:
  // One branch's equilibria, row-major over loads: value(load_index, height_index).
  struct Table {
    std::vector<double> pressure_pa, volume_m3, invariant;
    std::vector<int> reachable;  // per load: number of heights with an equilibrium
  };
  Table tabulate(int branch) const;
  const Table& table(int branch) const;
  double at(const std::vector<double>& values, double height_m, double load_n) const;
  CellParams params_;
  std::shared_ptr<const CellStructure> structure_;  // the cell's own (pillow or FE table)
  double height_step_m_, load_step_n_;
  int heights_, loads_;
  std::vector<Table> tables_;  // per branch
};

}  // namespace nursing_bed
