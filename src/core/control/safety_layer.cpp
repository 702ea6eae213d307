#include "nursing_bed/core/control/safety_layer.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include "nursing_bed/core/io/errors.h"

namespace nursing_bed {

std::string AirbagSafetyParams::validate() const {
  ErrorList errors;
  errors.addIf(!(relief_pressure_pa > 0.0 && std::isfinite(relief_pressure_pa)), "relief_pressure_pa must be positive");
  errors.addIf(!(relief_margin_pa >= 0.0 && relief_margin_pa < relief_pressure_pa),
               "relief_margin_pa must lie in [0, relief_pressure_pa)");
  errors.addIf(!(command_timeout_s >= 0.0), "command_timeout_s must be >= 0");
  errors.addIf(!(sensor_pressure_max_pa > sensor_pressure_min_pa), "sensor pressure range is empty");
  errors.addIf(!(sensor_height_max_m > sensor_height_min_m), "sensor height range is empty");
  errors.addIf(!(sensor_fault_periods >= 1 && sensor_fault_periods <= 100), "sensor_fault_periods must lie in 1..100");
  errors.addIf(!(max_load_n > 0.0 && std::isfinite(max_load_n)), "max_load_n must be a positive finite load");
  errors.addIf(!(max_height_rate_m_s > 0.0 && std::isfinite(max_height_rate_m_s)),
               "max_height_rate_m_s must be a positive finite rate");
  return errors.text();
}

namespace {
const AirbagSafetyParams& validated(const AirbagSafetyParams& p) {
  const std::string error = p.validate();
  if (!error.empty()) throw std::invalid_argument("safety parameters: " + error);
  return p;
}
}  // namespace

SafetyLayer::SafetyLayer(const AirbagSafetyParams& params) : params_(validated(params)) {}

std::string SafetyLayer::setParams(const AirbagSafetyParams& params) {
  const std::string error = params.validate();
  if (error.empty()) params_ = params;
  return error;
}

SensorVerdict SafetyLayer::checkReadings(double gauge_pressure_pa, double height_m) {
  const AirbagSafetyParams& s = params_;
  const double p = gauge_pressure_pa, h = height_m;
  const bool sensor_ok = std::isfinite(p) && std::isfinite(h) && p >= s.sensor_pressure_min_pa &&
                         p <= s.sensor_pressure_max_pa && h >= s.sensor_height_min_m && h <= s.sensor_height_max_m;
  if (sensor_ok) {
    bad_readings_ = 0;
    return SensorVerdict::kOk;
  }
  return ++bad_readings_ >= s.sensor_fault_periods ? SensorVerdict::kFault : SensorVerdict::kHold;
}

bool SafetyLayer::commandTimedOut(double now_s) const {
  return params_.command_timeout_s > 0.0 && now_s - last_command_s_ > params_.command_timeout_s;
}

ReliefVerdict SafetyLayer::relief(double gauge_pressure_pa) {
  const double p = gauge_pressure_pa;
  const double rise = std::max(0.0, p - last_pressure_pa_);
  last_pressure_pa_ = p;
  if (p + rise + params_.relief_margin_pa >= params_.relief_pressure_pa) return ReliefVerdict::kVent;
  if (p < params_.relief_pressure_pa - 2.0 * params_.relief_margin_pa - rise) return ReliefVerdict::kClear;
  return ReliefVerdict::kKeep;
}

std::string SafetyLayer::checkLoad(double load_n) const {
  if (std::isfinite(load_n) && load_n >= 0.0 && load_n <= params_.max_load_n) return "";
  std::ostringstream msg;
  msg << "load " << load_n << " N refused: must be finite and within [0, " << params_.max_load_n
      << "] N (safety/max_load_n)";
  return msg.str();
}

}  // namespace nursing_bed
