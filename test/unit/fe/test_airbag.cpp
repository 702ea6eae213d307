// The FE airbag on a coarse mesh: geometry, a loaded quasi-static state, failure reporting.
#include <gtest/gtest.h>

#include <functional>
#include <map>
#include <stdexcept>

#include "nursing_bed/core/fe/airbag_fe.h"

namespace nursing_bed {
namespace fe {
namespace {

AirbagFeOptions coarse() {
  AirbagFeOptions o;
  o.geometry.elements_per_side = 8;
  o.geometry.connection_side_m = 0.025;
  o.membrane.threads = 1;
  return o;
}

}  // namespace

TEST(FeAirbag, FlatPillowsAreClosedAndStartNearlyFlat) {
  const AirbagGeometry g = coarse().geometry;
  const MembraneMesh m = buildAirbagMesh(g);
  EXPECT_TRUE(m.validate().ok()) << m.validate().message();
  // Two chambers of 2 x 8 x 8 x 2 triangles, the connection patch counted once.
  int patch = 0;
  for (std::size_t i = 0; i < m.triangles.size(); ++i) patch += m.part[i] == kConnection;
  EXPECT_GT(patch, 0);
  EXPECT_EQ(m.triangleCount(), 4 * 128 - patch);
  // Closed: every edge of the pressurised surface plus the patch is shared by two triangles.
  std::map<std::pair<int, int>, int> edges;
  for (const auto& t : m.triangles) {
    for (int k = 0; k < 3; ++k) ++edges[std::minmax(t[k], t[(k + 1) % 3])];
  }
  for (const auto& [e, count] : edges) EXPECT_GE(count, 2) << e.first << "-" << e.second;
  EXPECT_LT(initialTop(m), 4.1 * g.layerGap());
  EXPECT_GT(enclosedVolume(m, m.initial), 0.0);
}

TEST(FeAirbag, GussetedChambersStartAsErectedBoxes) {
  AirbagGeometry g = coarse().geometry;
  g.gusset_height_m = 0.04;
  const MembraneMesh m = buildAirbagMesh(g);
  EXPECT_TRUE(m.validate().ok()) << m.validate().message();
  // Box volume a^2 g per chamber, plus at most the a^2 x 2 gap slab between the chambers.
  const double v = enclosedVolume(m, m.initial), boxes = 2 * 0.1 * 0.1 * 0.04;
  EXPECT_GT(v, boxes);
  EXPECT_LT(v, boxes + 0.1 * 0.1 * 2 * g.layerGap());
}

TEST(FeAirbag, LoadedPlateRisesWithPressure) {
  AirbagFe bag(coarse());
  const QuasiStaticPoint low = bag.solveLoaded(5e3, 10.6);
  const QuasiStaticPoint high = bag.solveLoaded(20e3, 10.6);
  ASSERT_TRUE(low.converged) << low.message;
  ASSERT_TRUE(high.converged) << high.message;
  EXPECT_NEAR(high.plate_force_n, 10.6, 0.05);
  EXPECT_GT(high.height_m, low.height_m);
  EXPECT_GT(high.height_m, 0.05);
  EXPECT_LT(high.height_m, 0.15);
}

TEST(FeAirbag, NonConvergenceIsReportedNotHidden) {
  AirbagFeOptions o = coarse();
  o.relax.max_iterations = 200;
  o.relax.min_iterations = 10;
  AirbagFe bag(o);
  const QuasiStaticPoint p = bag.solveLoaded(20e3, 10.6);
  EXPECT_FALSE(p.converged);
  EXPECT_NE(p.message.find("not converged"), std::string::npos);
}

TEST(FeAirbag, BadGeometryIsRefusedByName) {
  auto refused = [](AirbagGeometry g, const std::string& field) {
    try {
      buildAirbagMesh(g);
      ADD_FAILURE() << field << " accepted";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
    }
  };
  const std::vector<std::pair<std::string, std::function<void(AirbagGeometry&)>>> cases = {
      {"face_side_m", [](AirbagGeometry& g) { g.face_side_m = -0.1; }},
      {"film_thickness_m", [](AirbagGeometry& g) { g.film_thickness_m = 0.02; }},
      {"connection_side_m", [](AirbagGeometry& g) { g.connection_side_m = 0.099; }},
      {"elements_per_side", [](AirbagGeometry& g) { g.elements_per_side = 7; }},
      {"chambers", [](AirbagGeometry& g) { g.chambers = 0; }},
      {"gusset_height_m", [](AirbagGeometry& g) { g.gusset_height_m = 0.5; }},
  };
  for (const auto& [field, spoil] : cases) {
    AirbagGeometry g = coarse().geometry;
    spoil(g);
    refused(g, field);
  }
  AirbagFeOptions o = coarse();
  o.material.yeoh.c10_pa = 0.0;
  EXPECT_THROW(AirbagFe{o}, std::invalid_argument);
}

TEST(FeAirbag, TransientInflatesAndConservesTheInjectedMass) {
  AirbagFe bag(coarse());
  TransientSetup s;
  TimeSeries inflow({0.0, 0.1, 0.2}, {0.0, 2e-3, 0.0});
  s.prescribed_inflow = &inflow;
  s.duration_s = 0.2;
  const TransientResult r = runTransient(&bag, s);
  ASSERT_TRUE(r.ok) << r.message;
  EXPECT_NEAR(r.samples.back().mass_kg - r.samples.front().mass_kg, inflow.integral(), 0.01 * inflow.integral());
  EXPECT_GT(r.samples.back().height_m, r.samples.front().height_m + 0.01);
  EXPECT_GT(r.samples.back().gauge_pressure_pa, 0.0);
  TransientSetup bad = s;
  bad.duration_s = -1.0;
  EXPECT_THROW(runTransient(&bag, bad), std::invalid_argument);
}

}  // namespace fe
}  // namespace nursing_bed
