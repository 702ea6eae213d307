// The membrane bag as a mechanical system: film elements, gas pressure on the film, penalty
// contact with the bed, the rigid loading plate (paper fig. 7) and the film's own layers, and
// an explicit central-difference step. Quasi-static states come from relax() (dynamic
// relaxation, fe/relaxation.h), transients from the gas-coupled run (fe/airbag_fe.h).
#pragma once

#include <Eigen/Dense>
#include <limits>
#include <string>
#include <vector>

#include "nursing_bed/core/fe/film.h"
#include "nursing_bed/core/fe/mesh.h"
#include "nursing_bed/core/io/status.h"

namespace nursing_bed {
namespace fe {

/// Numerical options of the membrane model.
struct MembraneOptions {
  double cfl = 0.5;  ///< fraction of the stable explicit step [-]
  /// Tangent modulus bound for the explicit step, times the initial 6 C10: 2 covers the Yeoh
  /// stiffening up to stretch ~1.6, 4 up to ~2.2 [-]
  double stiffening_factor = 2.0;
  double contact_stiffness_scale = 0.2;  ///< penalty k = scale * m_node / dt^2 (so k dt^2/m is fixed) [-]
  double contact_damping_ratio = 0.5;    ///< damping of penetrating nodes, fraction of critical [-]
  bool bed_contact = true;               ///< rigid bed at z = bed_height_m
  double bed_height_m = 0.0;
  double self_contact_radius_m = 0.0;    ///< node-node contact distance between layers; 0: off [m]
  int self_contact_exclusion_rings = 2;  ///< nodes this close in the mesh graph never touch [-]
  int threads = 2;                       ///< OpenMP threads (the machine has two cores)

  /// Success, or what is wrong (names the field).
  Status validate() const;
};

/// The rigid plate on top of the bag (paper fig. 7): an infinite horizontal plane.
struct PlateState {
  enum class Mode { kNone, kLoaded, kFixed };
  Mode mode = Mode::kNone;
  double height_m = 0.0;  ///< plane height
  double velocity_m_s = 0.0;
  double load_n = 0.6;           ///< downward force, plate weight included (kLoaded)
  double mass_kg = 0.06;         ///< moving mass (kLoaded)
  double damping_n_s_m = 0.0;    ///< viscous damping of the plate guide
  double contact_force_n = 0.0;  ///< upward force of the film on the plate (last evaluation)
};

/// Forces of one evaluation.
struct ForceSummary {
  double elastic_energy_j = 0.0;
  double plate_force_n = 0.0;   ///< film on plate, upward
  double bed_force_n = 0.0;     ///< film on bed, downward
  int wrinkled = 0, slack = 0;  ///< triangles in each state
  double max_stretch = 1.0;
};

// size: the explicit FE state: film, gas, bed, plate and self-contact forces share the node arrays
class MembraneModel {
 public:
  /// Throws std::invalid_argument naming the field when the mesh, material or options are bad.
  MembraneModel(MembraneMesh mesh, FilmMaterial material, MembraneOptions options = MembraneOptions{});

  const MembraneMesh& mesh() const { return mesh_; }
  const FilmMaterial& material() const { return material_; }
  const MembraneOptions& options() const { return options_; }
  int nodeCount() const { return mesh_.nodeCount(); }

  const Eigen::Matrix3Xd& positions() const { return x_; }
  const Eigen::Matrix3Xd& velocities() const { return v_; }
  void setPositions(const Eigen::Matrix3Xd& x);
  void zeroVelocities();
  PlateState& plate() { return plate_; }
  const PlateState& plate() const { return plate_; }
  /// Lumped nodal masses [kg].
  const Eigen::VectorXd& nodeMass() const { return mass_; }

  /// Largest stable explicit step of the film and its contacts [s].
  double stableTimeStep() const { return dt_stable_; }
  /// Enclosed gas volume (paper eq. 11) at the current positions [m^3].
  double volume(const Eigen::Vector3d& axis_weights = Eigen::Vector3d(1.0, 0.0, 0.0)) const {
    return enclosedVolume(mesh_, x_, axis_weights);
  }
  /// Total force on every node (film, gas at gauge pressure p, contacts) into forces();
  /// plate contact force into plate().contact_force_n.
  ForceSummary computeForces(double gauge_pressure_pa);
  const Eigen::Matrix3Xd& forces() const { return f_; }
  /// Last element responses (stretch, state, thickness) for output.
  const std::vector<TriangleResponse>& elementResponses() const { return response_; }

  /// One explicit step (semi-implicit Euler) of dt with gauge pressure p held over it and
  /// mass-proportional film damping `film_damping_per_s`. Forces must be current
  /// (computeForces at the current state); the step leaves them stale.
  void step(double dt, double film_damping_per_s);
  /// Kinetic energy of film and plate [J].
  double kineticEnergy() const;
  /// RMS of the out-of-balance force over free node components [N].
  double residualRms() const;
  /// Mean nodal reference area [m^2] (force scale p * this).
  double meanNodeArea() const { return mean_node_area_; }

 private:
  void buildReferences();
  void buildContactExclusions();
  void addPressure(double gauge_pressure_pa);
  void addBedAndPlate(ForceSummary* summary);
  void addSelfContact();
  void rebuildNeighbours();

  MembraneMesh mesh_;
  FilmMaterial material_;
  MembraneOptions options_;
  std::vector<TriangleReference> ref_;
  std::vector<TriangleResponse> response_;
  std::vector<std::vector<std::pair<int, int>>> node_elements_;  // (triangle, corner) per node
  Eigen::Matrix3Xd x_, v_, f_;
  Eigen::VectorXd mass_;
  PlateState plate_;
  double dt_stable_ = 0.0;
  double contact_k_ = 0.0;
  double contact_c_ = 0.0;
  double mean_node_area_ = 0.0;
  // Self contact: excluded partners (sorted) and a Verlet neighbour list.
  std::vector<std::vector<int>> excluded_;
  std::vector<std::vector<int>> neighbours_;
  Eigen::Matrix3Xd x_at_build_;
  bool neighbours_valid_ = false;
};

}  // namespace fe
}  // namespace nursing_bed
