#include "nursing_bed/core/gap/progress.h"

#include <algorithm>
#include <cmath>
#include <sstream>

namespace nursing_bed {
namespace gap {

void ProgressEstimate::plan(int steps, double units) {
  std::lock_guard<std::mutex> lock(mutex_);
  planned_ += std::max(0, steps) * units;
}

void ProgressEstimate::unplan(int steps, double units) {
  std::lock_guard<std::mutex> lock(mutex_);
  planned_ = std::max(done_, planned_ - std::max(0, steps) * units);
}

void ProgressEstimate::done(double units, double elapsed_s) {
  std::lock_guard<std::mutex> lock(mutex_);
  done_ += units;
  planned_ = std::max(planned_, done_);
  last_done_s_ = elapsed_s;
}

void ProgressEstimate::start(double elapsed_s) {
  std::lock_guard<std::mutex> lock(mutex_);
  started_s_ = elapsed_s;
}

double ProgressEstimate::secondsLeft(double elapsed_s) const {
  std::lock_guard<std::mutex> lock(mutex_);
  if (!(done_ > 0.0) || !(last_done_s_ > started_s_)) return NAN;
  const double per_unit = (last_done_s_ - started_s_) / done_;
  // The step under way has already spent part of its share.
  return std::max(0.0, (planned_ - done_) * per_unit - (elapsed_s - last_done_s_));
}

std::string ProgressEstimate::line(double elapsed_s) const {
  const double left = secondsLeft(elapsed_s);
  return roughDuration(elapsed_s) + " elapsed, " +
         (std::isfinite(left) ? "about " + roughDuration(left) + " left" : std::string("time left not yet known"));
}

std::string roughDuration(double seconds) {
  std::ostringstream s;
  if (!(seconds >= 0.0)) return "?";
  if (seconds < 90.0) {
    s << static_cast<long>(std::lround(seconds)) << " s";
  } else {
    const double minutes = std::round(seconds / 30.0) / 2.0;  // half minutes
    s << minutes << " min";
  }
  return s.str();
}

}  // namespace gap
}  // namespace nursing_bed
