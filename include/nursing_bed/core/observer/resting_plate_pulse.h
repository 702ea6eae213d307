// The gas a valve passes as it opens on a resting plate (ROS-free): the observer's count of
// each isolated valve pulse, taken through the plate's swing within the period.
// SI units: kg, Pa (gauge unless named absolute), s.
#pragma once

#include <limits>

#include "nursing_bed/core/physics/cell_model.h"

namespace nursing_bed {

/**
 * A valve opening on a plate at rest swings the cell's pressure within its first period and
 * after it: the plate and its load ring on the gas spring at 40-100 Hz, by tens to hundreds of
 * Pa at a low pressure. Readings at the period's ends do not see the swing, and a few ms' error
 * in when the valve acted moves the pulse onto another part of it, so at low pressure the flow
 * at the readings miscounts every isolated pulse, always the same way (a 5 ms vent at 100 Pa
 * under 2 N by 14 %). From rest the swing is the model's: the estimate's plate at rest under the
 * pressure read while the valves were shut (neither the readings' noise nor the pulse's own
 * swing enter), run through the period with the valves, passes the gas the pulse counts.
 * Later periods of a train start from a moving plate whose motion the estimate does not know;
 * their flows stay at the readings.
 */
class RestingPlatePulse {
 public:
  /// `swing_pressure_pa`: the largest |gauge pressure| at which the swing is taken; above it
  /// the swing is small against the pressure and the flows stay at the readings.
  explicit RestingPlatePulse(double swing_pressure_pa = 300.0) : swing_pressure_pa_(swing_pressure_pa) {}
  /// The plate at rest (a reset cell): the next opening is counted through its swing.
  void reset();
  /// The plate's motion unknown (readings lost): openings are counted at the readings until
  /// the valves have been shut for the ring-down time.
  void interrupt();
  /// One period: `in` the openings acting over it (flows at the readings), `old_pressure_pa`
  /// the reading at its start, `estimate` the gas and plate at its start with its absolute
  /// pressure. Returns the factor the flows at the readings take: the model's gas through the
  /// swing over the gas at the readings (1 unless a valve opens on a resting plate).
  double factor(CellModel& model, double time_s, const CellModel::StateVector& estimate, double estimate_pressure_pa,
                const CellInputs& in, double old_pressure_pa, double dt_s);

  /// A valve edge rings the plate on its gas spring; the swing has died down within this [s].
  static constexpr double kRingDownS = 0.03;

 private:
  double swing_pressure_pa_;
  double quiet_s_ = std::numeric_limits<double>::infinity();            ///< both valves shut this long [s]
  double rest_pressure_pa_ = std::numeric_limits<double>::quiet_NaN();  ///< the readings while shut, filtered
};

}  // namespace nursing_bed
