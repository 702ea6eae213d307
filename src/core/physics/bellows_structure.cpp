#include "nursing_bed/core/physics/bellows_structure.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "nursing_bed/core/io/errors.h"
#include "nursing_bed/core/physics/units.h"

namespace nursing_bed {

Status BellowsParams::validate() const {
  ErrorList errors;
  auto positive = [&errors](const char* name, double value) {
    errors.addIf(!(value > 0.0) || !std::isfinite(value), "bellows ", name, " must be a positive finite number, got ",
                 value);
  };
  positive("area_m2", area_m2);
  positive("compliance_m3_pa", compliance_m3_pa);
  positive("dead_volume_m3", dead_volume_m3);
  positive("stroke_m", stroke_m);
  return errors.status();
}

BellowsStructure::BellowsStructure(const BellowsParams& params)
    : params_(params), spring_rate_n_m_(params.springRate()) {}

StructureEval BellowsStructure::evaluate(double height_m, const double* shape) const {
  StructureEval e;
  const double a = params_.area_m2;
  e.volume_m3 = params_.dead_volume_m3 + a * height_m;
  e.effective_area_m2 = a;
  e.plate_force_n = -spring_rate_n_m_ * height_m;
  // The shape coordinate is a placeholder: no volume, relaxes to 0 in about a second.
  e.dvolume_dshape[0] = 0.0;
  e.elastic_force[0] = shape[0];
  e.shape_damping[0] = 1.0;
  // Wetted wall: a cylinder of cross-section A as long as the gas volume.
  const double radius = std::sqrt(a / kPi);
  e.surface_area_m2 = 2.0 * a + 2.0 * kPi * radius * std::max(e.volume_m3, 0.0) / a;
  return e;
}

bool BellowsStructure::withinLimits(double height_m, const double* /*shape*/) const {
  return height_m >= -1e-3 * params_.stroke_m && height_m <= params_.stroke_m;
}

std::string BellowsStructure::describe() const {
  std::ostringstream s;
  s << "bellows: area " << params_.area_m2 * 1e4 << " cm^2, compliance " << params_.compliance_m3_pa * 1e6 * 98.0665
    << " mL/cmH2O (spring " << spring_rate_n_m_ << " N/m), dead volume " << params_.dead_volume_m3 * 1e3
    << " L, stroke " << mToMm(params_.stroke_m) << " mm";
  return s.str();
}

}  // namespace nursing_bed
