// A patient lying supine on the cell array (ROS-free): rigid body segments with Dempster's mass
// fractions (via Winter) resting on the cells through soft tissue, modelled as a Winkler
// foundation under a rounded underside. Given every cell's height it finds where each segment
// rests (height z and roll about its long axis) and what load and interface pressure each cell
// takes. The simulator node couples it to the airbag nodes; posture plans use its footprint
// helpers to know where the body lies. Model, sources and calibration: doc/simulator.md.
//
// Units: SI throughout (m, kg, N, Pa, rad); frame: the bed grid's (bed_link: x towards the head,
// y to the patient's left, z up from the bed surface; see bed_grid.h).
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Dense>

#include "nursing_bed/core/bed/bed_grid.h"
#include "nursing_bed/core/bed/body_joints.h"
#include "nursing_bed/core/io/status.h"

namespace nursing_bed {

/// The patient and the contact model.
struct PatientParams {
  double mass_kg = 70.0;           ///< body mass [kg]
  double height_m = 1.70;          ///< stature [m]
  double head_clearance_m = 0.05;  ///< top of the head to the bed's head edge [m]
  /// Winkler modulus of the soft tissue and the mattress cover in series: contact pressure per
  /// unit penetration [Pa/m]. 1.5e5 Pa/m: ~30-47 mm immersion at the bony prominences, the
  /// sacrum/heel/occiput peaks of doc/paper_targets.md with the underside radii of the segment table.
  double tissue_stiffness_pa_m = 1.5e5;
  double lateral_offset_m = 0.0;  ///< body midline across the bed, + to the patient's left [m]
  /// Spacing of the contact sub-points over each segment's footprint [m] (<= 1/4 of a cell, so
  /// that point peaks are resolved inside a cell).
  double contact_resolution_m = 0.01;
  /// true: the tissue rests on a cover spanning the plates: the surface is the bilinear
  /// interpolation of the cell heights between cell centres (a plane of cells stays a plane).
  /// false: bare flat plates, each point on the plate of the cell under it (a staircase).
  bool smooth_cover = true;
  double max_roll_rad = 1.0;  ///< a segment's roll is bounded to +-this (it would roll off) [rad]
  /// true: the segments are joined (BodyJoints: neck, spine, shoulders, elbows, wrists, hips,
  /// knees, ankles) and pitch along the body; the whole body is solved at once. The joints' rest
  /// pose is the body's on a flat bed, where both models agree. false: free segments.
  bool articulated = false;
  /// Stiffness holding a joint's two ends at one height [N/m] (articulated only).
  double joint_stiffness_n_m = 1e5;

