#pragma once
// The noise of a cell's pressure readings, measured while its gas is still.

#include <limits>

namespace nursing_bed {

/**
 * The sd of a pressure reading, measured from successive readings while nothing moves the gas
 * (both valves shut, the plate settled): for white noise the second difference of three
 * readings, r2 - 2 r1 + r0, has six times a reading's variance, and a slow true change (a
 * patient breathing on the plate, the gas cooling after a fill) hardly enters it (into a
 * first difference a 1.6 Hz sway of 100 Pa puts 5 Pa per 5 ms sample, into a second 0.25 Pa).
 * A configured sd is only the sensor's data sheet (the observer's default is 15 Pa, the
 * emulator's readings have 10.6 Pa), and the observer's correction of the flows' noise bias
 * near ambient goes with its square: kept at 15 Pa against 10.6 Pa, a light plate's descent at
 * 40-77 Pa was counted 0.4 % too large (unit test
 * CellObserver.MeasuresItsReadingsNoiseAndTakesItsBiasOffALightPlatesDescent; measured, 0.07 %).
 *  - Starts at the configured sd, weighted as `prior_readings` readings.
 *  - A second difference beyond five of its sds (a load step, a valve edge) is left out.
 *  - Remembers about `memory_readings` readings (a sensor's noise may change with its
 *    surroundings, a pump running).
 *
 * The sd of a mean of n readings is sd / sqrt(n) only for independent readings. Read faster
 * than the sensor (or the terminal's ADC) refreshes, or through an anti-aliasing filter,
 * successive readings repeat or follow each other, and the mean's noise is larger than that
 * (the weight bound, which tests a mean of readings, then takes noise for a drifted
 * inventory). So the mean's noise is measured too, as the sd of means of blocks of
 * `block_readings` successive quiet readings (again from second differences, of the block
 * means), never taken below the independent readings'.
 */
class ReadingNoise {
 public:
  ReadingNoise(double configured_sd, double prior_readings, double memory_readings, int block_readings = 20);
  /// A reading taken while the gas is still.
  void addQuiet(double reading);
  /// The gas moved (or a reading was missing): the next quiet readings start anew.
  void interrupt();
  double sd() const;
  /// The sd of the mean of `readings` successive quiet readings: sd / sqrt(readings), or more
  /// where the block means say the readings are correlated (never less).
  double meanSd(double readings) const;
  /// How much larger a mean's variance is than independent readings' (>= 1; 1 until measured).
  double meanInflation() const;
  /// Second differences counted so far (not the prior).
  double differences() const { return differences_; }

 private:
  double prior_var_, prior_n_, memory_n_;
  double sum_var_ = 0.0, differences_ = 0.0;  ///< d2^2 / 6 summed, and their count
  double last_ = std::numeric_limits<double>::quiet_NaN(), before_last_ = std::numeric_limits<double>::quiet_NaN();
  /// Means of successive blocks: the one being summed, and the last two complete ones.
  void addToBlock(double reading);
  int block_readings_;
  double block_sum_ = 0.0;
  int block_count_ = 0;
  double block_last_ = std::numeric_limits<double>::quiet_NaN(),
         block_before_last_ = std::numeric_limits<double>::quiet_NaN();
  double sum_block_var_ = 0.0, block_differences_ = 0.0;  ///< of the block means: d2^2 / 6 summed, and their count
};

}  // namespace nursing_bed
