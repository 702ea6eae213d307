#include "nursing_bed/core/control/pressure_mode_controller.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace nursing_bed {

std::string PressureModeParams::validate() const {
  std::ostringstream err;
  if (!(band_pa > 0.0 && std::isfinite(band_pa))) err << "band_pa must be positive, got " << band_pa << "; ";
  if (!(tolerance_pa >= 0.0 && tolerance_pa < band_pa))
    err << "tolerance_pa must lie in [0, band_pa), got " << tolerance_pa << "; ";
  std::string s = err.str();
  if (s.size() >= 2) s.resize(s.size() - 2);
  return s;
}

namespace {
const PressureModeParams& validated(const PressureModeParams& p) {
  const std::string error = p.validate();
  if (!error.empty()) throw std::invalid_argument("pressure mode parameters: " + error);
  return p;
}
}  // namespace

PressureModeController::PressureModeController(const PressureModeParams& params) : params_(validated(params)) {}

ValveOpenings PressureModeController::update(double gauge_pressure_pa) const {
  const double error = setpoint_pa_ - gauge_pressure_pa;
  ValveOpenings v;
  if (error > params_.tolerance_pa) v.inlet = std::min(1.0, error / params_.band_pa);
  if (error < -params_.tolerance_pa) v.vent = std::min(1.0, -error / params_.band_pa);
  return v;
}

}  // namespace nursing_bed
