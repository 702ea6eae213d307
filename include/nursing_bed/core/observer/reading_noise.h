#pragma once
// The noise of a cell's pressure readings, measured while its gas is still.

#include <limits>

namespace nursing_bed {

/**
 * The sd of a pressure reading, measured from successive readings while nothing moves the gas
 * (both valves shut, the plate settled): for white noise the difference of two readings has
 * twice a reading's variance. A configured sd is only the sensor's data sheet (the observer's
 * default is 15 Pa, the emulator's readings have 10.6 Pa), and the observer's correction of the
 * flows' noise bias near ambient goes with its square: kept at 15 Pa against 10.6 Pa, a light
 * plate's descent at 40-77 Pa was counted 0.4 % too large (unit test
 * CellObserver.MeasuresItsReadingsNoiseAndTakesItsBiasOffALightPlatesDescent; measured, 0.07 %).
 *  - Starts at the configured sd, weighted as `prior_readings` readings.
 *  - A difference beyond five sds (a load step, a valve edge) is left out.
 *  - Remembers about `memory_readings` readings (a sensor's noise may change with its
 *    surroundings, a pump running).
 */
class ReadingNoise {
 public:
  ReadingNoise(double configured_sd, double prior_readings, double memory_readings);
  /// A reading taken while the gas is still.
  void addQuiet(double reading);
  /// The gas moved (or a reading was missing): the next quiet reading starts a new pair.
  void interrupt() { last_ = std::numeric_limits<double>::quiet_NaN(); }
  double sd() const;
  /// Differences counted so far (not the prior).
  double pairs() const { return pairs_; }

 private:
  double prior_var_, prior_n_, memory_n_;
  double sum_half_sq_ = 0.0, pairs_ = 0.0;
  double last_ = std::numeric_limits<double>::quiet_NaN();
};

}  // namespace nursing_bed
