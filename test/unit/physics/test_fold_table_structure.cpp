// physics' FoldTableStructure (the FE cell with a fold state) and its selection from the cell YAML.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <stdexcept>

#include "nursing_bed/core/physics/cell_model.h"
#include "nursing_bed/core/physics/cell_params_io.h"
#include "nursing_bed/core/physics/fold_table_structure.h"

namespace nursing_bed {
namespace {

// One branch of a synthetic bag: F = p 0.01 (1 - h / reach), V = 0.01 h + 1e-8 p.
StructureTableData branch(double reach_m) {
  StructureTableData t;
  for (int i = 1; i <= 20; ++i) t.heights_m.push_back(0.01 * i);
  t.pressures_pa = {1e3, 4e3, 8e3, 12e3, 16e3, 20e3, 30e3};
  for (double h : t.heights_m) {
    std::vector<double> v, f;
    for (double p : t.pressures_pa) {
      v.push_back(0.01 * h + 1e-8 * p);
      f.push_back(p * 0.01 * (1.0 - h / reach_m));
    }
    t.volume_m3.push_back(v);
    t.plate_force_n.push_back(f);
  }
  return t;
}

// Folded: reach 100 mm; open: reach 150 mm. Opens above 10 kPa, folds again below 5 kPa.
FoldTableData syntheticFold() {
  FoldTableData d;
  d.description = "synthetic";
  d.folded = branch(0.10);
  d.open = branch(0.15);
  d.snap_loads_n = {0.5, 100.0};
  d.open_pa = {10e3, 10e3};
  d.close_pa = {5e3, 5e3};
  return d;
}

void writeBranch(std::ostream& f, const char* name, const StructureTableData& t) {
  auto list = [&f](const std::vector<double>& v) {
    f << '[';
    for (std::size_t i = 0; i < v.size(); ++i) f << (i ? ", " : "") << v[i];
    f << "]\n";
  };
  f << name << ":\n  heights_m: ";
  list(t.heights_m);
  f << "  pressures_pa: ";
  list(t.pressures_pa);
  for (const auto& [key, grid] : {std::pair{"volume_m3", &t.volume_m3}, std::pair{"plate_force_n", &t.plate_force_n}}) {
    f << "  " << key << ":\n";
    for (const auto& row : *grid) f << "    - ", list(row);
  }
}

std::string writeFold(const std::string& path, const FoldTableData& d) {
  std::ofstream f(path);
  f.precision(12);
  f << "description: \"" << d.description << "\"\nsnap:\n  loads_n: [" << d.snap_loads_n[0] << ", " << d.snap_loads_n[1]
    << "]\n  open_pa: [" << d.open_pa[0] << ", " << d.open_pa[1] << "]\n  close_pa: [" << d.close_pa[0] << ", "
    << d.close_pa[1] << "]\n";
  writeBranch(f, "folded", d.folded);
  writeBranch(f, "open", d.open);
  return path;
}

std::string tmpDir() {
  const std::string d = std::string(NURSING_BED_TEST_TMP_DIR) + "/fold_table";
  std::filesystem::create_directories(d);
  return d;
}

CellParams foldCell(const std::string& file) {
  CellParams params;
  params.structure_type = "fold_table";
  params.structure_table_file = file;
  return params;
}

// After holding the supply at p with the inlet open until the cell is at p (within 20 Pa, at
// most 20 s): the plate's rest, and the rest the folded (reach 100 mm) and the open (150 mm)
// branch of the synthetic bag give at the cell's own pressure.
struct Rest {
  double height_m, folded_m, open_m;
};

Rest restAt(CellModel* cell, double p, double load) {
  CellInputs in;
  in.load_n = load;
  in.supply_pressure_pa = p;
  in.inlet_opening = 1.0;
  cell->advance(1.0, in);
  for (int i = 0; i < 190 && std::abs(cell->variables().gauge_pressure_pa - p) > 20.0; ++i) cell->advance(0.1, in);
  const double lift = 1.0 - load / (0.01 * cell->variables().gauge_pressure_pa);
  return {cell->variables().height_m, 0.10 * lift, 0.15 * lift};
}

}  // namespace

TEST(FoldTableStructure, TheFoldOpensAboveItsPressureAndClosesOnlyBelowTheLowerOne) {
  const FoldTableStructure s(syntheticFold(), 2e-3, 5e-6);
  EXPECT_NEAR(s.foldRate(0.0, 7e3, 0.05), 0.0, 1e-2);  // between the thresholds both states hold
  EXPECT_NEAR(s.foldRate(1.0, 7e3, 0.05), 0.0, 1e-2);
  EXPECT_GT(s.foldRate(0.0, 11e3, 0.05), 10.0);  // past open_pa the folded bag opens
  EXPECT_GT(s.foldRate(0.4, 11e3, 0.05), 10.0);
  EXPECT_LT(s.foldRate(1.0, 4e3, 0.05), -10.0);  // below close_pa the open bag folds
  EXPECT_LT(s.foldRate(0.6, 4e3, 0.05), -10.0);
  EXPECT_LT(s.foldRate(0.3, 7e3, 0.05), 0.0);  // a partial fold falls back into the nearer state
  EXPECT_GT(s.foldRate(0.7, 7e3, 0.05), 0.0);
}

TEST(FoldTableStructure, OverAPeriodTheFoldMovesAtItsOwnRate) {
  // A dip below close_pa shorter than the fold's time (0.02 s) leaves an open fold mostly open;
  // a long one closes it where relaxedShape does; the film relaxes either way.
  const FoldTableStructure s(syntheticFold(), 2e-3, 5e-6);
  const double open[kMaxShapeDofs] = {0.4, 1.0};
  const auto relaxed = s.relaxedShape(0.05, 3e3, open);
  EXPECT_LT(relaxed[1], 0.01);
  const auto period = s.shapeAfter(0.05, 3e3, open, 0.002);
  EXPECT_GT(period[1], 0.5);
  EXPECT_LT(period[1], 1.0);
  EXPECT_NEAR(period[0], relaxed[0], 1e-9);
  EXPECT_NEAR(s.shapeAfter(0.05, 3e3, open, 1.0)[1], relaxed[1], 1e-3);
  // Between the snap pressures an open fold stays open, over any time.
  EXPECT_NEAR(s.shapeAfter(0.05, 7e3, open, 1.0)[1], 1.0, 1e-3);
}

TEST(FoldTableStructure, ARunningCellKeepsItsBranchBetweenTheSnapPressures) {
  const std::string file = writeFold(tmpDir() + "/fold.yaml", syntheticFold());
  const double load = 40.0;  // folded: h = 0.1 (1 - 4000 / p); open: h = 0.15 (1 - 4000 / p)
  CellModel cell(foldCell(file));
  cell.reset(load);
  Rest r = restAt(&cell, 8e3, load);  // below open_pa: still folded
  EXPECT_NEAR(r.height_m, r.folded_m, 1e-3);
  EXPECT_GT(r.height_m, 0.04);
  r = restAt(&cell, 12e3, load);  // snapped open
  EXPECT_NEAR(r.height_m, r.open_m, 1e-3);
  r = restAt(&cell, 8e3, load);  // back at 8 kPa it stays open
  EXPECT_NEAR(r.height_m, r.open_m, 1e-3);
  r = restAt(&cell, 6e3, load);
  EXPECT_NEAR(r.height_m, r.open_m, 1e-3);
  restAt(&cell, 2e3, load);      // below close_pa: folds (and rests flat)
  r = restAt(&cell, 8e3, load);  // folded again on the way up
  EXPECT_NEAR(r.height_m, r.folded_m, 1e-3);
}

TEST(FoldTableStructure, BadDataAreRefusedWithTheField) {
  FoldTableData d = syntheticFold();
  d.close_pa = {12e3, 12e3};
  try {
    FoldTableStructure s(d, 2e-3, 5e-6);
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("snap/close_pa"), std::string::npos) << e.what();
  }
  d = syntheticFold();
  d.open.plate_force_n.pop_back();
  try {
    FoldTableStructure s(d, 2e-3, 5e-6);
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("open: plate_force_n"), std::string::npos) << e.what();
  }
  const std::string path = tmpDir() + "/no_snap.yaml";
  std::ofstream(path) << "folded: {}\n";
  try {
    FoldTableStructure::load(path);
    FAIL();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("folded/heights_m"), std::string::npos) << e.what();
  }
}

