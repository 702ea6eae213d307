// physics' TabulatedStructure (the FE-derived cell) and its selection from the cell YAML.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <stdexcept>

#include "nursing_bed/core/fe/fe_output.h"
#include "nursing_bed/core/physics/cell_model.h"
#include "nursing_bed/core/physics/cell_params_io.h"
#include "nursing_bed/core/physics/tabulated_structure.h"

namespace nursing_bed {
namespace {

// A synthetic bag: A_eff(h) = 0.01 (1 - h / 0.2) m^2 whatever the pressure, V = 0.01 h + 1e-8 p.
fe::StructureTable syntheticTable() {
  fe::StructureTable t;
  t.description = "synthetic";
  for (int i = 1; i <= 10; ++i) t.heights_m.push_back(0.015 * i);
  t.pressures_pa = {1e3, 5e3, 10e3, 20e3, 30e3};
  for (double h : t.heights_m) {
    std::vector<double> v, f;
    for (double p : t.pressures_pa) {
      v.push_back(0.01 * h + 1e-8 * p);
      f.push_back(p * 0.01 * (1.0 - h / 0.2));
    }
    t.volume_m3.push_back(v);
    t.plate_force_n.push_back(f);
  }
  return t;
}

std::string tmpDir() {
  const std::string d = std::string(NURSING_BED_TEST_TMP_DIR) + "/tabulated";
  std::filesystem::create_directories(d);
  return d;
}

}  // namespace

TEST(TabulatedStructure, EquilibriumIsWhereThePlateForceCarriesTheLoad) {
  const std::string path = tmpDir() + "/table.yaml";
  fe::writeStructureTable(path, syntheticTable());
  const TabulatedStructure s(TabulatedStructure::load(path));
  // p 0.01 (1 - h/0.2) = L  ->  h = 0.2 (1 - L / (0.01 p)).
  for (double p : {4e3, 5e3, 8e3}) {
    const StructureEquilibrium eq = s.equilibriumAtPressure(p, 30.0);
    ASSERT_TRUE(eq.converged) << p;
    EXPECT_NEAR(eq.height_m, 0.2 * (1.0 - 30.0 / (0.01 * p)), 1e-4) << p;
    EXPECT_NEAR(eq.shape[0] * 1e4, p, 1e-3 * p);  // the film relaxed to the gas pressure
  }
  const double q = 1.2;
  EXPECT_NEAR(s.evaluate(0.05, &q).volume_m3, 0.01 * 0.05 + 1e-8 * 12e3, 1e-12);
}

TEST(TabulatedStructure, BelowItsLowestHeightTheVolumeFollowsTheRowsSlopeDownToTheDeadVolume) {
  // The lowest row's plate force is a folded stack's contact (F/q far above the face's area):
  // extended along it, V would fall to nothing above the bed. Along dV/dh it reaches the dead
  // volume only at the bed.
  fe::StructureTable t = syntheticTable();  // V = 0.01 h + 1e-8 p, lowest row at 15 mm
  for (double& f : t.plate_force_n[0]) f *= 5.0;
  const TabulatedStructure s(TabulatedStructure::load([&] {
                               const std::string path = tmpDir() + "/contact.yaml";
                               fe::writeStructureTable(path, t);
                               return path;
                             }()),
                             2e-3, 4e-6);
  const double q = 0.1;  // 1 kPa
  EXPECT_NEAR(s.evaluate(0.010, &q).volume_m3, 0.01 * 0.010 + 1e-5, 1e-12);
  EXPECT_NEAR(s.evaluate(0.0, &q).volume_m3, 1e-5, 1e-12) << "the row's slope carried to the bed";
  // Pressed into the bed, deep below the folds' depth: the flat volume less the folds' gas.
  const double folds = nursing_bed::PillowParams{}.fold_fraction * 4e-6;
  EXPECT_NEAR(s.evaluate(-0.01, &q).volume_m3, 1e-5 - folds, 1e-12) << "pressed into the bed";
  EXPECT_LT(s.evaluate(-0.01, &q).effective_area_m2, 1e-12) << "no volume left to push the plate with";
  // A steeper slope than the flat volume allows stops at the dead volume.
  for (auto& row : t.volume_m3)
    for (double& v : row) v -= 1e-5;
  const std::string steep = tmpDir() + "/steep.yaml";
  fe::writeStructureTable(steep, t);
  EXPECT_NEAR(TabulatedStructure(TabulatedStructure::load(steep), 2e-3, 4e-6).evaluate(0.0, &q).volume_m3, 4e-6, 1e-15);
  EXPECT_THROW(TabulatedStructure(TabulatedStructure::load(steep), 2e-3, 0.0), std::invalid_argument);
}

TEST(TabulatedStructure, BadTablesAreRefusedWithTheField) {
  const std::string path = tmpDir() + "/bad.yaml";
  auto refused = [&](fe::StructureTable t, const std::string& field) {
    fe::writeStructureTable(path, t);
    try {
      TabulatedStructure::load(path);
      ADD_FAILURE() << field;
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
    }
  };
  fe::StructureTable t = syntheticTable();
  t.heights_m[3] = t.heights_m[2];
  refused(t, "heights_m");
  t = syntheticTable();
  t.volume_m3[2][1] = -1.0;
  refused(t, "volume_m3");
  t = syntheticTable();
  t.plate_force_n.pop_back();
  refused(t, "plate_force_n");
  std::ofstream(path) << "heights_m: [0.1, 0.2]\n";
  try {
    TabulatedStructure::load(path);
    ADD_FAILURE();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("pressures_pa"), std::string::npos) << e.what();
  }
  EXPECT_THROW(TabulatedStructure::load(tmpDir() + "/missing.yaml"), std::runtime_error);
}

