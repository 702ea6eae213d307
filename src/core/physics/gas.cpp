#include "nursing_bed/core/physics/gas.h"

#include <cmath>

namespace nursing_bed {

double GasProperties::criticalPressureRatio() const {
  const double g = heat_capacity_ratio;
  return std::pow(2.0 / (g + 1.0), g / (g - 1.0));
}

Status GasProperties::validate() const {
  if (!(gas_constant_j_kg_k > 0.0) || !std::isfinite(gas_constant_j_kg_k))
    return Status::error("gas_constant_j_kg_k must be a positive finite number");
  if (!(heat_capacity_ratio > 1.0) || !(heat_capacity_ratio < 2.0))
    return Status::error("heat_capacity_ratio must lie in (1, 2)");
  return Status::success();
}

}  // namespace nursing_bed
