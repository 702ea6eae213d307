// A sampled signal with linear interpolation (e.g. a measured inflow curve, the paper's way of
// driving the model).
#pragma once

#include <cstddef>
#include <string>
#include <vector>

namespace nursing_bed {

class TimeSeries {
 public:
  TimeSeries() = default;
  /// Times must be strictly increasing and finite, values finite; throws std::invalid_argument
  /// naming the first bad sample otherwise.
  TimeSeries(std::vector<double> times_s, std::vector<double> values);

  /// Linear interpolation; held constant outside the sampled range. Amortised O(1) for
  /// monotone queries.
  double at(double time_s) const;
  bool empty() const { return times_.empty(); }
  std::size_t size() const { return times_.size(); }
  double startTime() const { return times_.front(); }
  double endTime() const { return times_.back(); }
  const std::vector<double>& times() const { return times_; }
  const std::vector<double>& values() const { return values_; }
  /// Trapezoidal integral over the sampled range.
  double integral() const;

 private:
  std::vector<double> times_;
  std::vector<double> values_;
  mutable std::size_t cursor_ = 0;
};

}  // namespace nursing_bed
