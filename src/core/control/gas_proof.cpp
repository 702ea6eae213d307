#include "nursing_bed/core/control/gas_proof.h"

#include <algorithm>
#include <cmath>

namespace nursing_bed {

void GasProof::start() {
  pending_ = params_.hold_s > 0.0;
  hold_ = Hold{};
}

void GasProof::reset() {
  pending_ = false;
  hold_ = Hold{};
  failures_ = 0;
}

GasProof::Verdict GasProof::update(bool holding, double gauge_pressure_pa, double height_m, double dt_s) {
  // A vent stuck open lets the refilled plate sink again under an estimate that stays; held at
  // height, gas that leaves moves the pressure, so the second half of a hold reads what the
  // first read only when the gas stays.
  if (!pending_) return Verdict::kNone;
  const bool counts = holding && std::isfinite(gauge_pressure_pa) && height_m > params_.min_height_m;
  if (!counts) {
    hold_ = Hold{};
    return Verdict::kNone;
  }
  hold_.held_s += dt_s;
  const double into_s = hold_.held_s - params_.settle_s;
  if (into_s <= 0.0) return Verdict::kNone;
  if (into_s <= 0.5 * params_.hold_s) {
    hold_.first_pa += gauge_pressure_pa;
    ++hold_.first_n;
  } else {
    hold_.second_pa += gauge_pressure_pa;
    ++hold_.second_n;
  }
  if (into_s < params_.hold_s || hold_.first_n == 0 || hold_.second_n == 0) return Verdict::kNone;
  const double first = hold_.first_pa / hold_.first_n, second = hold_.second_pa / hold_.second_n;
  const double tolerance = std::max(params_.tolerance_pa, params_.tolerance_rel * std::fabs(first));
  hold_ = Hold{};
  if (std::fabs(second - first) <= tolerance) {
    pending_ = false;
    return Verdict::kProved;
  }
  ++failures_;
  return Verdict::kFailed;
}

}  // namespace nursing_bed
