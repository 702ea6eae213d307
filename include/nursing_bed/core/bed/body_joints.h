// The joints of the articulated patient (ROS-free): neck, lumbar spine, shoulders, elbows,
// wrists, hips, knees and ankles join the body model's rigid segments. Each joint is an elastic
// potential on the poses of the two segments it joins: a stiff spring holding the joint's two
// ends at the same height, a rotational spring with range-of-motion limits on the relative
// pitch, and a weak one on the relative roll. BodyModel minimises it with the contact potential
// when PatientParams::articulated is set. Reference: doc/simulator.md, "Joints".
//
// Poses are per segment (z: underside apex height [m], t: tan(roll), s: dz/dx, the pitch
// slope); angles are small-angle slopes [rad].
#pragma once

#include <vector>

#include <Eigen/Dense>

namespace nursing_bed {

/// One line of the joint table.
struct JointSpec {
  const char* name;        ///< e.g. "right_knee"
  int parent, child;       ///< segment indices (segmentTable())
  double from_vertex_h;    ///< joint centre along the body from the vertex, of stature H
  double lateral_h;        ///< joint centre from the body midline, + to the patient's left, of H
  double pitch_stiffness;  ///< passive rotational stiffness about the lateral axis [N m/rad]
  double pitch_min_rad;    ///< range of motion of the child's distal end, down (-) ...
  double pitch_max_rad;    ///< ... and up (+), from the rest pose [rad]
};

/// The joints: neck, lumbar (two), shoulders, elbows, wrists, hips, knees, ankles.
const std::vector<JointSpec>& jointTable();

/// A segment's pose and where it is, as the joints see it.
struct JointSegment {
  double x_c = 0.0, y_c = 0.0;  ///< footprint centre [m]
  int dof = -1;                 ///< index of its first unknown (z, t, s) in the solver's vector; -1: not solved
};

/// The joints' potential for one patient: calibrated rest offsets and its derivatives.
class BodyJoints {
 public:
  /// `x_vertex_m`, `y_mid_m`: the vertex's x and the body midline's y in the bed frame;
  /// `height_m`: stature; `translation_stiffness_n_m`: the joint-height spring.
  BodyJoints(double x_vertex_m, double y_mid_m, double height_m, double translation_stiffness_n_m);

  /// Sets the rest pose: the joints are unstrained at `poses` (z, t, s per solved segment,
  /// indexed through `segments`), the body's pose on a flat bed.
  void calibrate(const std::vector<JointSegment>& segments, const Eigen::VectorXd& poses);

  /// Adds the joints' potential to *energy, its gradient to *gradient and its Hessian to
  /// *hessian at `poses` (both or neither may be null: the energy alone); joints with a segment
  /// not solved are skipped.
  void accumulate(const std::vector<JointSegment>& segments, const Eigen::VectorXd& poses, double* energy,
                  Eigen::VectorXd* gradient, Eigen::MatrixXd* hessian) const;

 private:
  struct Joint {
    JointSpec spec;
    double x = 0.0, y = 0.0;  // joint centre in the bed frame [m]
    double height_rest = 0.0, pitch_rest = 0.0, roll_rest = 0.0;
    double distal_sign = 1.0;  // +1 when the child lies towards +x of the joint
  };
  /// d(joint height on segment)/d(z, t, s) of `seg` at joint `j`.
  Eigen::Vector3d heightGradient(const Joint& j, const JointSegment& seg) const;

  std::vector<Joint> joints_;
  double translation_stiffness_ = 0.0;
};

}  // namespace nursing_bed
