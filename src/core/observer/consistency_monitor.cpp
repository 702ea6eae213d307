#include "nursing_bed/core/observer/consistency_monitor.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include "nursing_bed/core/io/errors.h"

namespace nursing_bed {
Status ConsistencyMonitorParams::validate() const {
  ErrorList errors;
  auto nonNegative = [&](const char* key, double v) {
    errors.addIf(!(v >= 0.0 && std::isfinite(v)), key, " must be finite and >= 0, got ", v);
  };
  auto positive = [&](const char* key, double v) {
    errors.addIf(!(v > 0.0 && std::isfinite(v)), key, " must be finite and > 0, got ", v);
  };
  nonNegative("frozen_s", frozen_s);
  nonNegative("settle_s", settle_s);
  positive("reference_time_s", reference_time_s);
  nonNegative("drift_sds", drift_sds);
  nonNegative("min_drift_pa", min_drift_pa);
  positive("cusum_threshold_pa_s", cusum_threshold_pa_s);
  positive("surprise_m", surprise_m);
  positive("jump_pa", jump_pa);
  return errors.status();
}

namespace {
const ConsistencyMonitorParams& validated(const ConsistencyMonitorParams& p) {
  const Status valid = p.validate();
  if (!valid.ok()) throw std::invalid_argument("consistency monitor parameters: " + valid.message());
  return p;
}
}  // namespace

ConsistencyMonitor::ConsistencyMonitor(const ConsistencyMonitorParams& params) : params_(validated(params)) {}

bool ConsistencyMonitor::update(const ConsistencySample& sample, double dt_s) {
  if (!std::isfinite(sample.gauge_pressure_pa) || !(dt_s > 0.0)) {
    interrupt();
    return false;
  }
  if (inconsistent()) return false;
  std::ostringstream why;
  const double previous_pa = last_reading_pa_;
  const bool jump = jumped(sample);
  if (jump) {
    why << "pressure jumped from " << previous_pa << " to " << sample.gauge_pressure_pa
        << " Pa in one reading under a settled plate";
  } else if (frozen(sample.gauge_pressure_pa, dt_s)) {
    why << "pressure reading frozen at " << sample.gauge_pressure_pa << " Pa for " << same_for_s_ << " s";
  } else if (std::fabs(sample.correction_m) > params_.surprise_m) {
    why << "the plate's weight bound corrected the height by " << 1e3 * sample.correction_m << " mm (limit "
        << 1e3 * params_.surprise_m << " mm)";
  } else if (innovation(sample, dt_s)) {
    why << "pressure " << sample.gauge_pressure_pa << " Pa departs from the hold's " << reference_pa_
        << " Pa with both valves shut (CUSUM " << cusum() << " Pa s)";
  }
  reason_ = why.str();
  return inconsistent();
}

bool ConsistencyMonitor::jumped(const ConsistencySample& sample) const {
  // Settled before this reading (the valves acting over its period included): a plate still
  // ringing after a fill from flat swings by kilopascals between two readings.
  const bool settled = sample.valves_shut && shut_for_s_ >= params_.settle_s;
  return settled && have_reading_ && std::fabs(sample.gauge_pressure_pa - last_reading_pa_) > params_.jump_pa;
}

bool ConsistencyMonitor::frozen(double gauge_pressure_pa, double dt_s) {
  same_for_s_ = have_reading_ && gauge_pressure_pa == last_reading_pa_ ? same_for_s_ + dt_s : 0.0;
  last_reading_pa_ = gauge_pressure_pa;
  have_reading_ = true;
  return params_.frozen_s > 0.0 && same_for_s_ >= params_.frozen_s;
}

bool ConsistencyMonitor::innovation(const ConsistencySample& sample, double dt_s) {
  // Page's CUSUM: g+ = max(0, g+ + (nu - k) dt), g- likewise for -nu, with nu the reading less
  // the hold's running mean and k the drift the noise is allowed. Nothing counts until the
  // plate has settled after the last valve edge.
  shut_for_s_ = sample.valves_shut ? shut_for_s_ + dt_s : 0.0;
  if (shut_for_s_ < params_.settle_s) {
    have_reference_ = false;
    up_pa_s_ = down_pa_s_ = 0.0;
    return false;
  }
  const double p = sample.gauge_pressure_pa;
  if (!have_reference_) {
    reference_pa_ = p;
    have_reference_ = true;
    return false;
  }
  const double nu = p - reference_pa_;
  const double k = std::max(params_.min_drift_pa, params_.drift_sds * sample.noise_sd_pa);
  up_pa_s_ = std::max(0.0, up_pa_s_ + (nu - k) * dt_s);
  down_pa_s_ = std::max(0.0, down_pa_s_ + (-nu - k) * dt_s);
  if (cusum() >= params_.cusum_threshold_pa_s) return true;
  reference_pa_ += (p - reference_pa_) * std::min(1.0, dt_s / params_.reference_time_s);
  return false;
}

void ConsistencyMonitor::interrupt() {
  have_reading_ = false;
  same_for_s_ = 0.0;
  shut_for_s_ = 0.0;
  have_reference_ = false;
  up_pa_s_ = down_pa_s_ = 0.0;
}

void ConsistencyMonitor::clear() {
  reason_.clear();
  interrupt();
}

double ConsistencyMonitor::cusum() const { return std::max(up_pa_s_, down_pa_s_); }

}  // namespace nursing_bed
