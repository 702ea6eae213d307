#include "nursing_bed/core/bed/body_joints.h"

#include <algorithm>

namespace nursing_bed {

namespace {

// Segment indices (segmentTable() order).
// clang-format off
enum : int {
  kHeadNeck = 0, kThorax, kAbdomen, kPelvis,
  kRightUpperArm, kRightForearm, kRightHand, kLeftUpperArm, kLeftForearm, kLeftHand,
  kRightThigh, kRightLeg, kRightFoot, kLeftThigh, kLeftLeg, kLeftFoot
};
// clang-format on

// Joint centres, fractions of stature H from the vertex (Winter Fig. 4.1 landmark heights,
// 1 - height): neck (C4-C7) 0.160, shoulder 0.182, elbow 0.368, wrist 0.514, hip (greater
// trochanter) 0.470, knee 0.715, the ankle line of the segment table 0.941; the lumbar joints at
// the trunk segments' borders 0.330 (T12/L1) and 0.400 (L4/L5); limbs on their own axes.
// Ranges of motion (AAOS, "Joint Motion: Method of Measuring and Recording", 1965): knee
// flexion 135 deg, hyperextension 5 deg; hip flexion 120 deg, extension 30 deg; elbow flexion
// 145 deg, hyperextension 5 deg; shoulder flexion 180 deg, extension 60 deg; wrist 70-80 deg;
// ankle dorsiflexion 20 deg; neck flexion/extension ~45 deg; lumbar ~20 deg per level
// (small-angle slopes: large ranges are capped at 1.4 rad). Passive stiffness in the relaxed
// mid-range: a few N m/rad at the knee and elbow, ~10 at the hip and ankle (the mid-range slopes
// of the passive moments of Riener & Edrich, J. Biomech. 32 (1999) 539-544), stiffer at the spine.
// Pitch is the child's distal end rising (+) or sinking (-) against the parent.
// clang-format off
const std::vector<JointSpec> kJointTable = {
    // name              parent          child           along  lateral  k [Nm/rad]  min     max
    {"neck",             kThorax,        kHeadNeck,      0.160,  0.000,  10.0,      -0.70,  0.70},
    {"upper_lumbar",     kAbdomen,       kThorax,        0.330,  0.000,  30.0,      -0.35,  0.35},
    {"lower_lumbar",     kPelvis,        kAbdomen,       0.400,  0.000,  30.0,      -0.35,  0.35},
    {"right_shoulder",   kThorax,        kRightUpperArm, 0.182, -0.125,   2.0,      -1.00,  1.40},
    {"right_elbow",      kRightUpperArm, kRightForearm,  0.368, -0.125,   1.0,      -0.09,  1.40},
    {"right_wrist",      kRightForearm,  kRightHand,     0.514, -0.125,   0.5,      -1.00,  1.00},
    {"left_shoulder",    kThorax,        kLeftUpperArm,  0.182,  0.125,   2.0,      -1.00,  1.40},
    {"left_elbow",       kLeftUpperArm,  kLeftForearm,   0.368,  0.125,   1.0,      -0.09,  1.40},
    {"left_wrist",       kLeftForearm,   kLeftHand,      0.514,  0.125,   0.5,      -1.00,  1.00},
    {"right_hip",        kPelvis,        kRightThigh,    0.470, -0.048,  10.0,      -0.52,  1.40},
    {"right_knee",       kRightThigh,    kRightLeg,      0.715, -0.048,   5.0,      -1.40,  0.09},
    {"right_ankle",      kRightLeg,      kRightFoot,     0.941, -0.048,  10.0,      -0.35,  0.35},
    {"left_hip",         kPelvis,        kLeftThigh,     0.470,  0.048,  10.0,      -0.52,  1.40},
    {"left_knee",        kLeftThigh,     kLeftLeg,       0.715,  0.048,   5.0,      -1.40,  0.09},
    {"left_ankle",       kLeftLeg,       kLeftFoot,      0.941,  0.048,  10.0,      -0.35,  0.35},
};
// clang-format on

// Beyond a range of motion the joint stiffens to this [N m/rad]; the relative roll of two
// joined segments is held by this weak spring (it only keeps a lifted limb from spinning) [N m/rad].
constexpr double kLimitStiffness = 1000.0;
constexpr double kRollStiffness = 1.0;

// Adds k/2 e^2 with de/dx = +1 at a and -1 at b (one coordinate each).
void addDifference(double k, double e, int a, int b, double* energy, Eigen::VectorXd* g, Eigen::MatrixXd* h) {
  *energy += 0.5 * k * e * e;
  if (!g) return;
  (*g)(a) += k * e;
  (*g)(b) -= k * e;
  (*h)(a, a) += k;
  (*h)(b, b) += k;
  (*h)(a, b) -= k;
  (*h)(b, a) -= k;
}

}  // namespace

const std::vector<JointSpec>& jointTable() { return kJointTable; }

BodyJoints::BodyJoints(double x_vertex_m, double y_mid_m, double height_m, double translation_stiffness_n_m)
    : translation_stiffness_(translation_stiffness_n_m) {
  for (const JointSpec& spec : kJointTable) {
    Joint j;
    j.spec = spec;
    j.x = x_vertex_m - spec.from_vertex_h * height_m;
    j.y = y_mid_m + spec.lateral_h * height_m;
    joints_.push_back(j);
  }
}

Eigen::Vector3d BodyJoints::heightGradient(const Joint& j, const JointSegment& seg) const {
  return Eigen::Vector3d(1.0, j.y - seg.y_c, j.x - seg.x_c);
}

void BodyJoints::calibrate(const std::vector<JointSegment>& segments, const Eigen::VectorXd& poses) {
  for (Joint& j : joints_) {
    const JointSegment& p = segments[j.spec.parent];
    const JointSegment& c = segments[j.spec.child];
    j.distal_sign = c.x_c >= j.x ? 1.0 : -1.0;
    if (p.dof < 0 || c.dof < 0) continue;
    j.height_rest =
        heightGradient(j, p).dot(poses.segment<3>(p.dof)) - heightGradient(j, c).dot(poses.segment<3>(c.dof));
    j.pitch_rest = j.distal_sign * (poses(c.dof + 2) - poses(p.dof + 2));
    j.roll_rest = poses(c.dof + 1) - poses(p.dof + 1);
  }
}

void BodyJoints::accumulate(const std::vector<JointSegment>& segments, const Eigen::VectorXd& poses, double* energy,
                            Eigen::VectorXd* gradient, Eigen::MatrixXd* hessian) const {
  for (const Joint& j : joints_) {
    const JointSegment& p = segments[j.spec.parent];
    const JointSegment& c = segments[j.spec.child];
    if (p.dof < 0 || c.dof < 0) continue;
    // The joint's two ends at one height: k/2 (J_p - J_c - rest)^2, J linear in the poses.
    const Eigen::Vector3d gp = heightGradient(j, p), gc = heightGradient(j, c);
    const double e = gp.dot(poses.segment<3>(p.dof)) - gc.dot(poses.segment<3>(c.dof)) - j.height_rest;
    const double k = translation_stiffness_;
    *energy += 0.5 * k * e * e;
    if (gradient) {
      gradient->segment<3>(p.dof) += k * e * gp;
      gradient->segment<3>(c.dof) -= k * e * gc;
      hessian->block<3, 3>(p.dof, p.dof) += k * gp * gp.transpose();
      hessian->block<3, 3>(c.dof, c.dof) += k * gc * gc.transpose();
      hessian->block<3, 3>(p.dof, c.dof) -= k * gp * gc.transpose();
      hessian->block<3, 3>(c.dof, p.dof) -= k * gc * gp.transpose();
    }
    // Pitch: distal lift a = sign (s_c - s_p) - rest; the spring, and the stiff limits beyond
    // the range (convex: one-sided quadratics).
    const double a = j.distal_sign * (poses(c.dof + 2) - poses(p.dof + 2)) - j.pitch_rest;
    const double over = std::max(0.0, a - j.spec.pitch_max_rad) + std::min(0.0, a - j.spec.pitch_min_rad);
    // d a / d s_c = sign, d a / d s_p = -sign: the same as e = sign a over (c, p).
    auto addPitch = [&](double kp, double value) {
      addDifference(kp, j.distal_sign * value, c.dof + 2, p.dof + 2, energy, gradient, hessian);
    };
    addPitch(j.spec.pitch_stiffness, a);
    if (over != 0.0) addPitch(kLimitStiffness, over);
    addDifference(kRollStiffness, poses(c.dof + 1) - poses(p.dof + 1) - j.roll_rest, c.dof + 1, p.dof + 1, energy,
                  gradient, hessian);
  }
}

}  // namespace nursing_bed
