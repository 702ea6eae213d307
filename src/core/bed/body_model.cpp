#include "nursing_bed/core/bed/body_model.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <set>
#include <sstream>
#include <stdexcept>

#include "nursing_bed/core/io/errors.h"
#include "nursing_bed/core/physics/units.h"

namespace nursing_bed {

namespace {

// Stature the underside radii of the table are given for [m]; they scale with H / this.
constexpr double kReferenceStatureM = 1.70;

// Segment indices (segmentTable() order).
// clang-format off
enum : int {
  kHeadNeck = 0, kThorax, kAbdomen, kPelvis,
  kRightUpperArm, kRightForearm, kRightHand, kLeftUpperArm, kLeftForearm, kLeftHand,
  kRightThigh, kRightLeg, kRightFoot, kLeftThigh, kLeftLeg, kLeftFoot, kSegmentCount
};
// clang-format on

// Where the segment table's numbers come from.
//
// Mass fractions: Dempster (1955) as tabulated by Winter, "Biomechanics and Motor Control of
// Human Movement" (4th ed., 2009), Table 4.1: head+neck 0.081, thorax 0.216, abdomen 0.139,
// pelvis 0.142, upper arm 0.028, forearm 0.016, hand 0.006, thigh 0.100, leg 0.0465,
// foot 0.0145 (each limb segment per side); they sum to 1.000.
//
// Lengths and widths, fractions of stature H: Winter Fig. 4.1 (after Drillis & Contini 1966):
// head (vertex-chin) 0.130, upper arm 0.186, forearm 0.146, hand 0.108, thigh 0.245,
// leg 0.246, foot 0.152; shoulder width 0.259, hip width 0.191, chest width 0.174; landmark
// heights shoulder 0.818, hip (greater trochanter) 0.530, knee 0.285, ankle 0.039.
//
// Chosen here (not in Winter's figure): the trunk split along the body, from the shoulder line
// (0.182 H from the vertex) to the gluteal fold (0.520 H): thorax 0.148 H (to ~T12/L1),
// abdomen 0.070 H (to ~L4/L5, the iliac crest), pelvis 0.120 H (iliac crest to the gluteal
// fold: the buttocks' contact, so it reaches below the greater trochanter at 0.470 H); waist
// breadth 0.160 H, head breadth 0.091 H; limb widths from typical adult circumferences / pi
// (upper arm ~30 cm -> 0.055 H, forearm ~25 cm -> 0.045 H, hand breadth 0.050 H, mean thigh
// ~43 cm -> 0.080 H, calf ~32 cm -> 0.060 H, heel breadth 0.040 H); depths for drawing only.
// The neck (0.130-0.182 H) is in cervical lordosis and touches nothing: the head+neck mass rests
// on the head's footprint. In supine the foot stands up from the heel, so its footprint is the
// heel, 0.059 H long behind the ankle line (0.941-1.000 H from the vertex); the leg's footprint
// ends there. The thigh's contact starts at the gluteal fold.
//
// Placement: supine, head towards +x, arms along the trunk (their axes 0.125 H off the midline,
// just clear of the hips), legs hip-width apart (each leg's axis through its hip joint, a
// quarter of the hip width, 0.048 H, off the midline).
//
// Underside radii (for H = 1.70 m): the limbs are near-cylinders (R_y = half their width, R_x
// long: straight); the trunk's back is broad and flat; the contact-concentrating radii of the
// occiput, the sacrum (pelvis) and the heels are calibrated so that, with
// tissue_stiffness_pa_m = 1.5e5 Pa/m on a flat bed, the point peaks of a 70 kg, 1.70 m patient
// fall in the supine references on foam (sacrum 36-44, heels 46-59, occiput 43-63 mmHg;
// doc/paper_targets.md): see doc/simulator.md for the values obtained. The heel's small effective
// radius stands in for its thin, stiff tissue over the calcaneus.
// clang-format off
const std::vector<SegmentSpec> kSegmentTable = {
    // name             mass     length start  end    width  depth  lateral  R_x    R_y   parent       trunk
    {"head_neck",       0.081,   0.130, 0.000, 0.130, 0.091, 0.115,  0.000,  0.070, 0.040, kThorax,     false},
    {"thorax",          0.216,   0.148, 0.182, 0.330, 0.174, 0.130,  0.000,  0.600, 0.200, kAbdomen,    true},
    {"abdomen",         0.139,   0.070, 0.330, 0.400, 0.160, 0.120,  0.000,  1.000, 0.400, kPelvis,     true},
    {"pelvis",          0.142,   0.120, 0.400, 0.520, 0.191, 0.130,  0.000,  0.110, 0.250, -1,          true},
    {"right_upper_arm", 0.028,   0.186, 0.182, 0.368, 0.055, 0.055, -0.125,  1.000, 0.047, kThorax,     false},
    {"right_forearm",   0.016,   0.146, 0.368, 0.514, 0.045, 0.045, -0.125,  1.000, 0.038, kRightUpperArm, false},
    {"right_hand",      0.006,   0.108, 0.514, 0.622, 0.050, 0.020, -0.125,  0.300, 0.060, kRightForearm, false},
    {"left_upper_arm",  0.028,   0.186, 0.182, 0.368, 0.055, 0.055,  0.125,  1.000, 0.047, kThorax,     false},
    {"left_forearm",    0.016,   0.146, 0.368, 0.514, 0.045, 0.045,  0.125,  1.000, 0.038, kLeftUpperArm, false},
    {"left_hand",       0.006,   0.108, 0.514, 0.622, 0.050, 0.020,  0.125,  0.300, 0.060, kLeftForearm, false},
    {"right_thigh",     0.100,   0.245, 0.520, 0.715, 0.080, 0.090, -0.048,  1.000, 0.068, kPelvis,     false},
    {"right_leg",       0.0465,  0.246, 0.715, 0.941, 0.060, 0.060, -0.048,  1.000, 0.051, kRightThigh, false},
    {"right_foot",      0.0145,  0.152, 0.941, 1.000, 0.040, 0.130, -0.048,  0.012, 0.008, kRightLeg,   false},
    {"left_thigh",      0.100,   0.245, 0.520, 0.715, 0.080, 0.090,  0.048,  1.000, 0.068, kPelvis,     false},
    {"left_leg",        0.0465,  0.246, 0.715, 0.941, 0.060, 0.060,  0.048,  1.000, 0.051, kLeftThigh,  false},
    {"left_foot",       0.0145,  0.152, 0.941, 1.000, 0.040, 0.130,  0.048,  0.012, 0.008, kLeftLeg,    false},
};
// clang-format on

// Newton's tolerance: force within this fraction of the weight, moment within this times
// weight x 1 m.
constexpr double kTolerance = 1e-10;
constexpr int kMaxIterations = 100;

std::vector<int> sortedUnique(std::set<int> s) { return std::vector<int>(s.begin(), s.end()); }

}  // namespace

const std::vector<SegmentSpec>& segmentTable() { return kSegmentTable; }

Status PatientParams::validate() const {
  ErrorList errors;
  errors.addIf(!(mass_kg >= 20.0 && mass_kg <= 250.0), "mass_kg must lie in [20, 250] kg (got ", mass_kg, ")");
  errors.addIf(!(height_m >= 1.0 && height_m <= 2.3), "height_m must lie in [1.0, 2.3] m (got ", height_m, ")");
  errors.addIf(!(head_clearance_m >= 0.0 && head_clearance_m <= 1.0), "head_clearance_m must lie in [0, 1] m (got ",
               head_clearance_m, ")");
  errors.addIf(!(tissue_stiffness_pa_m >= 1e4 && tissue_stiffness_pa_m <= 1e8),
               "tissue_stiffness_pa_m must lie in [1e4, 1e8] Pa/m (got ", tissue_stiffness_pa_m, ")");
  errors.addIf(!(std::isfinite(lateral_offset_m) && std::abs(lateral_offset_m) <= 1.0),
               "lateral_offset_m must lie in [-1, 1] m (got ", lateral_offset_m, ")");
  errors.addIf(!(contact_resolution_m >= 0.002 && contact_resolution_m <= 0.05),
               "contact_resolution_m must lie in [0.002, 0.05] m (got ", contact_resolution_m, ")");
  errors.addIf(!(max_roll_rad > 0.0 && max_roll_rad <= 1.4), "max_roll_rad must lie in (0, 1.4] rad (got ",
               max_roll_rad, ")");
  errors.addIf(!(joint_stiffness_n_m >= 1e3 && joint_stiffness_n_m <= 1e7),
               "joint_stiffness_n_m must lie in [1e3, 1e7] N/m (got ", joint_stiffness_n_m, ")");
  return errors.status();
}

int BodyModel::segmentIndex(const std::string& name) {
  for (std::size_t i = 0; i < kSegmentTable.size(); ++i)
    if (name == kSegmentTable[i].name) return static_cast<int>(i);
  return -1;
}

BodyModel::BodyModel(const PatientParams& params, const BedGrid& grid) : params_(params), grid_(grid) {
  const Status valid = params_.validate();
  if (!valid.ok()) throw std::invalid_argument("patient parameters: " + valid.message());
  if (grid_.rows < 1 || grid_.cols < 1 || !(grid_.pitch_m > 0.0))
    throw std::invalid_argument("body model: the bed grid is empty");
  const double H = params_.height_m;
  const double scale = H / kReferenceStatureM;
  const double x_vertex = 0.5 * grid_.lengthM() - params_.head_clearance_m;
  for (const SegmentSpec& spec : kSegmentTable) {
    Segment seg;
    seg.spec = spec;
    seg.x0 = x_vertex - spec.end_fraction * H;    // foot end
    seg.x1 = x_vertex - spec.start_fraction * H;  // head end
    seg.x_c = 0.5 * (seg.x0 + seg.x1);
    seg.y_c = params_.lateral_offset_m + spec.lateral_fraction * H;
    seg.y0 = seg.y_c - 0.5 * spec.width_fraction * H;
    seg.y1 = seg.y_c + 0.5 * spec.width_fraction * H;
    seg.mass_kg = spec.mass_fraction * params_.mass_kg;
    seg.radius_x = spec.radius_x_m * scale;
    seg.radius_y = spec.radius_y_m * scale;
    seg.carried_n = seg.mass_kg * kGravity;
    buildSegment(&seg);
    segments_.push_back(std::move(seg));
  }
  // Segments off the bed hand their weight to their parents, distal first (children come after
  // their parents in the table, so walk it backwards).
  for (int i = kSegmentCount - 1; i >= 0; --i) {
    Segment& seg = segments_[i];
    if (!seg.points.empty()) continue;
    seg.on_bed = false;
    if (seg.spec.parent < 0 || seg.spec.trunk || i == kHeadNeck) {
      std::ostringstream m;
      m << "body model: the " << seg.spec.name << " does not lie on the bed (a " << H << " m patient with "
        << params_.head_clearance_m << " m head clearance, lateral offset " << params_.lateral_offset_m << " m, on a "
        << grid_.lengthM() << " x " << grid_.widthM() << " m bed)";
      throw std::invalid_argument(m.str());
    }
    segments_[seg.spec.parent].carried_n += seg.carried_n;
    seg.carried_n = 0.0;
  }
  if (params_.articulated) {
    joints_.emplace(x_vertex, params_.lateral_offset_m, H, params_.joint_stiffness_n_m);
    calibrateJoints();
  }
}

void BodyModel::buildSegment(Segment* seg) const {
  // Sub-points on a regular grid over the footprint, symmetric about the segment's centre.
  const double res = params_.contact_resolution_m;
  const int nx = std::max(1, static_cast<int>(std::ceil((seg->x1 - seg->x0) / res - 1e-9)));
  const int ny = std::max(1, static_cast<int>(std::ceil((seg->y1 - seg->y0) / res - 1e-9)));
  const double dx = (seg->x1 - seg->x0) / nx, dy = (seg->y1 - seg->y0) / ny;
  const double half_l = 0.5 * grid_.lengthM(), half_w = 0.5 * grid_.widthM();
  const double p = grid_.pitch_m;
  for (int i = 0; i < nx; ++i) {
    const double x = seg->x0 + (i + 0.5) * dx;
    if (x <= -half_l || x >= half_l) continue;  // off the bed: no support
    for (int j = 0; j < ny; ++j) {
      const double y = seg->y0 + (j + 0.5) * dy;
      if (y <= -half_w || y >= half_w) continue;
      SubPoint sp;
      sp.u = y - seg->y_c;
      sp.x = x;
      const double v = x - seg->x_c;
      sp.v = v;
      sp.q = sp.u * sp.u / (2.0 * seg->radius_y) + v * v / (2.0 * seg->radius_x);
      sp.area = dx * dy;
      // Continuous cell coordinates: row r at x(r), col c at y(c).
      const double r = 0.5 * grid_.rows - 0.5 - x / p;
      const double c = y / p + 0.5 * grid_.cols - 0.5;
      const int face_row = std::clamp(static_cast<int>(std::lround(r)), 0, grid_.rows - 1);
      const int face_col = std::clamp(static_cast<int>(std::lround(c)), 0, grid_.cols - 1);
      sp.face_cell = grid_.id(face_row, face_col);
      if (params_.smooth_cover) {
        // Bilinear between the four surrounding centres; clamped beyond the outermost ones.
        const double rc = std::clamp(r, 0.0, static_cast<double>(grid_.rows - 1));
        const double cc = std::clamp(c, 0.0, static_cast<double>(grid_.cols - 1));
        const int r0 = std::min(static_cast<int>(std::floor(rc)), std::max(grid_.rows - 2, 0));
        const int c0 = std::min(static_cast<int>(std::floor(cc)), std::max(grid_.cols - 2, 0));
        const int r1 = std::min(r0 + 1, grid_.rows - 1), c1 = std::min(c0 + 1, grid_.cols - 1);
        const double fr = rc - r0, fc = cc - c0;
        sp.cell[0] = grid_.id(r0, c0);
        sp.cell[1] = grid_.id(r0, c1);
        sp.cell[2] = grid_.id(r1, c0);
        sp.cell[3] = grid_.id(r1, c1);
        sp.weight[0] = (1.0 - fr) * (1.0 - fc);
        sp.weight[1] = (1.0 - fr) * fc;
        sp.weight[2] = fr * (1.0 - fc);
        sp.weight[3] = fr * fc;
      } else {
        sp.cell[0] = sp.face_cell;
        sp.weight[0] = 1.0;
      }
      seg->points.push_back(sp);
    }
  }
}

double BodyModel::weightN() const { return params_.mass_kg * kGravity; }

void BodyModel::reset() {
  for (Segment& seg : segments_) {
    seg.warm = false;
    seg.s = 0.0;
  }
  articulated_warm_ = false;
}

BodyModel::Evaluation BodyModel::evaluate(const Segment& seg, const std::vector<double>& surface, double z,
                                          double t) const {
  // Potential m g z + k/2 sum a d+^2, its gradient (W - F, -M) and Hessian [[s0, s1], [s1, s2]].
  Evaluation e;
  double energy = 0.0;
  for (std::size_t i = 0; i < seg.points.size(); ++i) {
    const SubPoint& sp = seg.points[i];
    const double d = surface[i] - z - t * sp.u - sp.q;
    if (d <= 0.0) continue;
    const double ad = sp.area * d;
    energy += ad * d;
    e.force += ad;
    e.moment += ad * sp.u;
    e.s0 += sp.area;
    e.s1 += sp.area * sp.u;
    e.s2 += sp.area * sp.u * sp.u;
  }
  const double k = params_.tissue_stiffness_pa_m;
  e.force *= k;
  e.moment *= k;
  e.s0 *= k;
  e.s1 *= k;
  e.s2 *= k;
  e.potential = seg.carried_n * z + 0.5 * k * energy;
  return e;
}

int BodyModel::solveSegment(Segment* seg, const std::vector<double>& surface, bool* converged) const {
  const double W = seg->carried_n;
  const double t_max = std::tan(params_.max_roll_rad);
  const double k = params_.tissue_stiffness_pa_m;
  // Highest point of the surface relative to the underside at roll t: first contact there.
  auto touchdown = [&](double t) {
    double top = -std::numeric_limits<double>::infinity();
    for (std::size_t i = 0; i < seg->points.size(); ++i)
      top = std::max(top, surface[i] - t * seg->points[i].u - seg->points[i].q);
    return top;
  };
  if (!seg->warm) {
    // Cold start: level, sunk as far as a paraboloid on a plane would for this weight
    // (F = k pi sqrt(R_x R_y) d^2).
    seg->t = 0.0;
    seg->z = touchdown(0.0) - std::sqrt(W / (k * kPi * std::sqrt(seg->radius_x * seg->radius_y)));
  }
  double z = seg->z, t = seg->t;
  const double force_tol = kTolerance * W, moment_tol = kTolerance * W * 1.0;
  int it = 0;
  *converged = false;
  for (; it < kMaxIterations; ++it) {
    Evaluation e = evaluate(*seg, surface, z, t);
    if (e.s0 <= 0.0) {  // floating above the surface: drop onto it, then go on
      z = touchdown(t) - 1e-6;
      continue;
    }
    const double gz = W - e.force, gt = -e.moment;
    // Roll at its bound and pushed further out: hold it there (an unbalanced segment).
    const bool hold_t = (t >= t_max && gt < 0.0) || (t <= -t_max && gt > 0.0);
    if (std::abs(gz) <= force_tol && (hold_t || std::abs(gt) <= moment_tol)) {
      *converged = true;
      break;
    }
    double dz, dt = 0.0;
    const double det = e.s0 * e.s2 - e.s1 * e.s1;
    if (!hold_t && det > 1e-12 * e.s0 * e.s2 && e.s2 > 0.0) {
      dz = -(e.s2 * gz - e.s1 * gt) / det;
      dt = -(-e.s1 * gz + e.s0 * gt) / det;
    } else {
      dz = -gz / e.s0;  // contact along a line (no roll stiffness) or roll held: height only
    }
    // Backtracking line search on the potential (convex, C1: Newton converges from anywhere).
    const double slope = gz * dz + gt * dt;  // < 0: a descent direction
    double alpha = 1.0;
    bool accepted = false;
    for (int ls = 0; ls < 40; ++ls, alpha *= 0.5) {
      const double zn = z + alpha * dz;
      const double tn = std::clamp(t + alpha * dt, -t_max, t_max);
      const Evaluation en = evaluate(*seg, surface, zn, tn);
      // (with an allowance for rounding, or steps near the solution would be refused)
      if (en.potential <= e.potential + 1e-4 * alpha * slope + 1e-12 * std::abs(e.potential) || ls == 39) {
        z = zn;
        t = tn;
        accepted = true;
        break;
      }
    }
    if (!accepted) break;
  }
  seg->z = z;
  seg->t = t;
  seg->warm = true;
  return it;
}

void BodyModel::checkHeights(const std::vector<double>& cell_heights_m) const {
  const std::size_t n = static_cast<std::size_t>(grid_.cells());
  if (cell_heights_m.size() != n) {
    std::ostringstream m;
    m << "body model: got " << cell_heights_m.size() << " cell heights for a " << grid_.rows << " x " << grid_.cols
      << " bed (" << n << " cells)";
    throw std::invalid_argument(m.str());
  }
  for (std::size_t i = 0; i < n; ++i)
    if (!std::isfinite(cell_heights_m[i]))
      throw std::invalid_argument("body model: cell " + std::to_string(i) + " height is not finite");
}

SegmentPose BodyModel::segmentPose(const Segment& seg) const {
  SegmentPose pose;
  pose.name = seg.spec.name;
  pose.x_c_m = seg.x_c;
  pose.y_c_m = seg.y_c;
  pose.mass_kg = seg.mass_kg;
  pose.length_m = seg.spec.length_fraction * params_.height_m;
  pose.width_m = seg.y1 - seg.y0;
  pose.footprint_length_m = seg.x1 - seg.x0;
  pose.depth_m = seg.spec.depth_fraction * params_.height_m;
  pose.on_bed = seg.on_bed;
  return pose;
}

void BodyModel::surfaceUnder(const Segment& seg, const std::vector<double>& cell_heights_m,
                             std::vector<double>* surface) const {
  surface->resize(seg.points.size());
  for (std::size_t i = 0; i < seg.points.size(); ++i) {
    const SubPoint& sp = seg.points[i];
    (*surface)[i] = sp.weight[0] * cell_heights_m[sp.cell[0]] + sp.weight[1] * cell_heights_m[sp.cell[1]] +
                    sp.weight[2] * cell_heights_m[sp.cell[2]] + sp.weight[3] * cell_heights_m[sp.cell[3]];
  }
}

void BodyModel::restOnCells(const Segment& seg, const std::vector<double>& surface, std::vector<double>* loads,
                            SegmentPose* pose, BodyState* state) const {
  const std::size_t n = state->cell_load_n.size();
  const double k = params_.tissue_stiffness_pa_m;
  // Forces at the sub-points, shared among the cells that make the surface there.
  loads->assign(n, 0.0);
  double force = 0.0, moment = 0.0, peak = 0.0;
  for (std::size_t i = 0; i < seg.points.size(); ++i) {
    const SubPoint& sp = seg.points[i];
    const double d = surface[i] - seg.z - seg.t * sp.u - seg.s * sp.v - sp.q;
    if (d <= 0.0) continue;
    const double f = k * sp.area * d;
    force += f;
    moment += f * sp.u;
    for (int j = 0; j < 4; ++j)
      if (sp.weight[j] > 0.0) (*loads)[sp.cell[j]] += f * sp.weight[j];
    const double pressure = k * d;
    peak = std::max(peak, pressure);
    double& cell_peak = state->cell_peak_pressure_pa[sp.face_cell];
    cell_peak = std::max(cell_peak, pressure);
  }
  pose->z_m = seg.z;
  pose->roll_rad = std::atan(seg.t);
  pose->pitch_rad = std::atan(seg.s);
  pose->support_n = force;
  pose->moment_residual_nm = moment;
  pose->peak_pressure_pa = peak;
  pose->at_roll_limit = std::abs(seg.t) >= std::tan(params_.max_roll_rad) * (1.0 - 1e-12);
  for (std::size_t c = 0; c < n; ++c) {
    if ((*loads)[c] == 0.0) continue;
    pose->cell_loads_n.emplace_back(static_cast<std::uint32_t>(c), (*loads)[c]);
    state->cell_load_n[c] += (*loads)[c];
  }
}

void BodyModel::cellPressures(BodyState* state) const {
  const double area = grid_.cellAreaM2();
  for (std::size_t c = 0; c < state->cell_load_n.size(); ++c) {
    state->cell_pressure_pa[c] = state->cell_load_n[c] / area;
    state->total_load_n += state->cell_load_n[c];
  }
  // Regional peaks: point peaks of the region's segments; cell peaks over the cells they load.
  auto region = [state](std::initializer_list<int> segs, double* point_peak, double* cell_peak) {
    for (int s : segs) {
      *point_peak = std::max(*point_peak, state->segments[s].peak_pressure_pa);
      for (const auto& cl : state->segments[s].cell_loads_n)
        *cell_peak = std::max(*cell_peak, state->cell_pressure_pa[cl.first]);
    }
  };
  region({kPelvis}, &state->peak_pressure_pa.sacrum, &state->peak_cell_pressure_pa.sacrum);
  region({kRightFoot, kLeftFoot}, &state->peak_pressure_pa.heels, &state->peak_cell_pressure_pa.heels);
  region({kHeadNeck}, &state->peak_pressure_pa.occiput, &state->peak_cell_pressure_pa.occiput);
}

BodyState BodyModel::solve(const std::vector<double>& cell_heights_m) {
  checkHeights(cell_heights_m);
  const std::size_t n = cell_heights_m.size();
  BodyState state;
  state.cell_load_n.assign(n, 0.0);
  state.cell_pressure_pa.assign(n, 0.0);
  state.cell_peak_pressure_pa.assign(n, 0.0);
  std::vector<double> surface, loads;
  std::vector<std::vector<double>> surfaces;
  if (joints_) {
    surfaces.resize(segments_.size());
    for (std::size_t i = 0; i < segments_.size(); ++i)
      if (segments_[i].on_bed) surfaceUnder(segments_[i], cell_heights_m, &surfaces[i]);
    bool ok = false;
    state.iterations += solveArticulated(surfaces, &ok);
    state.converged = ok;
  }
  double trunk_roll = 0.0, trunk_mass = 0.0;
  for (Segment& seg : segments_) {
    SegmentPose pose = segmentPose(seg);
    if (!seg.on_bed) {
      // Hanging off the bed: drawn level with its parent, carried by it.
      const Segment& parent = segments_[seg.spec.parent];
      pose.z_m = parent.z;
      pose.roll_rad = std::atan(parent.t);
      state.segments.push_back(pose);
      continue;
    }
    if (joints_) {
      surface = surfaces[&seg - segments_.data()];
    } else {
      surfaceUnder(seg, cell_heights_m, &surface);
      bool ok = false;
      state.iterations += solveSegment(&seg, surface, &ok);
      state.converged = state.converged && ok;
    }
    restOnCells(seg, surface, &loads, &pose, &state);
    if (seg.spec.trunk) {
      trunk_roll += seg.mass_kg * pose.roll_rad;
      trunk_mass += seg.mass_kg;
    }
    state.segments.push_back(std::move(pose));
  }
  state.roll_rad = trunk_mass > 0.0 ? trunk_roll / trunk_mass : 0.0;
  cellPressures(&state);
  return state;
}

void BodyModel::calibrateJoints() {
  // Free segments on a flat bed (their equilibrium does not depend on its height).
  const std::vector<double> flat(static_cast<std::size_t>(grid_.cells()),
                                 0.5 * (grid_.min_height_m + grid_.max_height_m));
  std::vector<double> surface;
  std::vector<JointSegment> dofs(segments_.size());
  int n = 0;
  for (std::size_t i = 0; i < segments_.size(); ++i) {
    dofs[i].x_c = segments_[i].x_c;
    dofs[i].y_c = segments_[i].y_c;
    if (segments_[i].on_bed) dofs[i].dof = 3 * n++;
  }
  Eigen::VectorXd poses = Eigen::VectorXd::Zero(3 * n);
  for (std::size_t i = 0; i < segments_.size(); ++i) {
    Segment& seg = segments_[i];
    if (!seg.on_bed) continue;
    surfaceUnder(seg, flat, &surface);
    bool ok = false;
    solveSegment(&seg, surface, &ok);
    poses.segment<3>(dofs[i].dof) << seg.z, seg.t, 0.0;
  }
  joints_->calibrate(dofs, poses);
  reset();
}

double BodyModel::articulatedPotential(const std::vector<JointSegment>& dofs,
                                       const std::vector<std::vector<double>>& surfaces, const Eigen::VectorXd& poses,
                                       Eigen::VectorXd* gradient, Eigen::MatrixXd* hessian) const {
  // Per segment: weight at the footprint centre, m g z, and the Winkler layer's k/2 sum a d+^2
  // with d = h - (z + t u + s v + q), linear in (z, t, s): convex, as the joints' potential.
  const double k = params_.tissue_stiffness_pa_m;
  double energy = 0.0;
  if (gradient) gradient->setZero(poses.size());
  if (hessian) hessian->setZero(poses.size(), poses.size());
  for (std::size_t i = 0; i < segments_.size(); ++i) {
    const Segment& seg = segments_[i];
    const int o = dofs[i].dof;
    if (o < 0) continue;
    const double z = poses(o), t = poses(o + 1), s = poses(o + 2);
    // Sums of a d (1, u, v) and a (1, u, v)(1, u, v)^T over the points in contact.
    double e = 0.0, f = 0.0, fu = 0.0, fv = 0.0, a = 0.0, au = 0.0, av = 0.0, auu = 0.0, auv = 0.0, avv = 0.0;
    for (std::size_t p = 0; p < seg.points.size(); ++p) {
      const SubPoint& sp = seg.points[p];
      const double d = surfaces[i][p] - z - t * sp.u - s * sp.v - sp.q;
      if (d <= 0.0) continue;
      const double ad = sp.area * d;
      e += ad * d;
      f += ad;
      fu += ad * sp.u;
      fv += ad * sp.v;
      if (!hessian) continue;
      a += sp.area;
      au += sp.area * sp.u;
      av += sp.area * sp.v;
      auu += sp.area * sp.u * sp.u;
      auv += sp.area * sp.u * sp.v;
      avv += sp.area * sp.v * sp.v;
    }
    energy += seg.carried_n * z + 0.5 * k * e;
    if (!gradient) continue;
    gradient->segment<3>(o) += Eigen::Vector3d(seg.carried_n - k * f, -k * fu, -k * fv);
    if (!hessian) continue;
    Eigen::Matrix3d h;
    h << a, au, av, au, auu, auv, av, auv, avv;
    hessian->block<3, 3>(o, o) += k * h;
  }
  joints_->accumulate(dofs, poses, &energy, gradient, hessian);
  return energy;
}

int BodyModel::solveArticulated(const std::vector<std::vector<double>>& surfaces, bool* converged) {
  int iterations = 0;
  std::vector<JointSegment> dofs(segments_.size());
  int n = 0;
  for (std::size_t i = 0; i < segments_.size(); ++i) {
    Segment& seg = segments_[i];
    dofs[i].x_c = seg.x_c;
    dofs[i].y_c = seg.y_c;
    if (!seg.on_bed) continue;
    dofs[i].dof = 3 * n++;
    if (!articulated_warm_) {  // cold: start from the free segments
      bool ok = false;
      iterations += solveSegment(&seg, surfaces[i], &ok);
      seg.s = 0.0;
    }
  }
  Eigen::VectorXd x(3 * n), g, dx;
  Eigen::MatrixXd hess;
  for (std::size_t i = 0; i < segments_.size(); ++i)
    if (dofs[i].dof >= 0) x.segment<3>(dofs[i].dof) << segments_[i].z, segments_[i].t, segments_[i].s;
  const double t_max = std::tan(params_.max_roll_rad);
  // Force residuals within this fraction of the weight, moments within it times weight x 1 m.
  const double tol = 1e-9 * weightN();
  *converged = false;
  for (int it = 0; it < kMaxIterations; ++it, ++iterations) {
    const double energy = articulatedPotential(dofs, surfaces, x, &g, &hess);
    if (g.lpNorm<Eigen::Infinity>() <= tol) {
      *converged = true;
      break;
    }
    // Positive semi-definite (a segment off the cells is held by its joints only): a little
    // regularisation keeps the factorisation defined without changing the solution.
    hess.diagonal().array() += 1e-9 * hess.diagonal().maxCoeff();
    dx = -hess.ldlt().solve(g);
    const double slope = g.dot(dx);
    if (!(slope < 0.0)) dx = -g / hess.diagonal().maxCoeff();  // not a descent direction: gradient step
    double alpha = 1.0;
    Eigen::VectorXd xn;
    bool accepted = false;
    for (int ls = 0; ls < 40; ++ls, alpha *= 0.5) {
      xn = x + alpha * dx;
      for (int r = 1; r < xn.size(); r += 3) xn(r) = std::clamp(xn(r), -t_max, t_max);
      const double en = articulatedPotential(dofs, surfaces, xn, nullptr, nullptr);
      if (en <= energy + 1e-4 * alpha * g.dot(dx) + 1e-12 * std::abs(energy)) {
        accepted = true;
        break;
      }
    }
    if (!accepted) break;
    x = xn;
  }
  for (std::size_t i = 0; i < segments_.size(); ++i) {
    if (dofs[i].dof < 0) continue;
    Segment& seg = segments_[i];
    seg.z = x(dofs[i].dof);
    seg.t = x(dofs[i].dof + 1);
    seg.s = x(dofs[i].dof + 2);
    seg.warm = true;
  }
  articulated_warm_ = true;
  return iterations;
}

std::vector<ContactPoint> BodyModel::contactMap(const std::vector<double>& cell_heights_m) const {
  checkHeights(cell_heights_m);
  const double k = params_.tissue_stiffness_pa_m;
  const double x_vertex = 0.5 * grid_.lengthM() - params_.head_clearance_m;
  std::vector<ContactPoint> out;
  std::size_t total = 0;
  for (const Segment& seg : segments_) total += seg.points.size();
  out.reserve(total);
  std::vector<double> surface;
  for (std::size_t s = 0; s < segments_.size(); ++s) {
    const Segment& seg = segments_[s];
    if (!seg.on_bed) continue;
    surfaceUnder(seg, cell_heights_m, &surface);
    const double half_width = 0.5 * (seg.y1 - seg.y0);
    for (std::size_t i = 0; i < seg.points.size(); ++i) {
      const SubPoint& sp = seg.points[i];
      const double underside = seg.z + seg.t * sp.u + seg.s * sp.v + sp.q;
      const double d = surface[i] - underside;
      ContactPoint c;
      c.segment = static_cast<int>(s);
      c.from_vertex_m = x_vertex - sp.x;
      c.lateral_m = sp.u;
      c.half_width_m = half_width;
      c.area_m2 = sp.area;
      c.pressure_pa = d > 0.0 ? k * d : 0.0;
      c.skin_height_m = std::max(surface[i], underside);
      out.push_back(c);
    }
  }
  return out;
}

std::vector<int> BodyModel::rowsOf(const std::vector<int>& segment_indices) const {
  std::set<int> rows;
  const double p = grid_.pitch_m;
  for (int s : segment_indices) {
    const Segment& seg = segments_[s];
    for (int r = 0; r < grid_.rows; ++r) {
      const double xc = grid_.x(r);
      // The cell's face [xc - p/2, xc + p/2] overlaps the footprint (not just touches it).
      if (xc + 0.5 * p > seg.x0 + 1e-9 && xc - 0.5 * p < seg.x1 - 1e-9) rows.insert(r);
    }
  }
  return sortedUnique(rows);
}

std::vector<int> BodyModel::footprintRows() const {
  std::vector<int> all;
  for (int s = 0; s < kSegmentCount; ++s)
    if (segments_[s].on_bed) all.push_back(s);
  return rowsOf(all);
}

std::vector<int> BodyModel::trunkRows() const { return rowsOf({kThorax, kAbdomen, kPelvis}); }
std::vector<int> BodyModel::headRows() const { return rowsOf({kHeadNeck}); }
std::vector<int> BodyModel::pelvisRows() const { return rowsOf({kPelvis}); }

std::vector<int> BodyModel::heelRows() const {
  std::vector<int> feet;
  if (segments_[kRightFoot].on_bed) feet.push_back(kRightFoot);
  if (segments_[kLeftFoot].on_bed) feet.push_back(kLeftFoot);
  return rowsOf(feet);
}

std::vector<int> BodyModel::footprintCols() const {
  std::set<int> cols;
  const double p = grid_.pitch_m;
  for (const Segment& seg : segments_) {
    if (!seg.on_bed) continue;
    for (int c = 0; c < grid_.cols; ++c) {
      const double yc = grid_.y(c);
      if (yc + 0.5 * p > seg.y0 + 1e-9 && yc - 0.5 * p < seg.y1 - 1e-9) cols.insert(c);
    }
  }
  return sortedUnique(cols);
}

}  // namespace nursing_bed
