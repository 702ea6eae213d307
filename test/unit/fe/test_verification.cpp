// Closed-form checks of the membrane solver on coarse meshes (the fine ones run in fe_airbag).
#include <gtest/gtest.h>

#include <stdexcept>

#include "nursing_bed/core/fe/mesh.h"
#include "nursing_bed/core/fe/verification.h"
#include "nursing_bed/core/physics/units.h"

namespace nursing_bed {
namespace fe {

TEST(FeVerification, SphereThroughLimitPointWithinOnePercent) {
  VerificationCase c;
  c.resolution = 3;
  c.stretches = {1.1, 1.227, 1.4, 1.65, 1.9};  // rising, the limit point, falling, the minimum, rising
  const auto points = runVerification(c, FilmMaterial{});
  ASSERT_EQ(points.size(), c.stretches.size());
  for (const auto& p : points) {
    EXPECT_TRUE(p.converged) << p.message;
    EXPECT_LT(std::abs(p.relative_error), 0.01) << "stretch " << p.stretch;
  }
  // Past the limit point the pressure falls under volume control.
  EXPECT_GT(points[1].fe_pressure_pa, points[2].fe_pressure_pa);
}

TEST(FeVerification, TubeThroughLimitPointWithinOnePercent) {
  VerificationCase c;
  c.shape = VerificationCase::Shape::kTube;
  c.resolution = 48;
  c.stretches = {1.2, 1.46, 1.8, 2.2};
  const auto points = runVerification(c, FilmMaterial{});
  for (const auto& p : points) {
    EXPECT_TRUE(p.converged) << p.message;
    EXPECT_LT(std::abs(p.relative_error), 0.01) << "stretch " << p.stretch;
  }
  EXPECT_GT(points[1].fe_pressure_pa, points[2].fe_pressure_pa);
}

TEST(FeVerification, VolumeExactOnClosedPolyhedra) {
  // A cube of side a from the icosphere's code path is not available; use the coarse icosahedron
  // and compare eq. 11 (x n_x) with the tetrahedron sum about the origin.
  const MembraneMesh m = icosphereMesh(0.1, 1, 1e-3);
  double tets = 0.0;
  for (const auto& t : m.triangles) {
    tets += m.initial.col(t[0]).dot(m.initial.col(t[1]).cross(m.initial.col(t[2]))) / 6.0;
  }
  EXPECT_NEAR(enclosedVolume(m, m.initial), tets, 1e-15);
  EXPECT_NEAR(enclosedVolume(m, m.initial, Eigen::Vector3d(0.0, 0.0, 1.0)), tets, 1e-15);
  // Translation does not change it (closed surface).
  Eigen::Matrix3Xd shifted = m.initial.colwise() + Eigen::Vector3d(0.3, -0.2, 0.5);
  EXPECT_NEAR(enclosedVolume(m, shifted), tets, 1e-14);
}

TEST(FeVerification, BadCasesAreRefused) {
  VerificationCase c;
  c.stretches = {0.9};
  EXPECT_THROW(runVerification(c, FilmMaterial{}), std::invalid_argument);
  c.stretches = {1.2};
  c.thickness_m = -1.0;
  try {
    runVerification(c, FilmMaterial{});
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("thickness_m"), std::string::npos);
  }
  c.thickness_m = 0.5e-3;
  FilmMaterial bad;
  bad.yeoh.c10_pa = -1.0;
  EXPECT_THROW(runVerification(c, bad), std::invalid_argument);
}

}  // namespace fe
}  // namespace nursing_bed
