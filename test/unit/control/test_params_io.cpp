// Cell parameter files: the shipped YAML loads, and bad files are refused by name.
#include <gtest/gtest.h>

#include <limits>
#include <regex>

#include "nursing_bed/core/control/airbag_params_io.h"
#include "nursing_bed/core/physics/cell_params_io.h"

namespace nb = nursing_bed;

namespace {

const std::string kShippedConfig = std::string(NURSING_BED_SOURCE_DIR) + "/config/airbag_tpu_double_100.yaml";

TEST(CellParamsIo, ShippedConfigEqualsTheBuiltInDefaults) {
  const nb::CellParams loaded = nb::loadCellParamsYaml(kShippedConfig);
  const nb::CellParams defaults;
  for (const auto& f : nb::cellParamFields())
    EXPECT_NEAR(f.get(loaded), f.get(defaults), 1e-7 * std::abs(f.get(defaults)) + 1e-12) << f.key;
}

TEST(CellParamsIo, EveryFieldRoundTripsThroughYaml) {
  nb::CellParams p;
  p.structure.film_thickness_m = 0.42e-3;
  p.supply_pressure_pa = 23456.0;
  p.structure.chambers = 3;
  const nb::CellParams back = nb::parseCellParamsYaml(nb::cellParamsToYaml(p), "roundtrip");
  for (const auto& f : nb::cellParamFields())
    EXPECT_NEAR(f.get(back), f.get(p), 1e-9 * std::abs(f.get(p)) + 1e-15) << f.key;
}

TEST(CellParamsIo, WrittenNumbersAreNumbersToYaml11Readers) {
  // rosparam reads with PyYAML (YAML 1.1): a float needs a '.', "5e-06" is a string there, and
  // sim.launch refused a calibrated file for it. Its resolver's patterns for int and float:
  const std::regex yaml11_int(R"([-+]?(0|[1-9][0-9_]*))");
  const std::regex yaml11_float(
      R"([-+]?([0-9][0-9_]*)?\.[0-9.]*([eE][-+][0-9]+)?|[-+]?\.(inf|Inf|INF)|\.(nan|NaN|NAN))");
  for (double v : {5e-6, 1.5e-5, -2e-8, 1e21, 0.079, 30000.0, 0.0, -1.0, std::numeric_limits<double>::infinity(),
                   std::numeric_limits<double>::quiet_NaN()}) {
    const std::string text = nb::formatParamValue(v);
    EXPECT_TRUE(std::regex_match(text, yaml11_int) || std::regex_match(text, yaml11_float))
        << v << " written as " << text;
  }
  const nb::CellParams back = nb::parseCellParamsYaml(nb::cellParamsToYaml(nb::CellParams{}), "written");
  EXPECT_DOUBLE_EQ(back.structure.dead_volume_m3, nb::CellParams{}.structure.dead_volume_m3);
}

void expectError(const std::string& yaml, const std::string& fragment) {
  try {
    nb::parseCellParamsYaml(yaml, "test.yaml");
    FAIL() << "accepted: " << yaml;
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("test.yaml"), std::string::npos) << e.what();
  }
}

TEST(CellParamsIo, BadFilesAreRefusedWithTheProblemNamed) {
  expectError("valves:\n  inlet_aera_m2: 1e-5\n", "unknown parameter 'valves/inlet_aera_m2'");
  expectError("valves:\n  inlet_area_m2: large\n", "'valves/inlet_area_m2' must be a number");
  expectError("structure:\n  chambers: 2.5\n", "'structure/chambers' must be a whole number");
  expectError("structure:\n  film_thickness_m: -0.001\n", "film_thickness_m must be a positive");
  expectError("valves: [1, 2]\n", "'valves' must be a number or a map");
  expectError("valves:\n  inlet_area_m2: [1\n", "YAML syntax error");
  expectError("- a\n- b\n", "expected a map");
  EXPECT_THROW(nb::loadCellParamsYaml("/nonexistent/cell.yaml"), std::runtime_error);
}

TEST(CellParamsIo, AbsentKeysKeepTheirDefaults) {
  const nb::CellParams p = nb::parseCellParamsYaml("supply:\n  pressure_pa: 25000\n", "partial");
  EXPECT_EQ(p.supply_pressure_pa, 25000.0);
  EXPECT_EQ(p.inlet_area_m2, nb::CellParams{}.inlet_area_m2);
  EXPECT_EQ(nb::parseCellParamsYaml("", "empty").supply_pressure_pa, nb::CellParams{}.supply_pressure_pa);
}

}  // namespace

namespace {

TEST(AirbagParamsIo, ShippedControllerConfigEqualsTheBuiltInDefaults) {
  const std::string path = std::string(NURSING_BED_SOURCE_DIR) + "/config/airbag_controller.yaml";
  const nb::AirbagCellParams loaded = nb::airbagParamsFrom(nb::flattenYamlFile(path), path);
  const nb::AirbagCellParams defaults;
  for (const auto& f : nb::airbagParamFields())
    EXPECT_NEAR(f.get(loaded), f.get(defaults), 1e-9 * std::abs(f.get(defaults)) + 1e-12) << f.key;
}

TEST(AirbagParamsIo, NestedCellKeysAndErrors) {
  const nb::AirbagCellParams p = nb::airbagParamsFrom(
      nb::flattenYamlText("cell:\n  valves:\n    inlet_area_m2: 2e-5\ncontroller:\n  max_height_m: 0.12\n", "t"), "t");
  EXPECT_EQ(p.cell.inlet_area_m2, 2e-5);
  EXPECT_EQ(p.controller.max_height_m, 0.12);
  auto expect_error = [](const std::string& yaml, const std::string& fragment) {
    try {
      nb::airbagParamsFrom(nb::flattenYamlText(yaml, "node.yaml"), "node.yaml");
      FAIL() << yaml;
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
    }
  };
  expect_error("controller:\n  max_hieght_m: 0.1\n", "unknown parameter 'controller/max_hieght_m'");
  expect_error("safety:\n  relief_pressure_pa: 20000\n", "relief");  // below the controller's limit
  expect_error("sensors:\n  noise_seed: 1.5\n", "whole number");
  expect_error("controller:\n  period_s: fast\n", "must be a number, got 'fast'");
}

TEST(AirbagParamsIo, StructureSelectionFromTheParameterServerResolvesAgainstConfig) {
  const nb::AirbagCellParams p = nb::airbagParamsFrom(
      nb::flattenYamlText("cell:\n  structure:\n    type: table\n    table_file: ../data/fe/t.yaml\n", "t"), "t");
  EXPECT_EQ(p.cell.structure_type, "table");
  EXPECT_EQ(p.cell.structure_table_file, std::string(NURSING_BED_SOURCE_DIR) + "/config/../data/fe/t.yaml");
  const nb::AirbagCellParams abs = nb::airbagParamsFrom(
      nb::flattenYamlText("cell:\n  structure:\n    type: table\n    table_file: /abs/t.yaml\n", "t"), "t");
  EXPECT_EQ(abs.cell.structure_table_file, "/abs/t.yaml");
  try {
    nb::airbagParamsFrom(nb::flattenYamlText("cell:\n  structure:\n    type: balloon\n", "node.yaml"), "node.yaml");
    FAIL() << "an unknown structure type was accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(
                  "structure_type must be 'pillow', 'table', 'fold_table' or 'bellows', got 'balloon'"),
              std::string::npos)
        << e.what();
  }
}

}  // namespace