TEST(FoldTableStructure, SelectedFromTheCellYamlWithARelativePath) {
  const std::string dir = tmpDir();
  writeFold(dir + "/cell_fold.yaml", syntheticFold());
  std::ofstream(dir + "/cell.yaml") << "structure:\n  type: fold_table\n  table_file: cell_fold.yaml\n";
  const CellParams params = loadCellParamsYaml(dir + "/cell.yaml");
  EXPECT_EQ(params.structure_type, "fold_table");
  const CellModel cell(params);
  EXPECT_NE(cell.structure().describe().find("fold table"), std::string::npos);
  std::ofstream(dir + "/cell_nofile.yaml") << "structure:\n  type: fold_table\n";
  EXPECT_THROW(loadCellParamsYaml(dir + "/cell_nofile.yaml"), std::runtime_error);
}

}  // namespace nursing_bed

namespace nursing_bed {

// The shipped FE cell with the fold (the gusseted reading): under 10.6 N at 4.87 kPa the FE bag
// rests at 84.4 mm on the way up (folded) and at 100.5 mm on the way down (still open).
TEST(FoldTableStructure, TheFe3dCellRestsOnTheFesFoldGoingUpAndComingDown) {
  const CellParams params =
      loadCellParamsYaml(std::string(NURSING_BED_SOURCE_DIR) + "/config/airbag_tpu_double_100_fe3d.yaml");
  ASSERT_EQ(params.structure_type, "fold_table");
  CellModel cell(params);
  const double load = 10.6, p = 1e3 * (1.0 + 29.0 * 2 / 15);
  cell.reset(load);
  const double up = restAt(&cell, p, load).height_m;
  for (double step : {20e3, 14e3, 8e3}) restAt(&cell, step, load);  // down in steps, as the FE went
  const double down = restAt(&cell, p, load).height_m;
  EXPECT_NEAR(cell.variables().gauge_pressure_pa, p, 20.0);
  EXPECT_NEAR(up, 0.0844, 3e-3);
  EXPECT_NEAR(down, 0.1005, 3e-3);
}

}  // namespace nursing_bed

