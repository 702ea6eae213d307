// The plate's height and speed from noisy height readings and its force balance (ROS-free).
#pragma once

#include "nursing_bed/core/control/plate_landing.h"

namespace nursing_bed {

/**
 * An alpha-beta tracker whose prediction carries the plate's acceleration from its force
 * balance: it smooths the readings' noise without the lag a plain filter of the readings'
 * difference has (the dynamics come from the model; the readings only correct its error, with
 * both of the error's poles at -bandwidth). Two readings' difference over 5 ms turns 0.1 mm of
 * noise into 28 mm/s of speed; this tracker at 40 /s into about 1 mm/s.
 */
class PlateTracker {
 public:
  explicit PlateTracker(double bandwidth_per_s = 40.0) : bandwidth_per_s_(bandwidth_per_s) {}

  /// Starts from a reading at rest.
  void reset(double height_m);
  /// One period of `dt_s`: predicts with `acceleration_m_s2` (upwards), corrects by the reading.
  const PlateState& update(double dt_s, double height_m, double acceleration_m_s2);
  const PlateState& state() const { return state_; }
  /// The tracked speed's noise [m/s] from independent reading noise of `height_sd_m`.
  double speedSd(double height_sd_m, double dt_s) const;

 private:
  double bandwidth_per_s_;
  bool started_ = false;
  PlateState state_;
};

}  // namespace nursing_bed
