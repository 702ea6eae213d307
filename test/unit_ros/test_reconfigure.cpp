// dynamic_reconfigure requests turned into the nodes' parameters (ros/reconfigure.h), without a
// master: a good request is taken whole, a bad one refused whole with the key named.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "nursing_bed/core/bed/posture_plans.h"
#include "nursing_bed/core/control/airbag_params_io.h"
#include "nursing_bed/ros/reconfigure.h"

namespace nb = nursing_bed;

namespace {

/// An airbag node's parameters as loadParams() gives them for cell (0, 0).
nb::AirbagNodeParams airbagParams() {
  nb::AirbagNodeParams p;
  p.row = 0;
  p.col = 0;
  return p;
}

/// Every value of the parameters, as text: equal texts, equal parameters.
std::string dump(const nb::AirbagNodeParams& p) { return nb::paramsToYaml(p.airbag, nb::airbagParamFields()); }
std::string dump(const nb::BedManagerParams& p) {
  return nb::paramsToYaml(p.bed.plans, nb::planConfigFields()) + std::to_string(p.bed.cell_timeout_s) + " " +
         std::to_string(p.bed.leak_alarm_error_m) + " " + std::to_string(p.bed.leak_alarm_s);
}

template <class Config>
dynamic_reconfigure::Config message(const Config& config) {
  dynamic_reconfigure::Config msg;
  config.__toMessage__(msg);
  return msg;
}

/// `config` with the parameter `name` set to `value` (through its message, as a request does).
template <class Config>
Config with(Config config, const std::string& name, double value) {
  dynamic_reconfigure::Config msg = message(config);
  for (auto& d : msg.doubles)
    if (d.name == name) d.value = value;
  for (auto& i : msg.ints)
    if (i.name == name) i.value = static_cast<int>(value);
  config.__fromMessage__(msg);
  return config;
}

/// Every finite end of the cfg's ranges, by parameter name: (min, max), infinite when open.
template <class Config>
std::vector<std::pair<std::string, double>> rangeEnds() {
  std::vector<std::pair<std::string, double>> ends;
  for (const Config* bound : {&Config::__getMin__(), &Config::__getMax__()}) {
    const dynamic_reconfigure::Config msg = message(*bound);
    for (const auto& d : msg.doubles)
      if (std::isfinite(d.value)) ends.emplace_back(d.name, d.value);
    for (const auto& i : msg.ints)
      if (i.value != std::numeric_limits<int>::max() && i.value != std::numeric_limits<int>::min())
        ends.emplace_back(i.name, i.value);
  }
  return ends;
}

}  // namespace

TEST(ReconfigureRanges, EndOnlyWhereValidateRefusesTheEndSoAClampedRequestIsStillRefused) {
  // dynamic_reconfigure clamps a request into the cfg range before the node sees it: an end the
  // node accepted would turn a bad value into a good one without a word.
  const auto airbag_ends = rangeEnds<nb::AirbagCellConfig>();
  EXPECT_GE(airbag_ends.size(), 8u);  // the exclusive bounds of the controller and the relief
  for (const auto& [name, end] : airbag_ends) {
    nb::AirbagNodeParams params = airbagParams();
    nb::ReconfiguredKeys changed;
    EXPECT_NE(nb::reconfigureParams(with(nb::airbagConfigFrom(params), name, end), &params, &changed), "")
        << name << " = " << end << " is accepted: leave that side of its range open";
  }
  const auto manager_ends = rangeEnds<nb::BedManagerConfig>();
  EXPECT_GE(manager_ends.size(), 5u);
  for (const auto& [name, end] : manager_ends) {
    nb::BedManagerParams params;
    nb::ReconfiguredKeys changed;
    EXPECT_NE(nb::reconfigureParams(with(nb::bedManagerConfigFrom(params), name, end), &params, &changed), "")
        << name << " = " << end << " is accepted: leave that side of its range open";
  }
}

TEST(ReconfigureKeys, AreTheYamlKeysWithTheSectionSlashWrittenAsAnUnderscore) {
  EXPECT_EQ(nb::reconfigureYamlKey("controller_height_tolerance_m"), "controller/height_tolerance_m");
  EXPECT_EQ(nb::reconfigureYamlKey("safety_relief_pressure_pa"), "safety/relief_pressure_pa");
  EXPECT_EQ(nb::reconfigureYamlKey("plans_alternating_period_s"), "plans/alternating_period_s");
  EXPECT_EQ(nb::reconfigureYamlKey("leak_alarm_s"), "leak_alarm_s");
  EXPECT_EQ(nb::reconfigureYamlKey("plans_adaptive_relief_s"), "plans/adaptive/relief_s");
  EXPECT_EQ(nb::reconfigureYamlKey("plans_adaptive_tolerance_exponent"), "plans/adaptive/tolerance/exponent");
}

TEST(ReconfigureDefaults, AreTheParameterStructsDefaults) {
  // Also checks that every cfg parameter has a key in the parameter tables (else it throws).
  EXPECT_EQ(message(nb::airbagConfigFrom(nb::AirbagNodeParams{})), message(nb::AirbagCellConfig::__getDefault__()));
  EXPECT_EQ(message(nb::bedManagerConfigFrom(nb::BedManagerParams{})), message(nb::BedManagerConfig::__getDefault__()));
}

