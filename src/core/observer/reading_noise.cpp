#include "nursing_bed/core/observer/reading_noise.h"

#include <cmath>
#include <stdexcept>

namespace nursing_bed {

ReadingNoise::ReadingNoise(double configured_sd, double prior_readings, double memory_readings)
    : prior_var_(configured_sd * configured_sd), prior_n_(prior_readings), memory_n_(memory_readings) {
  if (!(configured_sd > 0.0) || !(prior_readings > 0.0) || !(memory_readings > prior_readings))
    throw std::invalid_argument("ReadingNoise: the sd and the prior must be > 0, the memory longer than the prior");
}

void ReadingNoise::addQuiet(double reading) {
  if (!std::isfinite(reading)) {
    interrupt();
    return;
  }
  const double previous = last_;
  last_ = reading;
  if (!std::isfinite(previous)) return;
  const double d = reading - previous;
  // var(d) = 2 sd^2; beyond five of its sds the pressure moved.
  if (d * d > 25.0 * 2.0 * sd() * sd()) return;
  sum_half_sq_ += 0.5 * d * d;
  pairs_ += 1.0;
  if (pairs_ > memory_n_) {
    const double keep = memory_n_ / pairs_;
    sum_half_sq_ *= keep;
    pairs_ = memory_n_;
  }
}

double ReadingNoise::sd() const { return std::sqrt((prior_var_ * prior_n_ + sum_half_sq_) / (prior_n_ + pairs_)); }

}  // namespace nursing_bed