  /// Success when valid, else an error with every problem found, each naming the field.
  Status validate() const;
};

/// One line of the segment table: anthropometry (fractions of stature H or body mass) and the
/// contact shape. Positions are along the body from the vertex (top of the head), supine.
struct SegmentSpec {
  const char* name;         ///< e.g. "pelvis", "left_foot"
  double mass_fraction;     ///< of body mass (Dempster via Winter, Table 4.1)
  double length_fraction;   ///< anatomical segment length, of H (Winter Fig. 4.1; trunk: chosen)
  double start_fraction;    ///< contact footprint from this distance from the vertex, of H
  double end_fraction;      ///< ... to this one, of H
  double width_fraction;    ///< footprint width across the bed, of H
  double depth_fraction;    ///< thickness above the bed (drawing only), of H
  double lateral_fraction;  ///< footprint centre from the body midline, + to the patient's left, of H
  double radius_x_m;        ///< underside radius along the body, for H = 1.70 m (scales with H) [m]
  double radius_y_m;        ///< underside radius across the body, for H = 1.70 m [m]
  int parent;               ///< index of the proximal segment (-1: pelvis, the root)
  bool trunk;               ///< thorax, abdomen, pelvis: their roll is the body's roll
};

/// The 16 segments: head+neck, thorax, abdomen, pelvis, and per side (right first) upper arm,
/// forearm, hand, thigh, leg (shank), foot. Mass fractions sum to 1.
const std::vector<SegmentSpec>& segmentTable();

/// Where a segment rests and what carries it.
// size: a plain record of one segment's pose, size and support for the simulator's outputs
struct SegmentPose {
  std::string name;
  double x_c_m = 0.0;      ///< apex of the underside (footprint centre) along the bed [m]
  double y_c_m = 0.0;      ///< across the bed; the segment's long axis [m]
  double z_m = 0.0;        ///< underside apex height above the bed surface [m]
  double roll_rad = 0.0;   ///< about the long axis (+x); + lowers the patient's right side [rad]
  double pitch_rad = 0.0;  ///< about the lateral axis; + raises the head end (articulated only) [rad]
  double mass_kg = 0.0;
  double length_m = 0.0;            ///< anatomical length [m]
  double width_m = 0.0;             ///< footprint width [m]
  double footprint_length_m = 0.0;  ///< footprint length along the bed [m]
  double depth_m = 0.0;             ///< thickness (drawing) [m]
  double support_n = 0.0;           ///< force the cells push up with (own weight + unsupported children) [N]
  double moment_residual_nm = 0.0;  ///< sum F (y - y_c) left over (0 at equilibrium; not 0 when at max roll) [N m]
  double peak_pressure_pa = 0.0;    ///< highest point pressure under the segment [Pa]
  bool on_bed = true;               ///< false: footprint off the bed; its weight went to its parent
  bool at_roll_limit = false;       ///< the roll hit +-max_roll_rad (unbalanced: it would roll off)
  /// Cells this segment loads (by id) and how much [N].
  std::vector<std::pair<std::uint32_t, double>> cell_loads_n;
};

/// Peak interface pressures by region [Pa].
struct RegionPressures {
  double sacrum = 0.0;   ///< under the pelvis
  double heels = 0.0;    ///< under the feet
  double occiput = 0.0;  ///< under the head
};

/// One contact sub-point of the last solve: where it is on the body and what it bears. The
/// body's interface-pressure map, at contact_resolution_m; tissue-load metrics are taken over it.
struct ContactPoint {
  int segment = 0;             ///< index in segmentTable()
  double from_vertex_m = 0.0;  ///< along the body from the top of the head [m]
  double lateral_m = 0.0;      ///< across the segment from its long axis, + to the patient's left [m]
  double half_width_m = 0.0;   ///< the segment footprint's half width [m]
  double area_m2 = 0.0;        ///< area the point stands for [m^2]
  double pressure_pa = 0.0;    ///< interface pressure (0: no contact) [Pa]
  /// Height of the skin above the bed base (cell height 0) here: the cell surface where the
  /// point is in contact, the segment's underside where it is not [m].
  double skin_height_m = 0.0;
};

/// The solved body on the cells.
struct BodyState {
  std::vector<double> cell_load_n;            ///< by cell id: the body's share [N] (no plate weight)
  std::vector<double> cell_pressure_pa;       ///< by cell id: load / cell face area [Pa]
  std::vector<double> cell_peak_pressure_pa;  ///< by cell id: highest point pressure over the cell's face [Pa]
  std::vector<SegmentPose> segments;          ///< in segmentTable() order
  double roll_rad = 0.0;                      ///< body roll: mass-weighted roll of thorax, abdomen, pelvis [rad]
  /// Point peaks (a pressure mat's view, ~10 mm sensels): compare with the clinical references.
  RegionPressures peak_pressure_pa;
  /// Peaks of the cell-averaged pressure (load / 100 mm face) over the cells of each region.
  RegionPressures peak_cell_pressure_pa;
  double total_load_n = 0.0;  ///< sum of cell_load_n (= m g) [N]
  bool converged = true;      ///< every segment's equilibrium met the tolerance
  int iterations = 0;         ///< Newton iterations, all segments
};

/**
 * The body on the bed. Each segment is a rigid body with two degrees of freedom, the height z
 * of its underside apex and its roll phi, resting on the cell surface h(x, y) through a
 * Winkler layer: at every sub-point of its footprint the pressure is
 *   p = k_w max(0, h(x, y) - b(x, y)),
 *   b(x, y) = z + tan(phi) (y - y_c) + (y - y_c)^2 / (2 R_y) + (x - x_c)^2 / (2 R_x).
 * Equilibrium: sum F = m g and sum F (y - y_c) = 0. Both are the stationary conditions of the
 * convex potential m g z + k_w/2 sum a max(0, h - b)^2 in (z, tan phi), which solve() minimises
 * by Newton's method with a line search (warm-started from the last pose): it always converges,
 * also when a segment touches only part of its footprint or bridges deflated cells. A segment
 * whose footprint is off the bed hands its weight to its parent (foot -> leg -> thigh -> pelvis,
 * hand -> forearm -> upper arm -> thorax). Limbs roll freely (each follows its own local slope);
 * the trunk segments and the head roll each on their own too, and the body's roll is the trunk's.
 */
// size: 26 methods: the free and the articulated solve share the segments' contact geometry
class BodyModel {
 public:
  /// Throws std::invalid_argument naming the problem when `params` are invalid or the trunk
  /// does not lie on the bed (limbs may hang off the foot end; their weight goes to the parent).
  BodyModel(const PatientParams& params, const BedGrid& grid);

  /// Rests the body on cells at `cell_heights_m` (by cell id, [m]); throws std::invalid_argument
  /// when the size is not grid.cells() or a height is not finite.
  BodyState solve(const std::vector<double>& cell_heights_m);

  /// The contact sub-points of every segment on the bed at the poses of the last solve() on
  /// `cell_heights_m` (pass the same heights); cheaper than solve() (no Newton), for
  /// occasional tissue-load metrics. Throws std::invalid_argument as solve() does.
  std::vector<ContactPoint> contactMap(const std::vector<double>& cell_heights_m) const;