TEST(AirbagReconfigure, AGoodConfigBecomesTheParamsAndNamesWhatChanged) {
  nb::AirbagNodeParams params = airbagParams();
  nb::AirbagCellConfig config = nb::airbagConfigFrom(params);
  config.controller_height_tolerance_m = 0.0006;
  config.controller_hold_band_m = 0.0008;
  config.controller_integral_rate_per_s = 1.5;
  config.safety_relief_pressure_pa = 34000.0;
  nb::ReconfiguredKeys changed;
  ASSERT_EQ(nb::reconfigureParams(config, &params, &changed), "");
  EXPECT_DOUBLE_EQ(params.airbag.controller.height_tolerance_m, 0.0006);
  EXPECT_DOUBLE_EQ(params.airbag.controller.hold_band_m, 0.0008);
  EXPECT_DOUBLE_EQ(params.airbag.controller.integral_rate_per_s, 1.5);
  EXPECT_DOUBLE_EQ(params.airbag.safety.relief_pressure_pa, 34000.0);
  EXPECT_DOUBLE_EQ(params.airbag.controller.approach_band_m, nb::HeightControllerParams{}.approach_band_m);
  const nb::ReconfiguredKeys expected = {{"controller/height_tolerance_m", 0.0006},
                                         {"controller/hold_band_m", 0.0008},
                                         {"controller/integral_rate_per_s", 1.5},
                                         {"safety/relief_pressure_pa", 34000.0}};
  EXPECT_EQ(changed, expected);
}

TEST(AirbagReconfigure, ANegativeGainIsRefusedNamingTheKeyAndChangesNothing) {
  nb::AirbagNodeParams params = airbagParams();
  const std::string before = dump(params);
  nb::AirbagCellConfig config = nb::airbagConfigFrom(params);
  config.controller_integral_rate_per_s = -1.0;
  config.controller_approach_band_m = 0.005;  // valid, but refused with the rest
  nb::ReconfiguredKeys changed = {{"untouched", 1.0}};
  const std::string error = nb::reconfigureParams(config, &params, &changed);
  EXPECT_NE(error.find("controller_integral_rate_per_s = -1"), std::string::npos) << error;
  EXPECT_NE(error.find("integral_rate_per_s must be >= 0"), std::string::npos) << error;
  EXPECT_EQ(dump(params), before);
  EXPECT_EQ(changed.size(), 1u);
}

TEST(AirbagReconfigure, ANegativeDeadbandIsRefused) {
  nb::AirbagNodeParams params = airbagParams();
  const std::string before = dump(params);
  nb::AirbagCellConfig config = nb::airbagConfigFrom(params);
  config.controller_height_tolerance_m = -0.0001;
  nb::ReconfiguredKeys changed;
  const std::string error = nb::reconfigureParams(config, &params, &changed);
  EXPECT_NE(error.find("controller_height_tolerance_m"), std::string::npos) << error;
  EXPECT_NE(error.find("height_tolerance_m must lie in (0, 0.01) m"), std::string::npos) << error;
  EXPECT_EQ(dump(params), before);
  EXPECT_TRUE(changed.empty());
}

TEST(AirbagReconfigure, KeysValidAloneAreRefusedWhenTheSetIsNot) {
  // The same validate() as at start-up: the controller must stop below the relief pressure.
  nb::AirbagNodeParams params = airbagParams();
  const std::string before = dump(params);
  nb::AirbagCellConfig config = nb::airbagConfigFrom(params);
  config.safety_relief_pressure_pa = 30000.0;
  nb::ReconfiguredKeys changed;
  const std::string error = nb::reconfigureParams(config, &params, &changed);
  EXPECT_NE(error.find("safety_relief_pressure_pa"), std::string::npos) << error;
  EXPECT_NE(error.find("max_pressure_pa must be below the relief pressure"), std::string::npos) << error;
  EXPECT_EQ(dump(params), before);
}

TEST(AirbagReconfigure, ARefusedRequestSendsBackTheRunningValues) {
  nb::AirbagNodeParams params = airbagParams();
  const nb::AirbagCellConfig running = nb::airbagConfigFrom(params);
  nb::AirbagCellConfig config = running;
  config.controller_hold_band_m = 0.0001;  // below the deadband
  nb::ReconfiguredKeys changed;
  EXPECT_FALSE(nb::reconfigureRequest(config, &params, &changed, "airbag_0_0"));
  EXPECT_EQ(message(config), message(running));
  EXPECT_TRUE(changed.empty());
}

TEST(AirbagReconfigure, ARequestThatChangesNothingIsNotApplied) {
  // What the server's first callback (with the loaded values) gives: nothing to apply or save.
  nb::AirbagNodeParams params = airbagParams();
  nb::AirbagCellConfig config = nb::airbagConfigFrom(params);
  nb::ReconfiguredKeys changed;
  EXPECT_FALSE(nb::reconfigureRequest(config, &params, &changed, "airbag_0_0"));
  EXPECT_TRUE(changed.empty());
  config.controller_damping_band_m = 0.02;
  EXPECT_TRUE(nb::reconfigureRequest(config, &params, &changed, "airbag_0_0"));
  EXPECT_DOUBLE_EQ(params.airbag.controller.damping_band_m, 0.02);
}