namespace nursing_bed {

// The gas works through the volume the table gives it (A_eff = dV/dh, dV/ds the branches'
// difference), so filled slowly from flat its temperature stays near the supply's. With the FE
// plate force per pressure as A_eff the gas paid for the film's tension too and fell to 261 K
// under 15.6 N while the plate rose, 6 % of its volume (10 mm) that the observer never saw.
TEST(FoldTableStructure, TheGasWorksThroughItsOwnVolume) {
  const CellParams params =
      loadCellParamsYaml(std::string(NURSING_BED_SOURCE_DIR) + "/config/airbag_tpu_double_100_fe3d.yaml");
  CellModel cell(params);
  const CellStructure& structure = cell.structure();
  for (double h : {0.0113, 0.0521, 0.1007}) {
    for (double s : {0.0, 0.4, 1.0}) {
      const double q[2] = {0.6, s};
      const double dh = 1e-5;
      const double slope =
          (structure.evaluate(h + dh, q).volume_m3 - structure.evaluate(h - dh, q).volume_m3) / (2.0 * dh);
      const StructureEval e = structure.evaluate(h, q);
      EXPECT_NEAR(e.effective_area_m2, slope, 1e-3 * std::fabs(slope) + 1e-9) << h << " " << s;
      const double qs[2] = {0.6, s + 1e-4};
      const double dvds = (structure.evaluate(h, qs).volume_m3 - e.volume_m3) / 1e-4;
      if (s < 1.0) {
        EXPECT_NEAR(e.dvolume_dshape[1], dvds, 1e-3 * std::fabs(dvds) + 1e-12) << h << " " << s;
      }
    }
  }
  cell.reset(15.6);
  CellInputs in;
  in.load_n = 15.6;
  in.inlet_opening = 0.2;  // a slow fill: a fifth of the inlet
  double coldest = 1e9, hottest = 0.0;
  for (double t = 0.0; t < 6.0; t += 0.002) {
    cell.advance(0.002, in);
    if (t < 1.5) continue;  // the flat cell's first gas is compressed, as in a rigid vessel
    coldest = std::min(coldest, cell.variables().temperature_k);
    hottest = std::max(hottest, cell.variables().temperature_k);
  }
  EXPECT_GT(cell.variables().height_m, 0.12);  // filled through the fold's snap
  EXPECT_GT(coldest, 290.0);
  EXPECT_LT(hottest, 310.0);
}

TEST(FoldTableStructure, BelowTheTablesLowestRowAndPressureTheSlopesAreTheVolumes) {
  // The gas's work follows A_eff dh + dV/dq dq (paper eq. 14): both must be the slopes of the
  // volume the cell has, down to the dead volume and at film pressures below the table's
  // lowest (a lift-off from flat passes there), or the flat cell's first gas heats or cools.
  const CellParams params =
      loadCellParamsYaml(std::string(NURSING_BED_SOURCE_DIR) + "/config/airbag_tpu_double_100_fe3d.yaml");
  CellModel cell(params);
  const CellStructure& structure = cell.structure();
  for (double h : {0.0002, 0.0005, 0.002, 0.0113}) {
    for (double q0 : {0.02, 0.05, 0.2, 0.6}) {
      for (double s : {0.0, 1.0}) {
        const double q[2] = {q0, s};
        const StructureEval e = structure.evaluate(h, q);
        const double dh = 1e-6;
        const double slope =
            (structure.evaluate(h + dh, q).volume_m3 - structure.evaluate(h - dh, q).volume_m3) / (2.0 * dh);
        EXPECT_NEAR(e.effective_area_m2, slope, 2e-3 * std::fabs(slope) + 1e-7) << h << " " << q0 << " " << s;
        const double qq[2] = {q0 + 1e-5, s};
        const double dvdq = (structure.evaluate(h, qq).volume_m3 - e.volume_m3) / 1e-5;
        const double floor = 1e-3 * e.volume_m3 / 3.0;  // dV/dq is floored at 1e-3 V per 30 kPa
        EXPECT_NEAR(e.dvolume_dshape[0], std::max(dvdq, floor), 2e-3 * std::fabs(dvdq) + 1e-9)
            << h << " " << q0 << " " << s;
        EXPECT_GE(e.volume_m3, params.structure.dead_volume_m3 * (1.0 - 1e-12));
      }
    }
  }
}

}  // namespace nursing_bed
