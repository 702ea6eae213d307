// The plate's weight bound on a settled cell's height (ROS-free): no load is less than the
// plate's own weight, and the plate alone rests the higher the more pressure holds it, so a
// settled plate's mean pressure bounds its height from above (p A_eff(h) >= m_plate g).
#pragma once

#include <vector>

#include "nursing_bed/core/observer/reading_noise.h"
#include "nursing_bed/core/physics/cell_structure.h"

namespace nursing_bed {

class WeightBound {
 public:
  /// `window_s`: both valves shut this long (the plate settled), then the readings averaged
  /// over as long again; 0: off.
  explicit WeightBound(double window_s = 0.0) : window_s_(window_s) {}
  /// Tabulates the plate alone's rests (weight `plate_weight_n`) at heights up to 0.95 `top_m`.
  void tabulate(const CellStructure& structure, double plate_weight_n, double top_m);
  /// Below the least of the plate alone's rest pressures the plate cannot be lifted [Pa].
  double lowestLiftedPressure() const;
  /// The highest height at which the plate alone rests at no more than `gauge_pressure_pa`: a
  /// settled plate at that mean pressure is not above it (+inf beyond the table's top) [m].
  double plateAloneHeight(double gauge_pressure_pa) const;

  /// Forgets the quiet window under way.
  void reset();
  /// Accumulates the readings while both valves are shut and the plate is lifted; true (with
  /// their mean and standard error, from the readings' noise) at the end of each window after
  /// the first.
  bool quietMean(double gauge_pressure_pa, bool lifted, bool valves_shut, double dt_s, const ReadingNoise& noise,
                 double* mean_pa, double* se_pa);

 private:
  double window_s_;
  std::vector<double> h_m_, p_pa_;  ///< rests of the plate alone (NaN: none found)
  double quiet_s_ = 0.0;            ///< both valves shut this long [s]
  double quiet_sum_pa_ = 0.0;       ///< readings summed over the current window
  long quiet_count_ = 0;
};

}  // namespace nursing_bed
