// The FE airbag (doc/fe_membrane.md): the membrane bag under the rigid loading plate (paper fig. 7),
// its quasi-static states, and the gas-coupled inflation (control volume, paper eq. 11-17).
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "nursing_bed/core/fe/airbag_geometry.h"
#include "nursing_bed/core/fe/membrane_model.h"
#include "nursing_bed/core/fe/relaxation.h"
#include "nursing_bed/core/io/status.h"
#include "nursing_bed/core/physics/cell_model.h"
#include "nursing_bed/core/physics/time_series.h"

namespace nursing_bed {
namespace fe {

/// Relaxation of the airbag: viscous damping near critical for the bag's slowest modes
/// (kinetic damping crawls along the slack film's soft modes), tolerance 1e-4 (1e-3 left the
/// height 10 mm short at mid pressures; 1e-5 changes it by < 0.1 mm).
inline RelaxOptions airbagRelaxDefaults() {
  RelaxOptions r;
  r.tolerance = 1e-4;
  r.damping_per_s = 1000.0;
  r.max_iterations = 100000;
  return r;
}

struct AirbagFeOptions {
  AirbagGeometry geometry;
  FilmMaterial material;
  MembraneOptions membrane;  ///< self_contact_radius_m is set to the geometry's layer gap
  RelaxOptions relax = airbagRelaxDefaults();

  /// Success, or what is wrong (names the field).
  Status validate() const;
};

/// One quasi-static state.
struct QuasiStaticPoint {
  bool converged = false;
  std::string message;
  int iterations = 0;
  double gauge_pressure_pa = 0.0;
  double load_n = 0.0;         ///< load on the plate (NaN for a fixed plate)
  double height_m = 0.0;       ///< plate height
  double volume_m3 = 0.0;      ///< eq. 11
  double plate_force_n = 0.0;  ///< film on plate
  double max_stretch = 1.0;
  double wrinkled_fraction = 0.0;  ///< share of wrinkled or slack triangles
  double rim_inset_m = 0.0;        ///< widest film half-width minus the rim's: > 0 when the edge is folded in
};

class AirbagFe {
 public:
  /// Throws std::invalid_argument (naming the field) for bad options.
  explicit AirbagFe(const AirbagFeOptions& options);

  MembraneModel& model() { return *model_; }
  const MembraneModel& model() const { return *model_; }
  const AirbagFeOptions& options() const { return options_; }
  /// Back to the flat bag as made, plate resting on it.
  void reset();

  /// Equilibrium of the loaded plate (weight included in load_n) at a gauge pressure.
  QuasiStaticPoint solveLoaded(double gauge_pressure_pa, double load_n);
  /// Plate held at height h: the force the gas and film put on it.
  QuasiStaticPoint solveAtHeight(double height_m, double gauge_pressure_pa);
  /// Current state as a point (after a solve or during a transient).
  QuasiStaticPoint snapshot(double gauge_pressure_pa) const;

 private:
  QuasiStaticPoint solve(double gauge_pressure_pa);
  QuasiStaticPoint solveWithPlate(PlateState::Mode mode, double load_or_height, double gauge_pressure_pa);
  AirbagFeOptions options_;
  std::unique_ptr<MembraneModel> model_;
  std::vector<int> rim_nodes_;  // welded rim of the lowest chamber, mid-edge
};

/// Quasi-static h(p) under one load by continuation in pressure (each state starts from the
/// previous one). `progress` (may be empty) is told each point.
std::vector<QuasiStaticPoint> heightVsPressure(AirbagFe* bag, double load_n, const std::vector<double>& pressures_pa,
                                               const std::function<void(const QuasiStaticPoint&)>& progress = {});

/// Gas-coupled inflation run (paper section 4.2): the film, the plate carrying the load and
/// the adiabatic control volume (mass and energy, eq. 12-17) with the volume from the mesh
/// (eq. 11); inflow either a prescribed curve (the paper's way) or the inlet valve from the
/// regulator (CellParams), leak through leak_area_m2 (eq. 17-23 via the orifice law).
struct TransientSetup {
  CellParams cell;  ///< gas, ambient, supply, valves, plate damping
  double load_n = 0.6;
  double duration_s = 5.5;
  const TimeSeries* prescribed_inflow = nullptr;  ///< kg/s vs s; null: valve model
  double inflation_end_s = 5.5;                   ///< inlet closes (valve model)
  double film_damping_per_s = 30.0;               ///< mass-proportional film damping (air drag, TPU losses) [1/s]
  double sample_s = 0.01;

  /// Success, or what is wrong (names the field).
  Status validate() const;
};

struct TransientSample {
  double time_s, inflow_kg_s, gauge_pressure_pa, height_m, volume_m3, mass_kg, temperature_k, rim_inset_m;
};

struct TransientResult {
  bool ok = false;
  std::string message;
  std::vector<TransientSample> samples;
  long steps = 0;
};

/// Runs from the bag's current state (reset() first for a flat start). `progress` gets the
/// fraction done. Stops with ok = false and a message if the state becomes non-finite.
TransientResult runTransient(AirbagFe* bag, const TransientSetup& setup,
                             const std::function<void(double)>& progress = {});

}  // namespace fe
}  // namespace nursing_bed
