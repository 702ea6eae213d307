#include "nursing_bed/core/physics/pillow_structure.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "nursing_bed/core/io/errors.h"
#include "nursing_bed/core/physics/units.h"

namespace nursing_bed {
namespace {
// pi^2/4 - pi/2: how fast the corner spheres eat the effective area (see header).
constexpr double kCornerAreaFactor = kPi * kPi / 4.0 - kPi / 2.0;
}  // namespace

Status PillowParams::validate() const {
  ErrorList errors;
  auto positive = [&errors](const char* name, double value) {
    errors.addIf(!(value > 0.0) || !std::isfinite(value), name, " must be a positive finite number, got ", value);
  };
  positive("face_side_m", face_side_m);
  positive("film_thickness_m", film_thickness_m);
  positive("dead_volume_m3", dead_volume_m3);
  errors.addIf(!(fold_fraction > 0.0 && fold_fraction < 1.0), "fold_fraction must lie in (0, 1), got ", fold_fraction);
  positive("film_relaxation_time_s", film_relaxation_time_s);
  errors.addIf(!(max_film_stretch > 1.0) || !std::isfinite(max_film_stretch), "max_film_stretch must be > 1, got ",
               max_film_stretch);
  errors.addIf(!(gusset_height_m >= 0.0) || !std::isfinite(gusset_height_m), "gusset_height_m must be >= 0, got ",
               gusset_height_m);
  errors.addIf(chambers < 1 || chambers > 8, "chambers must be 1..8, got ", chambers);
  errors.addNested(material.validate(), "material: ");
  return errors.status();
}

namespace {
// The flat loop's half length squared: the pillow's effective area at h = 0 and rest stretch.
double flatArea(const PillowParams& p) { return std::pow(p.face_side_m + p.gusset_height_m, 2); }

// The loop's length at rest (L0) and the reference volume of all film (n A0 t, A0 = L0^2 / 2).
double loopLength(const PillowParams& p) { return 2.0 * (p.face_side_m + p.gusset_height_m); }
double filmVolumeOf(const PillowParams& p) {
  const double loop_length_m = loopLength(p);
  const double reference_area_per_chamber = 0.5 * loop_length_m * loop_length_m;
  return p.chambers * reference_area_per_chamber * p.film_thickness_m;
}
}  // namespace

PillowStructure::PillowStructure(const PillowParams& params)
    : params_(params), fold_(params.fold_fraction * params.dead_volume_m3, flatArea(params)) {
  loop_length_m_ = loopLength(params_);
  film_volume_m3_ = filmVolumeOf(params_);
  // Film stiffness at rest: d2W/dl2 at l = 1 is 24 C10 for the equibiaxial Yeoh film.
  const double rest_stiffness = film_volume_m3_ * params_.material.equibiaxialEnergySecondDerivative(1.0);
  shape_damping_j_s_ = params_.film_relaxation_time_s * rest_stiffness;
}

double PillowStructure::elasticForce(const PillowParams& params, double stretch) {
  return filmVolumeOf(params) * params.material.equibiaxialEnergyDerivative(stretch);
}

std::array<double, kMaxShapeDofs> PillowStructure::restShape() const {
  std::array<double, kMaxShapeDofs> q{};
  q[0] = 1.0;
  return q;
}

StructureEval PillowStructure::evaluate(double height_m, const double* shape) const {
  const double stretch = shape[0];
  const int n = params_.chambers;
  const double c = std::max(height_m, 0.0) / n;  // chamber height
  const double half_loop = 0.5 * stretch * loop_length_m_;
  const double w = half_loop - 0.5 * kPi * c;  // contact flat width

  StructureEval e;
  const double chamber_volume = w * w * c + 0.5 * kPi * w * c * c + kPi / 6.0 * c * c * c;
  e.volume_m3 = params_.dead_volume_m3 + n * chamber_volume;
  e.effective_area_m2 = w * w - kCornerAreaFactor * c * c;
  // dV/dlambda = n (L0/2) dV_chamber/dw.
  e.dvolume_dshape[0] = n * 0.5 * loop_length_m_ * (2.0 * w * c + 0.5 * kPi * c * c);
  const double energy_slope = params_.material.equibiaxialEnergyDerivative(stretch);
  e.elastic_force[0] = film_volume_m3_ * energy_slope;
  e.shape_damping[0] = shape_damping_j_s_;
  const double w_flat = std::max(w, 0.0);
  e.contact_area_m2 = w_flat * w_flat;
  e.surface_area_m2 = n * (2.0 * w_flat * w_flat + 2.0 * kPi * w_flat * c + kPi * c * c);
  e.film_stretch = stretch;
  // Nominal stress per direction is half of dW/dl; tension per current length divides by l.
  e.film_tension_n_m = params_.film_thickness_m * 0.5 * energy_slope / stretch;
  // Below flat the terms above are those of c = 0 (no volume depends on the stretch there).
  return fold_.below(height_m, e);
}

bool PillowStructure::withinLimits(double height_m, const double* shape) const {
  // The contact flat must exist (w >= 0) and the film stay below its rupture margin.
  const double w = 0.5 * shape[0] * loop_length_m_ - 0.5 * kPi * std::max(height_m, 0.0) / params_.chambers;
  return shape[0] <= params_.max_film_stretch && w >= 0.0;
}

double PillowStructure::heightLimit(const double* shape) const {
  // A_eff reaches zero where w = sqrt(k) c: beyond it no load can be carried.
  const double half_loop = 0.5 * shape[0] * loop_length_m_;
  return params_.chambers * half_loop / (0.5 * kPi + std::sqrt(kCornerAreaFactor));
}

std::string PillowStructure::describe() const {
  std::ostringstream s;
  s << "pillow cell: " << params_.chambers << " chambers, face " << mToMm(params_.face_side_m) << " mm, gusset "
    << mToMm(params_.gusset_height_m) << " mm, film " << mToMm(params_.film_thickness_m) << " mm Yeoh("
    << paToMpa(params_.material.c10_pa) << ", " << paToMpa(params_.material.c20_pa) << ", "
    << paToMpa(params_.material.c30_pa) << ") MPa";
  return s.str();
}

}  // namespace nursing_bed
