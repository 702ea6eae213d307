// The loaded bag's equilibria as a force-height curve (fe_airbag's "equilibria" table).
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "nursing_bed/core/fe/equilibrium_curve.h"

namespace fe = nursing_bed::fe;

TEST(EquilibriumCurve, InterpolatesTheLoadAndVolumeBetweenTheLoadsPlates) {
  // Given in any order; 10 N rests at 80 mm, 20 N at 40 mm, 30 N at 30 mm.
  const std::vector<fe::LoadedState> curve =
      fe::equilibriumCurve({{20.0, 0.040, 2e-4}, {10.0, 0.080, 4e-4}, {30.0, 0.030, 1.5e-4}});
  ASSERT_EQ(curve.size(), 3u);
  double f = 0.0, v = 0.0;
  ASSERT_TRUE(fe::onEquilibriumCurve(curve, 0.060, &f, &v));
  EXPECT_NEAR(f, 15.0, 1e-12);
  EXPECT_NEAR(v, 3e-4, 1e-15);
  ASSERT_TRUE(fe::onEquilibriumCurve(curve, 0.030, &f, &v));
  EXPECT_NEAR(f, 30.0, 1e-12) << "its ends are on it";
  EXPECT_FALSE(fe::onEquilibriumCurve(curve, 0.081, &f, &v)) << "above the lightest load's plate";
  EXPECT_FALSE(fe::onEquilibriumCurve(curve, 0.029, &f, &v)) << "below the heaviest's";
  EXPECT_FALSE(fe::onEquilibriumCurve({curve[0]}, 0.080, &f, &v)) << "one state is no curve";
}

TEST(EquilibriumCurve, AHeavierLoadWhosePlateRestsHigherIsLeftOutAndNamed) {
  // Through a snap the 15 N plate has jumped up (90 mm) while the 10 N one has not (60 mm):
  // taken as it is, the force between 60 and 90 mm would be two-valued.
  std::vector<std::string> left_out;
  const std::vector<fe::LoadedState> curve = fe::equilibriumCurve(
      {{10.0, 0.060, 3e-4}, {15.0, 0.090, 4.5e-4}, {20.0, 0.040, 2e-4}, {25.0, 0.040, 2e-4}}, &left_out);
  ASSERT_EQ(curve.size(), 2u);
  EXPECT_EQ(curve[0].load_n, 10.0);
  EXPECT_EQ(curve[1].load_n, 20.0);
  ASSERT_EQ(left_out.size(), 2u);
  EXPECT_NE(left_out[0].find("15.0 N"), std::string::npos) << left_out[0];
  EXPECT_NE(left_out[1].find("25.0 N"), std::string::npos) << "the same height is not lower: " << left_out[1];
}
