#include "nursing_bed/core/control/pressure_mode_controller.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include "nursing_bed/core/io/errors.h"

namespace nursing_bed {

Status PressureModeParams::validate() const {
  ErrorList errors;
  errors.addIf(!(band_pa > 0.0 && std::isfinite(band_pa)), "band_pa must be positive, got ", band_pa);
  errors.addIf(!(tolerance_pa >= 0.0 && tolerance_pa < band_pa), "tolerance_pa must lie in [0, band_pa), got ",
               tolerance_pa);
  return errors.status();
}

namespace {
const PressureModeParams& validated(const PressureModeParams& p) {
  const Status valid = p.validate();
  if (!valid.ok()) throw std::invalid_argument("pressure mode parameters: " + valid.message());
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
