#include "nursing_bed/core/fe/airbag_geometry.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace nursing_bed {
namespace fe {

AirbagGeometry AirbagGeometry::flatPillows() { return AirbagGeometry{}; }

AirbagGeometry AirbagGeometry::gusseted() {
  AirbagGeometry g;
  g.gusset_height_m = 0.079;
  return g;
}

Status AirbagGeometry::validate() const {
  std::ostringstream err;
  if (!(face_side_m > 0.0 && face_side_m < 10.0)) err << "face_side_m must be in (0, 10) m, got " << face_side_m;
  else if (chambers < 1 || chambers > 8) err << "chambers must be 1..8, got " << chambers;
  else if (!(film_thickness_m > 0.0 && film_thickness_m < 0.05 * face_side_m))
    err << "film_thickness_m must be positive and below face_side_m/20 (a membrane), got " << film_thickness_m;
  else if (!(gusset_height_m >= 0.0 && gusset_height_m <= face_side_m))
    err << "gusset_height_m must be in [0, face_side_m], got " << gusset_height_m;
  else if (elements_per_side < 4 || elements_per_side > 200 || elements_per_side % 2 != 0)
    err << "elements_per_side must be even and in 4..200, got " << elements_per_side;
  else if (chambers > 1 &&
           !(connection_side_m >= 2.0 * elementSize() && connection_side_m <= face_side_m - 4.0 * elementSize()))
    err << "connection_side_m must span at least 2 elements and leave 2 free on each side, got " << connection_side_m;
  return Status::fromMessage(err.str());
}

std::string AirbagGeometry::describe() const {
  std::ostringstream s;
  s << chambers << " chamber(s) " << face_side_m * 1e3 << " mm, "
    << (gusset_height_m > 0.0 ? "gussets " + std::to_string(gusset_height_m * 1e3) + " mm" : std::string("no gussets"))
    << ", connection " << connection_side_m * 1e3 << " mm, film " << film_thickness_m * 1e3 << " mm, "
    << elements_per_side << " elements per side";
  return s.str();
}

namespace {

// Cells of the connection patch: the centred square of whole cells nearest connection_side_m.
int patchCells(const AirbagGeometry& g) {
  const int n = g.elements_per_side;
  int cells = static_cast<int>(std::lround(g.connection_side_m / g.elementSize()));
  if ((n - cells) % 2 != 0) ++cells;
  return cells;
}

struct FaceSpec {
  double base_z = 0.0;         // height of the rim
  double direction = 1;        // +1: bulges up from the rim (a top face), -1: down
  bool ramp_to_patch = false;  // rises to the patch (faces at a connection)
  bool skip_patch = false;     // the neighbour chamber's face owns the patch
  bool owns_patch = false;
  bool top = false;  // normal points up
};

MembraneMesh facePanel(const AirbagGeometry& g, const FaceSpec& f) {
  const int n = g.elements_per_side;
  const double a = g.face_side_m, h = g.elementSize(), gap = g.layerGap();
  const int pc = patchCells(g);
  const int lo = (n - pc) / 2, hi = lo + pc;
  auto ramp = [&](int i, int j) {
    const int edge = std::min({i, j, n - i, n - j});
    if (g.gusset_height_m > 0.0 && !f.ramp_to_patch) return 0.0;
    if (f.ramp_to_patch) return std::min(1.0, static_cast<double>(edge) / lo);
    return std::min(1.0, edge / 2.0);
  };
  auto place = [&](int i, int j) { return Eigen::Vector3d(i * h, j * h, f.base_z + f.direction * gap * ramp(i, j)); };
  auto flat = [&](int i, int j) { return Eigen::Vector3d(i * h, j * h, 0.0); };
  MembraneMesh m = gridPanel(n, n, place, flat, g.film_thickness_m, f.top ? kTopFace : kBottomFace, !f.top);
  (void)a;
  if (!(f.skip_patch || f.owns_patch)) return m;
  MembraneMesh out = m;
  out.triangles.clear(), out.rest.clear(), out.thickness_m.clear(), out.pressurised.clear(), out.part.clear();
  for (std::size_t t = 0; t < m.triangles.size(); ++t) {
    const Eigen::Vector3d c = (m.rest[t][0] + m.rest[t][1] + m.rest[t][2]) / 3.0;
    const bool inside = c.x() > lo * h && c.x() < hi * h && c.y() > lo * h && c.y() < hi * h;
    if (inside && f.skip_patch) continue;
    out.triangles.push_back(m.triangles[t]);
    out.rest.push_back(m.rest[t]);
    out.thickness_m.push_back(inside ? 2.0 * g.film_thickness_m : g.film_thickness_m);
    out.pressurised.push_back(inside ? 0 : 1);
    out.part.push_back(inside ? kConnection : m.part[t]);
  }
  return out;
}

// Four side gussets of one chamber between z0 and z0 + height, normals outward.
void addGussets(const AirbagGeometry& g, double z0, MembraneMesh* bag, double tol) {
  const int n = g.elements_per_side;
  const int m = std::max(2, static_cast<int>(std::lround(g.gusset_height_m / g.elementSize())));
  const double a = g.face_side_m, dz = g.gusset_height_m / m, h = g.elementSize();
  for (int side = 0; side < 4; ++side) {
    auto place = [&](int i, int j) {
      const double s = i * h, z = z0 + j * dz;
      switch (side) {
        case 0: return Eigen::Vector3d(s, 0.0, z);
        case 1: return Eigen::Vector3d(a, s, z);
        case 2: return Eigen::Vector3d(a - s, a, z);
        default: return Eigen::Vector3d(0.0, a - s, z);
      }
    };
    auto flat = [&](int i, int j) { return Eigen::Vector3d(i * h, j * dz, 0.0); };
    appendMesh(bag, gridPanel(n, m, place, flat, g.film_thickness_m, kGusset, false), tol);
  }
}

// x, y held at the nodes within one element of the face centre, on the lowest and highest face.
void pinCentres(const AirbagGeometry& g, MembraneMesh* bag) {
  const double c = 0.5 * g.face_side_m, reach = 1.01 * g.elementSize();
  const double z_lo = bag->initial.row(2).minCoeff(), z_hi = bag->initial.row(2).maxCoeff();
  for (int j = 0; j < bag->nodeCount(); ++j) {
    const Eigen::Vector3d x = bag->initial.col(j);
    const bool centre = std::abs(x.x() - c) <= reach && std::abs(x.y() - c) <= reach;
    const bool outer = std::abs(x.z() - z_lo) < 1e-9 || std::abs(x.z() - z_hi) < 1e-9;
    if (centre && outer) bag->fixed[j][0] = bag->fixed[j][1] = true;
  }
}

}  // namespace

MembraneMesh buildAirbagMesh(const AirbagGeometry& g) {
  const Status valid = g.validate();
  if (!valid) throw std::invalid_argument("AirbagGeometry: " + valid.message());
  const double gap = g.layerGap(), tol = 0.05 * gap;
  const bool gussets = g.gusset_height_m > 0.0;
  MembraneMesh bag;
  bag.initial.resize(3, 0);
  double z = gussets ? 0.0 : gap;  // rim (pillow) or bottom face (box) of the current chamber
  for (int k = 0; k < g.chambers; ++k) {
    const bool below = k > 0, above = k + 1 < g.chambers;
    FaceSpec bottom{z, -1.0, below, below, false, false};
    if (gussets) bottom.base_z = z + (below ? gap : 0.0);
    const double top_z = gussets ? bottom.base_z + g.gusset_height_m : z;
    FaceSpec top{top_z, 1.0, above, false, above, true};
    appendMesh(&bag, facePanel(g, bottom), tol);
    if (gussets) addGussets(g, bottom.base_z, &bag, tol);
    appendMesh(&bag, facePanel(g, top), tol);
    z = gussets ? top_z + gap : z + 2.0 * gap;
  }
  if (g.pin_centres) pinCentres(g, &bag);
  return bag;
}

double initialTop(const MembraneMesh& mesh) { return mesh.initial.row(2).maxCoeff(); }

}  // namespace fe
}  // namespace nursing_bed
