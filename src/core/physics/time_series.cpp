#include "nursing_bed/core/physics/time_series.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace nursing_bed {

TimeSeries::TimeSeries(std::vector<double> times_s, std::vector<double> values)
    : times_(std::move(times_s)), values_(std::move(values)) {
  if (times_.size() != values_.size())
    throw std::invalid_argument("time series: " + std::to_string(times_.size()) + " times but " +
                                std::to_string(values_.size()) + " values");
  for (std::size_t i = 0; i < times_.size(); ++i) {
    if (!std::isfinite(times_[i]) || !std::isfinite(values_[i]))
      throw std::invalid_argument("time series: sample " + std::to_string(i) + " is not finite");
    if (i > 0 && !(times_[i] > times_[i - 1]))
      throw std::invalid_argument("time series: time not strictly increasing at sample " + std::to_string(i));
  }
}

double TimeSeries::at(double time_s) const {
  const std::size_t n = times_.size();
  if (n == 0) return 0.0;
  if (time_s <= times_.front()) return values_.front();
  if (time_s >= times_.back()) return values_.back();
  if (cursor_ >= n - 1 || times_[cursor_] > time_s || times_[cursor_ + 1] < time_s) {
    // Jump by bisection; monotone queries then step one sample at a time.
    cursor_ = static_cast<std::size_t>(std::upper_bound(times_.begin(), times_.end(), time_s) - times_.begin()) - 1;
  }
  const double t0 = times_[cursor_], t1 = times_[cursor_ + 1];
  const double f = (time_s - t0) / (t1 - t0);
  return values_[cursor_] + f * (values_[cursor_ + 1] - values_[cursor_]);
}

double TimeSeries::integral() const {
  double sum = 0.0;
  for (std::size_t i = 1; i < times_.size(); ++i)
    sum += 0.5 * (values_[i] + values_[i - 1]) * (times_[i] - times_[i - 1]);
  return sum;
}

}  // namespace nursing_bed
