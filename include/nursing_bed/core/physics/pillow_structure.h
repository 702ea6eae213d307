// Reduced-order structure of the paper's double-layer airbag: stacked gusseted "pillow"
// chambers under a rigid plate. Derivation and limits: doc/cell_model.md.
#pragma once

#include <string>

#include "nursing_bed/core/io/status.h"
#include "nursing_bed/core/physics/cell_structure.h"
#include "nursing_bed/core/physics/yeoh.h"

namespace nursing_bed {

/// Geometry and film of the pillow cell. Defaults: the paper's 100 x 100 mm double-layer cell
/// (doc/cell_model.md says where each value comes from).
struct PillowParams {
  double face_side_m = 0.100;         ///< side of the square top/bottom faces (deflated footprint)
  double gusset_height_m = 0.079;     ///< unstretched side-gusset height of one chamber
  int chambers = 2;                   ///< stacked chambers sharing one gas volume
  double film_thickness_m = 0.50e-3;  ///< TPU film thickness
  double dead_volume_m3 = 5.0e-6;     ///< inlet fitting, tube stub and folds at zero height
  /// Fraction of the dead volume held in the flat films' folds under the plate, squeezed out as
  /// the plate presses the flat cell (FlatFold) [-], in (0, 1).
  double fold_fraction = 0.3;
  double film_relaxation_time_s = 2.0e-3;  ///< viscous time scale of the film shape at rest
  double max_film_stretch = 2.0;           ///< largest equibiaxial stretch the film is trusted to (rupture margin)
  YeohMaterial material;                   ///< film constitutive law (paper eq. 7)

  /// Success when valid, else an error naming what is wrong.
  Status validate() const;
};

/**
 * Each chamber's cross-section is a loop of film of unstretched length L0 = 2 (a + g) (two
 * faces of side a and two gussets of height g) that, under pressure, forms a flat contact
 * band of width w top and bottom joined by semicircular sides of diameter equal to the chamber
 * height c (a pressurised membrane between two flat contacts takes circular arcs of radius
 * T/p; the semicircle is the one tangent to both contacts). The film stretches equibiaxially
 * by lambda, so w = lambda L0 / 2 - (pi/2) c: as the cell rises, film rolls from the contact
 * flats into the sides and the flat shrinks. In 3D the flat is a w x w square, the sides are
 * half-cylinders along its edges and the corners a sphere of radius c/2:
 *   V_chamber = w^2 c + (pi/2) w c^2 + (pi/6) c^3          (paper eq. 11, closed form)
 *   A_eff     = dV/dh|lambda = w^2 - (pi^2/4 - pi/2) c^2    (plate force = p_gauge A_eff)
 * Shape coordinate q = {lambda}; film energy n A0 t W_yeoh(2 l^2 + l^-4), A0 = L0^2 / 2 per
 * chamber. The chambers are identical in series, c = h / n.
 */
class PillowStructure : public CellStructure {
 public:
  explicit PillowStructure(const PillowParams& params);

  int shapeDofs() const override { return 1; }
  std::array<double, kMaxShapeDofs> restShape() const override;
  StructureEval evaluate(double height_m, const double* shape) const override;
  double heightLimit(const double* shape) const override;
  bool withinLimits(double height_m, const double* shape) const override;
  std::string describe() const override;

  const PillowParams& params() const { return params_; }
  /// Reference volume of all film (n A0 t) [m^3]: film energy = this * W_yeoh per unit volume.
  double filmVolume() const { return film_volume_m3_; }
  /// The film's elastic force dW/dlambda at `stretch` (evaluate()'s elastic_force[0], which does
  /// not depend on the height), without building the structure.
  static double elasticForce(const PillowParams& params, double stretch);

 private:
  PillowParams params_;
  double loop_length_m_;      // L0
  double film_volume_m3_;     // n A0 t: reference film volume of all chambers
  double shape_damping_j_s_;  // eta of lambda
  FlatFold fold_;             // below h = 0
};

}  // namespace nursing_bed
