#include "nursing_bed/core/control/plate_landing.h"

#include <algorithm>
#include <cmath>

namespace nursing_bed {

void PlateLanding::start() {
  active_ = true;
  time_s_ = 0.0;
}

std::optional<double> PlateLanding::force(double dt_s, const PlateState& plate, double aim_m,
                                          const PlateMechanics& mechanics, double rate_per_s) {
  if (!active_) return std::nullopt;
  time_s_ += dt_s;
  const bool landed = std::fabs(plate.height_m - aim_m) < landed_m && std::fabs(plate.velocity_m_s) < landed_speed_m_s;
  if (landed || time_s_ > timeout_s) {
    stop();
    return std::nullopt;
  }
  return approachForce(plate, aim_m, mechanics, rate_per_s);
}

double PlateLanding::approachForce(const PlateState& plate, double aim_m, const PlateMechanics& mechanics,
                                   double rate_per_s) {
  const double error = plate.height_m - aim_m, v = plate.velocity_m_s;
  const double acceleration = -2.0 * rate_per_s * v - rate_per_s * rate_per_s * error;
  const double f = mechanics.load_n + mechanics.damping_n_s_m * v + mechanics.mass_kg * acceleration;
  return std::max(f, 0.05 * mechanics.load_n);
}

}  // namespace nursing_bed
