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
  const double r0 = before_last_, r1 = last_;
  before_last_ = last_;
  last_ = reading;
  if (!std::isfinite(r0) || !std::isfinite(r1)) return;
  const double d2 = reading - 2.0 * r1 + r0;
  // var(d2) = 6 sd^2; beyond five of its sds the pressure moved.
  if (d2 * d2 > 25.0 * 6.0 * sd() * sd()) return;
  sum_var_ += d2 * d2 / 6.0;
  differences_ += 1.0;
  if (differences_ > memory_n_) {
    sum_var_ *= memory_n_ / differences_;
    differences_ = memory_n_;
  }
}

double ReadingNoise::sd() const { return std::sqrt((prior_var_ * prior_n_ + sum_var_) / (prior_n_ + differences_)); }

}  // namespace nursing_bed