  /// Forgets the warm start (the next solve starts from scratch).
  void reset();

  /// Rows any segment's footprint covers (sorted).
  std::vector<int> footprintRows() const;
  /// Rows under the thorax, abdomen and pelvis (sorted).
  std::vector<int> trunkRows() const;
  /// Rows under the head (sorted).
  std::vector<int> headRows() const;
  /// Rows under the pelvis (sorted).
  std::vector<int> pelvisRows() const;
  /// Rows under the feet (heels) (sorted).
  std::vector<int> heelRows() const;
  /// Columns any segment's footprint covers (sorted).
  std::vector<int> footprintCols() const;

  const PatientParams& params() const { return params_; }
  const BedGrid& grid() const { return grid_; }
  double weightN() const;
  /// Index of a segment in segmentTable() by name, or -1.
  static int segmentIndex(const std::string& name);

 private:
  struct SubPoint {
    double u = 0.0;                        // y - y_c [m]
    double x = 0.0;                        // along the bed [m]
    double v = 0.0;                        // x - x_c [m]
    double q = 0.0;                        // (y - y_c)^2 / 2R_y + (x - x_c)^2 / 2R_x [m]
    double area = 0.0;                     // [m^2]
    std::uint32_t cell[4] = {0, 0, 0, 0};  // cells whose heights make the surface here
    double weight[4] = {0.0, 0.0, 0.0, 0.0};
    std::uint32_t face_cell = 0;  // the cell under this point
  };
  // size: a plain record of one segment's footprint, sub-points and warm-started pose
  struct Segment {
    SegmentSpec spec;
    double x_c = 0.0, y_c = 0.0, x0 = 0.0, x1 = 0.0, y0 = 0.0, y1 = 0.0;
    double mass_kg = 0.0, radius_x = 0.0, radius_y = 0.0;
    double carried_n = 0.0;  // own weight + that of children off the bed [N]
    bool on_bed = true;
    std::vector<SubPoint> points;
    double z = 0.0, t = 0.0;  // pose: apex height and tan(roll)
    double s = 0.0;           // pitch slope dz/dx (articulated only; 0 for free segments)
    bool warm = false;
  };
  struct Evaluation {
    double potential = 0.0, force = 0.0, moment = 0.0, s0 = 0.0, s1 = 0.0, s2 = 0.0;
  };

  void buildSegment(Segment* seg) const;
  Evaluation evaluate(const Segment& seg, const std::vector<double>& surface, double z, double t) const;
  /// Newton on the segment's potential; returns iterations, sets *converged.
  int solveSegment(Segment* seg, const std::vector<double>& surface, bool* converged) const;
  std::vector<int> rowsOf(const std::vector<int>& segment_indices) const;
  // The steps of solve(), in its order.
  /// Throws std::invalid_argument when the heights do not fit the grid or one is not finite.
  void checkHeights(const std::vector<double>& cell_heights_m) const;
  /// The pose's fixed part: name, size, mass, where the footprint is.
  SegmentPose segmentPose(const Segment& seg) const;
  /// The cell surface at each of the segment's sub-points, interpolated from the cell heights.
  void surfaceUnder(const Segment& seg, const std::vector<double>& cell_heights_m, std::vector<double>* surface) const;
  /// The solved segment's contact: its pose's support and peaks, its loads on the cells
  /// (`loads`: scratch, by cell id) added to the state's cell loads and peak pressures.
  void restOnCells(const Segment& seg, const std::vector<double>& surface, std::vector<double>* loads,
                   SegmentPose* pose, BodyState* state) const;
  /// Cell pressures, total load and regional peaks from the cell loads and the segments.
  void cellPressures(BodyState* state) const;
  // The articulated body (params_.articulated).
  /// The joints' rest pose from the free segments on a flat bed.
  void calibrateJoints();
  /// Newton on the whole body's potential (contact, weight, joints) from the last poses (or the
  /// free segments' when cold); returns iterations, sets *converged.
  int solveArticulated(const std::vector<std::vector<double>>& surfaces, bool* converged);
  /// The whole body's potential at `poses` (z, t, s per solved segment), its gradient and Hessian
  /// (both null: the potential alone, for the line search).
  double articulatedPotential(const std::vector<JointSegment>& dofs, const std::vector<std::vector<double>>& surfaces,
                              const Eigen::VectorXd& poses, Eigen::VectorXd* gradient, Eigen::MatrixXd* hessian) const;

  PatientParams params_;
  BedGrid grid_;
  std::vector<Segment> segments_;
  std::optional<BodyJoints> joints_;  // articulated only
  bool articulated_warm_ = false;     // the segments' poses are the last articulated solve's
};

}  // namespace nursing_bed
