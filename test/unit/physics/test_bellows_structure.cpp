// The bellows structure: a spring-loaded plate over a chamber of fixed cross-section. Its statics
// are closed-form (h = (p A - L) / k, V = V0 + C p - C L / A), so the equilibrium functions and the
// cell model's transient are checked against them.
#include <gtest/gtest.h>

#include <cmath>
#include <utility>
#include <vector>

#include "nursing_bed/core/physics/bellows_structure.h"
#include "nursing_bed/core/physics/cell_model.h"
#include "nursing_bed/core/physics/cell_params_io.h"

namespace nb = nursing_bed;

namespace {

nb::BellowsParams lung() {
  nb::BellowsParams b;
  b.area_m2 = 0.015;
  b.compliance_m3_pa = 1.0197e-7;  // 10 mL/cmH2O
  b.dead_volume_m3 = 0.8e-3;
  b.stroke_m = 0.08;
  return b;
}

}  // namespace

TEST(BellowsStructure, VolumeGrowsWithHeightAndTheSpringPullsThePlateDown) {
  const nb::BellowsParams b = lung();
  const nb::BellowsStructure s(b);
  const double q = 0.0;
  const nb::StructureEval e = s.evaluate(0.02, &q);
  EXPECT_DOUBLE_EQ(e.volume_m3, 0.8e-3 + 0.015 * 0.02);
  EXPECT_DOUBLE_EQ(e.effective_area_m2, 0.015);
  EXPECT_NEAR(e.plate_force_n, -b.area_m2 * b.area_m2 / b.compliance_m3_pa * 0.02, 1e-9);
  EXPECT_NEAR(b.springRate(), 0.015 * 0.015 / 1.0197e-7, 1e-6);
  EXPECT_TRUE(s.withinLimits(0.08, &q));
  EXPECT_FALSE(s.withinLimits(0.081, &q));
}

TEST(BellowsStructure, UnloadedEquilibriumIsTheCompliance) {
  const nb::BellowsParams b = lung();
  const nb::BellowsStructure s(b);
  for (const double p : {490.0, 1471.0, 2942.0}) {
    const nb::StructureEquilibrium eq = s.equilibriumAtPressure(p, 0.0);
    ASSERT_TRUE(eq.converged) << p;
    EXPECT_NEAR(eq.height_m, p * b.area_m2 / b.springRate(), 1e-9) << p;
    EXPECT_NEAR(eq.eval.volume_m3 - b.dead_volume_m3, b.compliance_m3_pa * p, 1e-12) << p;
  }
}

TEST(BellowsStructure, LoadedEquilibriaAtPressureAndAtHeightAgree) {
  const nb::BellowsParams b = lung();
  const nb::BellowsStructure s(b);
  const double load = 5.0, k = b.springRate();
  const nb::StructureEquilibrium at_p = s.equilibriumAtPressure(2000.0, load);
  ASSERT_TRUE(at_p.converged);
  EXPECT_NEAR(at_p.height_m, (2000.0 * b.area_m2 - load) / k, 1e-9);
  const nb::StructureEquilibrium at_h = s.equilibriumAtHeight(0.03, load);
  ASSERT_TRUE(at_h.converged);
  EXPECT_NEAR(at_h.gauge_pressure_pa, (k * 0.03 + load) / b.area_m2, 1e-6);
  // A pressure too low to lift the load leaves the plate down; one past the stroke is refused.
  EXPECT_DOUBLE_EQ(s.equilibriumAtPressure(load / b.area_m2 * 0.9, load).height_m, 0.0);
  EXPECT_FALSE(s.equilibriumAtPressure((k * 0.09 + load) / b.area_m2, load).converged);
  EXPECT_FALSE(s.equilibriumAtHeight(0.09, load).converged);
}

TEST(BellowsStructure, SelectedByTheParameterFile) {
  const nb::CellParams p = nb::parseCellParamsYaml(
      "structure: {type: bellows}\nbellows: {area_m2: 0.02, compliance_m3_pa: 2.0e-7, dead_volume_m3: 1.0e-3, "
      "stroke_m: 0.05}\n",
      "lung.yaml");
  EXPECT_EQ(p.structure_type, "bellows");
  EXPECT_DOUBLE_EQ(p.bellows.area_m2, 0.02);
  const auto s = nb::makeCellStructure(p);
  EXPECT_NE(s->describe().find("bellows"), std::string::npos);
  EXPECT_DOUBLE_EQ(s->heightLimit(nullptr), 0.05);
  try {
    nb::parseCellParamsYaml("structure: {type: bellows}\nbellows: {compliance_m3_pa: -1}\n", "bad.yaml");
    FAIL() << "a negative compliance was accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("bellows compliance_m3_pa"), std::string::npos) << e.what();
  }
}

TEST(BellowsCellModel, SettlesToTheSpringEquilibriumAfterAnInflow) {
  nb::CellParams params;
  params.structure_type = "bellows";
  params.bellows = lung();
  params.plate_mass_kg = 0.1;
  params.plate_damping_n_s_m = 100.0;
  params.leak_area_m2 = 0.0;
  nb::CellModel model(params);
  const double load = 2.0;
  model.reset(load);
  nb::CellInputs in;
  in.load_n = load;
  in.prescribed_inflow_kg_s = 0.5e-3 * 1.204;  // 0.5 L/s for 1 s
  model.advance(1.0, in);
  in.prescribed_inflow_kg_s = 0.0;
  model.advance(2.0, in);
  const nb::CellVariables& v = model.variables();
  const double k = params.bellows.springRate();
  EXPECT_NEAR(v.velocity_m_s, 0.0, 1e-5);
  // At rest the gas carries the load and the spring: h = (p A - L) / k.
  EXPECT_NEAR(v.height_m, (v.gauge_pressure_pa * params.bellows.area_m2 - load) / k, 1e-5);
  // About the 0.5 L let in, less what the gas's compression keeps in the dead volume.
  const double volume_in = v.structure.volume_m3 - params.bellows.dead_volume_m3;
  EXPECT_GT(volume_in, 0.40e-3);
  EXPECT_LT(volume_in, 0.50e-3);
  // From an equilibrium the model stays put.
  model.resetToEquilibrium(0.03, load);
  model.advance(1.0, in);
  EXPECT_NEAR(model.variables().height_m, 0.03, 1e-6);
}

TEST(BellowsStructure, ShippedLungFilesCarryTheirCompliance) {
  // Compliance [mL/cmH2O] and the highest PIP the recordings use with it [cmH2O].
  for (const auto& [c_ml_cmh2o, pip_cmh2o] : std::vector<std::pair<int, double>>{{10, 35}, {20, 35}, {50, 25}}) {
    const std::string file =
        std::string(NURSING_BED_SOURCE_DIR) + "/config/lung_quicklung_c" + std::to_string(c_ml_cmh2o) + ".yaml";
    const nb::CellParams p = nb::loadCellParamsYaml(file);
    EXPECT_EQ(p.structure_type, "bellows") << file;
    EXPECT_NEAR(p.bellows.compliance_m3_pa, c_ml_cmh2o * 1e-6 / 98.0665, 1e-4 * p.bellows.compliance_m3_pa) << file;
    // Filled to that PIP, the plate stays within its stroke.
    const nb::StructureEquilibrium eq = nb::makeCellStructure(p)->equilibriumAtPressure(pip_cmh2o * 98.0665, 0.0);
    EXPECT_TRUE(eq.converged) << file;
  }
}