TEST(TabulatedStructure, SelectedFromTheCellYamlWithARelativePath) {
  const std::string dir = tmpDir();
  fe::writeStructureTable(dir + "/cell_table.yaml", syntheticTable());
  std::ofstream(dir + "/cell.yaml") << "structure:\n  type: table\n  table_file: cell_table.yaml\n";
  const CellParams params = loadCellParamsYaml(dir + "/cell.yaml");
  EXPECT_EQ(params.structure_type, "table");
  const CellModel cell(params);
  EXPECT_NE(cell.structure().describe().find("FE table"), std::string::npos);
  // Bad selections are named.
  std::ofstream(dir + "/cell_bad.yaml") << "structure:\n  type: balloon\n";
  try {
    loadCellParamsYaml(dir + "/cell_bad.yaml");
    FAIL();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("structure_type"), std::string::npos);
  }
  std::ofstream(dir + "/cell_nofile.yaml") << "structure:\n  type: table\n";
  EXPECT_THROW(loadCellParamsYaml(dir + "/cell_nofile.yaml"), std::runtime_error);
}

}  // namespace nursing_bed

namespace nursing_bed {

// The shipped FE cell: its YAML loads, and a cell inflated on it settles where its own
// quasi-static h(p) says (the same table, two solvers: the dynamic cell and the equilibrium).
TEST(TabulatedStructure, ShippedFeCellRunsAndSettlesOnItsCharacteristic) {
  const CellParams params =
      loadCellParamsYaml(std::string(NURSING_BED_SOURCE_DIR) + "/config/airbag_tpu_double_100_fe.yaml");
  ASSERT_EQ(params.structure_type, "table");
  CellModel cell(params);
  CellInputs in;
  in.inlet_opening = 1.0;
  in.load_n = 10.6;
  cell.reset(in.load_n);
  cell.advance(8.0, in);
  const double p = cell.variables().gauge_pressure_pa, h = cell.variables().height_m;
  EXPECT_GT(h, 0.05);
  EXPECT_NEAR(p, params.supply_pressure_pa, 0.05 * params.supply_pressure_pa);
  const StructureEquilibrium eq = cell.structure().equilibriumAtPressure(p, in.load_n);
  ASSERT_TRUE(eq.converged);
  EXPECT_NEAR(h, eq.height_m, 2e-3);
}

TEST(TabulatedStructure, AFlatCellUnderAHeavyLoadStartsAtAmbientPressure) {
  // The plate pressed into the bed squeezes the bed, not the flat bag: extrapolating the table's
  // volume below h = 0 crushed the gas (206 kPa at 20.6 N, 218 MPa at 40 N; the simulated
  // hardware then reset the cell every period).
  const CellParams params =
      loadCellParamsYaml(std::string(NURSING_BED_SOURCE_DIR) + "/config/airbag_tpu_double_100_fe.yaml");
  for (double load : {0.6, 20.6, 40.0}) {
    CellModel cell(params);
    cell.reset(load);
    EXPECT_LT(cell.variables().height_m, 0.0) << load << " N";  // on the bed's contact spring
    EXPECT_NEAR(cell.variables().gauge_pressure_pa, 0.0, 1.0) << load << " N";
    CellInputs in;
    in.load_n = load;
    in.inlet_opening = 1.0;
    cell.advance(8.0, in);
    EXPECT_GT(cell.variables().height_m, 0.03) << load << " N";
  }
}

TEST(TabulatedStructure, NoEquilibriumIsTakenFromBeyondTheTablesPressures) {
  const CellParams params =
      loadCellParamsYaml(std::string(NURSING_BED_SOURCE_DIR) + "/config/airbag_tpu_double_100_fe.yaml");
  const CellModel cell(params);
  const auto& table = dynamic_cast<const TabulatedStructure&>(cell.structure()).table();
  const double p_max = table.pressures_pa.back();
  // Under 10.6 N the highest pressure holds the plate somewhere below the table's top; above
  // that height the force would be extrapolated past the FE's pressures.
  const StructureEquilibrium top = cell.structure().equilibriumAtPressure(p_max, 10.6);
  ASSERT_TRUE(top.converged);
  EXPECT_LT(top.height_m, table.heights_m.back());
  EXPECT_FALSE(cell.structure().equilibriumAtHeight(top.height_m + 5e-3, 10.6).converged);
  EXPECT_TRUE(cell.structure().equilibriumAtHeight(top.height_m - 5e-3, 10.6).converged);
}

}  // namespace nursing_bed
