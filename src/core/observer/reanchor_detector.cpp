#include "nursing_bed/core/observer/reanchor_detector.h"

#include <algorithm>
#include <cmath>

namespace nursing_bed {
namespace {

// A light plate rung by a vent edge: its pressure swings for a few of its 40-100 Hz periods
// and the descent it starts (or stops) takes a few tens of ms to reach its steady pressure.
constexpr double kVentEdgeSettleS = 0.1;

}  // namespace

ReanchorDetector::ReanchorDetector(double reanchor_time_s, double period_s, double flat_pressure_pa)
    : reanchor_time_s_(reanchor_time_s), period_s_(period_s), flat_pressure_pa_(flat_pressure_pa) {}

void ReanchorDetector::reset() {
  flat_for_s_ = -1.0;
  last_sample_s_ = -1.0;
  sub_ambient_flat_until_s_ = -1.0;
  venting_ = false;
  settled_from_s_ = -1.0;
}

bool ReanchorDetector::update(double now_s, const ObserverInputs& applied, double gauge_pressure_pa, double* mean_pa) {
  const bool to_vacuum = applied.valves.vent > 0.0 && applied.vent_back_pressure_pa != 0.0;
  const bool venting = applied.valves.vent > 0.0;
  if (venting != venting_) {
    venting_ = venting;
    settled_from_s_ = now_s + kVentEdgeSettleS;
  }
  const double since_s = last_sample_s_ < 0.0 ? period_s_ : now_s - last_sample_s_;
  last_sample_s_ = now_s;
  if (applied.valves.inlet > 0.0 || to_vacuum || !std::isfinite(gauge_pressure_pa) || now_s < settled_from_s_) {
    flat_for_s_ = -1.0;
    return false;
  }
  const double dt = std::clamp(since_s, period_s_, kSampleCreditPeriods * period_s_);
  if (flat_for_s_ < 0.0) {
    flat_for_s_ = 0.0;
    mean_pa_ = gauge_pressure_pa;
  } else {
    flat_for_s_ += dt;
  }
  const double tau = std::max(reanchor_time_s_ / 3.0, dt);
  mean_pa_ += (gauge_pressure_pa - mean_pa_) * std::min(1.0, dt / tau);
  // Below ambient only while the cell tests for a flat cell (expectFlatUntil): a vented flat
  // cell's plate may settle a little below it, while a lifted one keeps its load's pressure.
  // Taken always, light cells resting lifted near ambient would be re-anchored flat.
  const bool low =
      now_s < sub_ambient_flat_until_s_ ? mean_pa_ < flat_pressure_pa_ : std::fabs(mean_pa_) < flat_pressure_pa_;
  if (flat_for_s_ + 1e-9 >= reanchor_time_s_ && low) {
    *mean_pa = mean_pa_;
    flat_for_s_ = 0.0;
    return true;
  }
  return false;
}

}  // namespace nursing_bed
