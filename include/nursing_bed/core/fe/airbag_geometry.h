// Geometry generator of the paper's double-layer airbag (fig. 2, 7): stacked square chambers
// joined in the middle by a welded patch, with or without side gussets, stress-free as made.
#pragma once

#include <string>

#include "nursing_bed/core/fe/mesh.h"
#include "nursing_bed/core/io/status.h"

namespace nursing_bed {
namespace fe {

/// Parts (MembraneMesh::part) of the airbag mesh.
enum AirbagPart { kBottomFace = 0, kTopFace = 1, kGusset = 2, kConnection = 3 };

struct AirbagGeometry {
  double face_side_m = 0.100;  ///< side of the square faces (paper: 100 x 100 mm)
  int chambers = 2;            ///< stacked chambers, one gas volume (paper: two)
  /// Side of the square welded patch joining neighbouring chambers in the middle; the gas
  /// passes through a hole in it (not modelled: one uniform pressure). Paper: size not given.
  double connection_side_m = 0.030;
  /// Side-gusset height per chamber; 0 = flat pillow (two squares welded at the rim). The
  /// reduced model's gussets are 0.079 m (PillowParams).
  double gusset_height_m = 0.0;
  double film_thickness_m = 0.50e-3;  ///< TPU film (PillowParams default)
  int elements_per_side = 12;         ///< grid cells along a face side (default mesh)
  /// Hold the centre of the bottom face (the inlet fitting on the bed) and of the top face
  /// (stuck to the plate by friction) horizontally: without it the frictionless bag slides or
  /// tips under the plate (the gusseted bag tipped over in a transient).
  bool pin_centres = true;

  /// Two pillows without gussets (reading (a) of the paper's bag).
  static AirbagGeometry flatPillows();
  /// Today's reduced model's gusseted chambers (reading (b)).
  static AirbagGeometry gusseted();

  double elementSize() const { return face_side_m / elements_per_side; }
  /// Gap between film layers at the start, also the self-contact distance [m].
  double layerGap() const { return 0.4 * elementSize(); }
  /// Success, or what is wrong (names the field).
  Status validate() const;
  std::string describe() const;
};

/**
 * Builds the closed bag. Each face is a grid panel whose rest shape is its flat pattern. Flat
 * pillows: the rims of a chamber's two faces are shared nodes (the weld); the faces start a
 * layer gap apart (a ramp over the outer two cells, <= 2 % strain there at the start; the
 * rest shapes stay flat) so that the layers do not start in contact. Gusseted chambers start as erected boxes (stress-free: a box of flat
 * panels is isometric to its net). Neighbouring chambers share the connection patch: one set
 * of triangles of double thickness, gas on both sides (not pressurised, outside eq. 11).
 * Throws std::invalid_argument (naming the field) for a bad geometry.
 */
MembraneMesh buildAirbagMesh(const AirbagGeometry& geometry);

/// Height of the bag's top above the bed at the start [m].
double initialTop(const MembraneMesh& mesh);

}  // namespace fe
}  // namespace nursing_bed
