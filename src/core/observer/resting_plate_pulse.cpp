#include "nursing_bed/core/observer/resting_plate_pulse.h"

#include <algorithm>
#include <cmath>

namespace nursing_bed {
namespace {

// The pressure a plate rests at: the readings with the valves shut, filtered over this time [s].
constexpr double kRestPressureFilterS = 0.02;
// Openings below this are shut (the valve delay line's rounding leaves such slivers) [-].
constexpr double kShutOpening = 1e-6;
// The correction is taken only where the period moves this much gas at the readings, and is
// bounded to 1 -/+ this range (a pulse's swing changes its gas by tens of percent, no more).
constexpr double kFloorKg = 1e-12;
constexpr double kRange = 0.5;

}  // namespace

void RestingPlatePulse::reset() {
  quiet_s_ = std::numeric_limits<double>::infinity();
  rest_pressure_pa_ = std::numeric_limits<double>::quiet_NaN();
}

void RestingPlatePulse::interrupt() {
  quiet_s_ = 0.0;
  rest_pressure_pa_ = std::numeric_limits<double>::quiet_NaN();
}

double RestingPlatePulse::factor(CellModel& model, double time_s, const CellModel::StateVector& estimate,
                                 double estimate_pressure_pa, const CellInputs& in, double old_pressure_pa,
                                 double dt_s) {
  const bool acting = in.inlet_opening > kShutOpening || in.vent_opening > kShutOpening;
  const bool from_rest = quiet_s_ > kRingDownS;
  if (!acting && std::isfinite(old_pressure_pa)) {
    // The first shut period after an opening starts the filter afresh.
    const bool fresh = quiet_s_ == 0.0 || !std::isfinite(rest_pressure_pa_);
    rest_pressure_pa_ =
        fresh ? old_pressure_pa
              : rest_pressure_pa_ + (old_pressure_pa - rest_pressure_pa_) * std::min(1.0, dt_s / kRestPressureFilterS);
  }
  quiet_s_ = acting ? 0.0 : quiet_s_ + dt_s;
  const double pa = model.params().ambient_pressure_pa;
  const double rest = std::isfinite(rest_pressure_pa_) ? rest_pressure_pa_ : old_pressure_pa;
  if (!acting || !from_rest || !(std::fabs(rest) <= swing_pressure_pa_) || !(estimate_pressure_pa > 0.0)) return 1.0;
  // The estimate's gas scaled to the rest pressure at its volume, the plate still, and the
  // load that holds it there.
  CellModel::StateVector start = estimate;
  const double scale = (pa + rest) / estimate_pressure_pa;
  start[CellModel::kMass] *= scale;
  start[CellModel::kEnergy] *= scale;
  start[CellModel::kVelocity] = 0.0;
  CellInputs own = in;
  own.flow_gauge_pressure_pa = std::numeric_limits<double>::quiet_NaN();
  CellVariables v;
  const double acceleration = model.rate(time_s, start, own, &v)[CellModel::kVelocity];
  own.load_n = std::max(0.0, own.load_n + acceleration * v.moving_mass_kg);
  model.setState(time_s, start);
  model.advance(dt_s, own);
  const double swung = (model.state()[CellModel::kMass] - start[CellModel::kMass]) / scale;
  const double at_readings = model.rate(time_s, estimate, in)[CellModel::kMass] * dt_s;
  if (!std::isfinite(swung) || !(std::fabs(at_readings) > kFloorKg)) return 1.0;
  return std::clamp(swung / at_readings, 1.0 - kRange, 1.0 + kRange);
}

}  // namespace nursing_bed
