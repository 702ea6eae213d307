#include "nursing_bed/core/observer/reading_noise.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace nursing_bed {

namespace {
// Block-mean differences the inflation's prior of 1 (independent readings) counts as.
constexpr double kInflationPriorBlocks = 10.0;
}  // namespace

ReadingNoise::ReadingNoise(double configured_sd, double prior_readings, double memory_readings, int block_readings)
    : prior_var_(configured_sd * configured_sd),
      prior_n_(prior_readings),
      memory_n_(memory_readings),
      block_readings_(block_readings) {
  if (!(configured_sd > 0.0) || !(prior_readings > 0.0) || !(memory_readings > prior_readings) || block_readings < 2)
    throw std::invalid_argument(
        "ReadingNoise: the sd and the prior must be > 0, the memory longer than the prior, a block at least 2 "
        "readings");
}

void ReadingNoise::interrupt() {
  last_ = before_last_ = std::numeric_limits<double>::quiet_NaN();
  block_last_ = block_before_last_ = std::numeric_limits<double>::quiet_NaN();
  block_sum_ = 0.0;
  block_count_ = 0;
}

void ReadingNoise::addQuiet(double reading) {
  if (!std::isfinite(reading)) {
    interrupt();
    return;
  }
  addToBlock(reading);
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

void ReadingNoise::addToBlock(double reading) {
  block_sum_ += reading;
  if (++block_count_ < block_readings_) return;
  const double mean = block_sum_ / block_readings_;
  block_sum_ = 0.0;
  block_count_ = 0;
  const double m0 = block_before_last_, m1 = block_last_;
  block_before_last_ = block_last_;
  block_last_ = mean;
  if (!std::isfinite(m0) || !std::isfinite(m1)) return;
  const double d2 = mean - 2.0 * m1 + m0;
  // As for single readings: beyond five sds of the expected d2 the pressure moved.
  const double block_var = meanInflation() * sd() * sd() / block_readings_;
  if (d2 * d2 > 25.0 * 6.0 * block_var) return;
  sum_block_var_ += d2 * d2 / 6.0;
  block_differences_ += 1.0;
  const double memory = memory_n_ / block_readings_;
  if (block_differences_ > memory) {
    sum_block_var_ *= memory / block_differences_;
    block_differences_ = memory;
  }
}

double ReadingNoise::meanInflation() const {
  const double white_block_var = sd() * sd() / block_readings_;
  const double block_var =
      (white_block_var * kInflationPriorBlocks + sum_block_var_) / (kInflationPriorBlocks + block_differences_);
  return std::max(1.0, block_var / white_block_var);
}

double ReadingNoise::meanSd(double readings) const {
  return readings > 0.0 ? sd() * std::sqrt(meanInflation() / readings) : std::numeric_limits<double>::infinity();
}

}  // namespace nursing_bed
