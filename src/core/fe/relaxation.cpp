#include "nursing_bed/core/fe/relaxation.h"

#include <cmath>
#include <sstream>
#include <stdexcept>

namespace nursing_bed {
namespace fe {

double PressureControl::pressureAt(double volume_m3) const {
  if (!volumeControlled()) return gauge_pressure_pa;
  return gauge_pressure_pa + volume_stiffness_pa * (1.0 - volume_m3 / target_volume_m3);
}

Status RelaxOptions::validate() const {
  std::ostringstream err;
  if (!(tolerance > 0.0 && tolerance < 1.0)) err << "tolerance must be in (0, 1), got " << tolerance;
  else if (!(pressure_floor_pa > 0.0)) err << "pressure_floor_pa must be positive, got " << pressure_floor_pa;
  else if (max_iterations < 1 || min_iterations < 0 || min_iterations > max_iterations)
    err << "need 0 <= min_iterations <= max_iterations, max_iterations >= 1";
  else if (!(plate_mass_ratio > 0.0)) err << "plate_mass_ratio must be positive, got " << plate_mass_ratio;
  else if (!(damping_per_s >= 0.0)) err << "damping_per_s must be >= 0, got " << damping_per_s;
  return Status::fromMessage(err.str());
}

namespace {

// Relative residual of the film and, for a loaded plate, of the plate's balance.
double relativeResidual(const MembraneModel& model, double pressure_pa, const RelaxOptions& o) {
  const double scale = std::max(std::abs(pressure_pa), o.pressure_floor_pa) * model.meanNodeArea();
  double r = model.residualRms() / scale;
  const PlateState& plate = model.plate();
  if (plate.mode == PlateState::Mode::kLoaded) {
    // The plate gathers many nodes: compare its imbalance with the load it carries.
    r = std::max(r, 0.1 * std::abs(plate.contact_force_n - plate.load_n) / std::max(plate.load_n, 0.1));
  }
  return r;
}

}  // namespace

RelaxResult relax(MembraneModel* model, const PressureControl& control, const RelaxOptions& options) {
  const Status valid = options.validate();
  if (!valid) throw std::invalid_argument("relax: " + valid.message());
  if (control.volumeControlled() && !(control.target_volume_m3 > 0.0 && control.volume_stiffness_pa > 0.0)) {
    throw std::invalid_argument("relax: target_volume_m3 and volume_stiffness_pa must be positive");
  }
  PlateState& plate = model->plate();
  const double physical_plate_mass = plate.mass_kg;
  plate.mass_kg = options.plate_mass_ratio * model->nodeMass().sum();
  model->zeroVelocities();
  const double dt = model->stableTimeStep();
  RelaxResult result;
  double previous_kinetic = 0.0;
  for (int it = 1; it <= options.max_iterations; ++it) {
    const double volume = model->volume(control.volume_axes);
    const double pressure = control.pressureAt(volume);
    result.forces = model->computeForces(pressure);
    result.gauge_pressure_pa = pressure;
    result.volume_m3 = volume;
    result.residual = relativeResidual(*model, pressure, options);
    result.iterations = it;
    if (!std::isfinite(result.residual) || !model->positions().allFinite()) {
      result.message = "diverged (non-finite state) after " + std::to_string(it) + " iterations";
      break;
    }
    if (it >= options.min_iterations && result.residual < options.tolerance) {
      result.converged = true;
      result.message = "converged";
      break;
    }
    model->step(dt, options.damping_per_s);
    if (options.damping_per_s > 0.0) continue;
    // Kinetic damping: at each peak of kinetic energy the motion has passed an energy
    // minimum along its path; stop it there.
    const double kinetic = model->kineticEnergy();
    if (kinetic < previous_kinetic) {
      model->zeroVelocities();
      previous_kinetic = 0.0;
    } else {
      previous_kinetic = kinetic;
    }
  }
  if (!result.converged && result.message.empty()) {
    std::ostringstream msg;
    msg << "not converged after " << result.iterations << " iterations (residual " << result.residual << " > tolerance "
        << options.tolerance << ")";
    result.message = msg.str();
  }
  plate.mass_kg = physical_plate_mass;
  result.plate_height_m = plate.height_m;
  result.plate_force_n = plate.contact_force_n;
  model->zeroVelocities();
  return result;
}

}  // namespace fe
}  // namespace nursing_bed
