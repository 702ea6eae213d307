// The plate's weight bound on a cell's height (ROS-free): no load is less than the plate's own
// weight, and the plate alone rests the higher the more pressure holds it, so a settled plate's
// mean pressure bounds its height from above (p A_eff(h) >= m_plate g). A plate being lifted
// (inlet open, vent shut, not falling) needs more than that (its guide's damping and its
// acceleration add), so the bound holds while it is lifted too.
#pragma once

#include <vector>

#include "nursing_bed/core/observer/reading_noise.h"
#include "nursing_bed/core/physics/cell_structure.h"

namespace nursing_bed {

class WeightBound {
 public:
  /// `window_s`: both valves shut this long (the plate settled), then the readings averaged
  /// over as long again; `lift_window_s` the same while the plate is lifted; 0: off.
  explicit WeightBound(double window_s = 0.0, double lift_window_s = 0.0)
      : quiet_{window_s, true}, lifting_{lift_window_s, false} {}
  /// Tabulates the plate alone's rests (weight `plate_weight_n`) at heights up to 0.95 `top_m`.
  void tabulate(const CellStructure& structure, double plate_weight_n, double top_m);
  /// Below the least of the plate alone's rest pressures the plate cannot be lifted [Pa].
  double lowestLiftedPressure() const;
  /// The highest height at which the plate alone rests at no more than `gauge_pressure_pa`: a
  /// settled plate at that mean pressure is not above it (+inf beyond the table's top) [m].
  double plateAloneHeight(double gauge_pressure_pa) const;

  /// Forgets the windows under way.
  void reset();
  /// Accumulates the readings while both valves are shut and the plate is off the bed; true
  /// (with their mean and standard error, from the readings' noise) at the end of each window
  /// after the first.
  bool quietMean(double gauge_pressure_pa, bool lifted, bool valves_shut, double dt_s, const ReadingNoise& noise,
                 double* mean_pa, double* se_pa) {
    return quiet_.mean(gauge_pressure_pa, lifted && valves_shut, dt_s, noise, mean_pa, se_pa);
  }
  /// The same while the plate is being lifted (inlet open, vent shut, not falling), each mean
  /// over its own window only (the pressure follows the rising plate).
  bool liftingMean(double gauge_pressure_pa, bool lifted, bool lifting, double dt_s, const ReadingNoise& noise,
                   double* mean_pa, double* se_pa) {
    return lifting_.mean(gauge_pressure_pa, lifted && lifting, dt_s, noise, mean_pa, se_pa);
  }

 private:
  /// Readings averaged while a condition holds, after it has held one window (the plate's
  /// response to the valves' last change has passed); a mean at the end of each window, of
  /// every reading since the first (`cumulative`: a settled plate) or of that window's.
  struct Window {
    double length_s = 0.0;  ///< 0: off
    bool cumulative = true;
    double held_s = 0.0;  ///< the condition has held this long [s]
    double sum_pa = 0.0;  ///< readings summed since the first window (cumulative) or this one
    long count = 0;
    bool mean(double gauge_pressure_pa, bool holds, double dt_s, const ReadingNoise& noise, double* mean_pa,
              double* se_pa);
    void reset() { held_s = sum_pa = 0.0, count = 0; }
  };
  Window quiet_, lifting_;
  std::vector<double> h_m_, p_pa_;  ///< rests of the plate alone (NaN: none found)
};

}  // namespace nursing_bed
