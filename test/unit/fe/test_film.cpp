// The film element: Yeoh plane stress, relaxed energy (no compression), consistent forces.
#include <gtest/gtest.h>

#include <stdexcept>

#include "nursing_bed/core/fe/film.h"
#include "nursing_bed/core/fe/membrane_model.h"

namespace nursing_bed {
namespace fe {
namespace {

const Eigen::Vector3d kX0(0, 0, 0), kX1(0.01, 0, 0), kX2(0, 0.01, 0);

TriangleResponse stretched(double lx, double ly) {
  const TriangleReference ref = triangleReference(kX0, kX1, kX2, 1e-3);
  return triangleResponse(FilmMaterial{}, ref, Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(0.01 * lx, 0, 0),
                          Eigen::Vector3d(0, 0.01 * ly, 0));
}

}  // namespace

TEST(FeFilm, UniaxialTensionMatchesTheYeohUniaxialStress) {
  // Width at the natural (wrinkle-free) contraction l^-1/2: a uniaxial state (paper eq. 8-10).
  const double l = 1.5;
  const TriangleResponse r = stretched(l, 1.0 / std::sqrt(l));
  const FilmMaterial m;
  // Constant strain triangle with legs 0.01 m: the film pulls node 0 along +x with
  // A0 / 0.01 * (nominal stress * t0) = 0.005 m * P_xx.
  const double expected = 0.005 * m.yeoh.uniaxialNominalStress(l) * 1e-3;
  EXPECT_NEAR(r.force[0].x(), expected, 1e-9 * expected);
  EXPECT_NEAR(r.force[0].y(), 0.0, 1e-9 * expected);
}

TEST(FeFilm, CompressionCarriesNoStress) {
  EXPECT_EQ(stretched(0.9, 0.8).state, FilmState::kSlack);
  EXPECT_DOUBLE_EQ(stretched(0.9, 0.8).force[1].norm(), 0.0);
  const TriangleResponse w = stretched(1.3, 0.7);  // tension along x, compressed across: wrinkles
  EXPECT_EQ(w.state, FilmState::kWrinkled);
  EXPECT_NEAR(w.force[2].y(), 0.0, 1e-12);  // nothing across the wrinkles
  EXPECT_EQ(stretched(1.2, 1.1).state, FilmState::kTaut);
}

TEST(FeFilm, ForcesAreTheEnergyGradient) {
  const TriangleReference ref = triangleReference(kX0, kX1, kX2, 1e-3);
  const FilmMaterial m;
  for (const Eigen::Vector3d& x2 : {Eigen::Vector3d(0.002, 0.013, 0.004), Eigen::Vector3d(0.0, 0.007, 0.0)}) {
    const Eigen::Vector3d x1(0.014, 0.001, -0.002);
    const TriangleResponse r = triangleResponse(m, ref, kX0, x1, x2);
    for (int c = 0; c < 3; ++c) {
      Eigen::Vector3d d = Eigen::Vector3d::Zero();
      d[c] = 1e-8;
      const double de =
          triangleResponse(m, ref, kX0, x1 + d, x2).energy_j - triangleResponse(m, ref, kX0, x1 - d, x2).energy_j;
      EXPECT_NEAR(-de / 2e-8, r.force[1][c], 1e-5 * (1.0 + r.force[1].norm()));
    }
  }
}

TEST(FeFilm, BadMaterialAndOptionsAreRefusedByName) {
  FilmMaterial m;
  m.density_kg_m3 = 0.0;
  EXPECT_NE(m.validate().message().find("density_kg_m3"), std::string::npos);
  MembraneOptions o;
  o.cfl = 2.0;
  EXPECT_NE(o.validate().message().find("cfl"), std::string::npos);
  o = MembraneOptions{};
  o.self_contact_radius_m = -1.0;
  EXPECT_NE(o.validate().message().find("self_contact_radius_m"), std::string::npos);
}

}  // namespace fe
}  // namespace nursing_bed