TEST(BedManagerReconfigure, AGoodConfigBecomesTheParams) {
  nb::BedManagerParams params;
  nb::BedManagerConfig config = nb::bedManagerConfigFrom(params);
  config.leak_alarm_s = 20.0;
  config.leak_alarm_error_m = 0.015;
  config.cell_timeout_s = 0.8;
  config.plans_alternating_period_s = 900.0;
  config.plans_nominal_height_m = 0.08;
  config.plans_static_head_rows = 3;
  nb::ReconfiguredKeys changed;
  ASSERT_EQ(nb::reconfigureParams(config, &params, &changed), "");
  EXPECT_DOUBLE_EQ(params.bed.leak_alarm_s, 20.0);
  EXPECT_DOUBLE_EQ(params.bed.leak_alarm_error_m, 0.015);
  EXPECT_DOUBLE_EQ(params.bed.cell_timeout_s, 0.8);
  EXPECT_DOUBLE_EQ(params.bed.plans.alternating_period_s, 900.0);
  EXPECT_DOUBLE_EQ(params.bed.plans.nominal_height_m, 0.08);
  EXPECT_EQ(params.bed.plans.static_head_rows, 3);
  EXPECT_EQ(changed.count("plans/alternating_period_s"), 1u);
  EXPECT_EQ(changed.count("leak_alarm_s"), 1u);
  EXPECT_EQ(changed.size(), 6u);
}

TEST(BedManagerReconfigure, TheAdaptivePlansKeysBecomeTheParamsOrAreRefusedNamingTheKey) {
  nb::BedManagerParams params;
  nb::BedManagerConfig config = nb::bedManagerConfigFrom(params);
  config.plans_adaptive_heel_height_m = 0.04;
  config.plans_adaptive_tolerance_exponent = 2.0;
  nb::ReconfiguredKeys changed;
  ASSERT_EQ(nb::reconfigureParams(config, &params, &changed), "");
  EXPECT_DOUBLE_EQ(params.bed.plans.adaptive.heel_height_m, 0.04);
  EXPECT_DOUBLE_EQ(params.bed.plans.adaptive.tolerance.exponent, 2.0);
  EXPECT_EQ(changed.count("plans/adaptive/heel_height_m"), 1u);
  EXPECT_EQ(changed.count("plans/adaptive/tolerance/exponent"), 1u);

  const std::string before = dump(params);
  config = nb::bedManagerConfigFrom(params);
  config.plans_adaptive_relief_s = 2000.0;  // longer than the 1800 s budget
  const std::string error = nb::reconfigureParams(config, &params, &changed);
  EXPECT_NE(error.find("plans_adaptive_relief_s = 2000"), std::string::npos) << error;
  EXPECT_NE(error.find("relief_budget_s must exceed relief_s"), std::string::npos) << error;
  EXPECT_EQ(dump(params), before);
}

TEST(BedManagerReconfigure, AZeroLeakAlarmTimeIsRefusedNamingTheKeyAndChangesNothing) {
  nb::BedManagerParams params;
  const std::string before = dump(params);
  nb::BedManagerConfig config = nb::bedManagerConfigFrom(params);
  config.leak_alarm_s = 0.0;
  nb::ReconfiguredKeys changed;
  const std::string error = nb::reconfigureParams(config, &params, &changed);
  EXPECT_NE(error.find("leak_alarm_s = 0"), std::string::npos) << error;
  EXPECT_NE(error.find("~leak_alarm_error_m and ~leak_alarm_s must be positive"), std::string::npos) << error;
  EXPECT_EQ(dump(params), before);
  EXPECT_TRUE(changed.empty());
}

TEST(BedManagerReconfigure, PlanDefaultsThatContradictEachOtherAreRefused) {
  nb::BedManagerParams params;
  const std::string before = dump(params);
  nb::BedManagerConfig config = nb::bedManagerConfigFrom(params);
  config.plans_alternating_transition_s = 200.0;  // a 600 s cycle needs 6 transitions
  nb::ReconfiguredKeys changed;
  const std::string error = nb::reconfigureParams(config, &params, &changed);
  EXPECT_NE(error.find("plans_alternating_transition_s = 200"), std::string::npos) << error;
  EXPECT_NE(error.find("alternating_period_s too short for the transition"), std::string::npos) << error;
  EXPECT_EQ(dump(params), before);
  config = nb::bedManagerConfigFrom(params);
  config.plans_nominal_height_m = 0.2;  // above plans/max_height_m
  EXPECT_FALSE(nb::reconfigureRequest(config, &params, &changed, "bed_manager"));
  EXPECT_DOUBLE_EQ(config.plans_nominal_height_m, params.bed.plans.nominal_height_m);
  EXPECT_EQ(dump(params), before);
}
