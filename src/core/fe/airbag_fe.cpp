#include "nursing_bed/core/fe/airbag_fe.h"

#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

#include "nursing_bed/core/physics/gas.h"
#include "nursing_bed/core/physics/orifice.h"
#include "nursing_bed/core/physics/units.h"

namespace nursing_bed {
namespace fe {

Status AirbagFeOptions::validate() const {
  for (const Status& s : {geometry.validate(), material.validate(), membrane.validate(), relax.validate()}) {
    if (!s) return s;
  }
  return Status::success();
}

AirbagFe::AirbagFe(const AirbagFeOptions& options) : options_(options) {
  const Status valid = options_.validate();
  if (!valid) throw std::invalid_argument("AirbagFe: " + valid.message());
  options_.membrane.self_contact_radius_m = options_.geometry.layerGap();
  model_ = std::make_unique<MembraneModel>(buildAirbagMesh(options_.geometry), options_.material, options_.membrane);
  const MembraneMesh& m = model_->mesh();
  const double a = options_.geometry.face_side_m, tol = 1e-3 * options_.geometry.elementSize();
  for (int j = 0; j < m.nodeCount(); ++j) {
    if (std::abs(m.initial(0, j)) < tol && std::abs(m.initial(1, j) - 0.5 * a) < tol) rim_nodes_.push_back(j);
  }
  reset();
}

void AirbagFe::reset() {
  model_->setPositions(model_->mesh().initial);
  model_->zeroVelocities();
  PlateState& plate = model_->plate();
  plate.mode = PlateState::Mode::kLoaded;
  plate.height_m = initialTop(model_->mesh());
}

QuasiStaticPoint AirbagFe::snapshot(double gauge_pressure_pa) const {
  QuasiStaticPoint p;
  const MembraneModel& m = *model_;
  const Eigen::Matrix3Xd& x = m.positions();
  p.gauge_pressure_pa = gauge_pressure_pa;
  p.height_m = m.plate().height_m;
  p.volume_m3 = m.volume();
  p.plate_force_n = m.plate().contact_force_n;
  p.load_n = m.plate().mode == PlateState::Mode::kLoaded ? m.plate().load_n : std::numeric_limits<double>::quiet_NaN();
  int relaxed = 0;
  for (const auto& r : m.elementResponses()) {
    p.max_stretch = std::max(p.max_stretch, r.stretch_max);
    relaxed += r.state != FilmState::kTaut;
  }
  p.wrinkled_fraction = static_cast<double>(relaxed) / std::max<std::size_t>(1, m.elementResponses().size());
  // Edge profile in the mid-plane y = a/2: widest film half-width against the rim's.
  const double a = options_.geometry.face_side_m, centre_x = x.row(0).mean();
  double widest = 0.0, rim = std::numeric_limits<double>::infinity();
  for (int j = 0; j < x.cols(); ++j) {
    if (std::abs(m.mesh().initial(1, j) - 0.5 * a) < 1e-3 * a && m.mesh().initial(0, j) < 0.5 * a) {
      widest = std::max(widest, centre_x - x(0, j));
    }
  }
  for (int j : rim_nodes_) rim = std::min(rim, centre_x - x(0, j));
  p.rim_inset_m = rim_nodes_.empty() ? 0.0 : widest - rim;
  return p;
}

QuasiStaticPoint AirbagFe::solve(double gauge_pressure_pa) {
  PressureControl control;
  control.gauge_pressure_pa = gauge_pressure_pa;
  const RelaxResult r = relax(model_.get(), control, options_.relax);
  QuasiStaticPoint p = snapshot(gauge_pressure_pa);
  p.converged = r.converged;
  p.message = r.message;
  p.iterations = r.iterations;
  return p;
}

QuasiStaticPoint AirbagFe::solveWithPlate(PlateState::Mode mode, double value, double gauge_pressure_pa) {
  if (!(value > 0.0) || !std::isfinite(gauge_pressure_pa)) {
    throw std::invalid_argument(std::string("AirbagFe: ") +
                                (mode == PlateState::Mode::kLoaded ? "load_n" : "height_m") +
                                " must be positive and the pressure finite");
  }
  PlateState& plate = model_->plate();
  plate.mode = mode;
  (mode == PlateState::Mode::kLoaded ? plate.load_n : plate.height_m) = value;
  return solve(gauge_pressure_pa);
}

QuasiStaticPoint AirbagFe::solveLoaded(double gauge_pressure_pa, double load_n) {
  return solveWithPlate(PlateState::Mode::kLoaded, load_n, gauge_pressure_pa);
}

QuasiStaticPoint AirbagFe::solveAtHeight(double height_m, double gauge_pressure_pa) {
  return solveWithPlate(PlateState::Mode::kFixed, height_m, gauge_pressure_pa);
}

std::vector<QuasiStaticPoint> heightVsPressure(AirbagFe* bag, double load_n, const std::vector<double>& pressures_pa,
                                               const std::function<void(const QuasiStaticPoint&)>& progress) {
  std::vector<QuasiStaticPoint> points;
  for (double p : pressures_pa) {
    points.push_back(bag->solveLoaded(p, load_n));
    if (progress) progress(points.back());
  }
  return points;
}

}  // namespace fe
}  // namespace nursing_bed
