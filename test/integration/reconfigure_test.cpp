// dynamic_reconfigure on a running bed (ros/reconfigure.h): a cell's and the bed manager's
// ~set_parameters. A valid change takes effect (answered, saved under its YAML key, and seen in
// the behaviour); an invalid one is refused whole and the old values stay.
#include <dynamic_reconfigure/Reconfigure.h>

#include <cmath>
#include <limits>
#include <map>
#include <sstream>
#include <string>

#include "bed_fixture.h"

namespace nursing_bed {
namespace test {

class ReconfigureFixture : public PlanFixture {
 protected:
  using Values = std::map<std::string, double>;

  /// Calls `ns`/set_parameters with `doubles`; returns every value the server answers with
  /// (its configuration after the request). Empty `doubles`: the current configuration.
  Values reconfigure(const std::string& ns, const Values& doubles) {
    dynamic_reconfigure::Reconfigure srv;
    for (const auto& [name, value] : doubles) {
      dynamic_reconfigure::DoubleParameter d;
      d.name = name;
      d.value = value;
      srv.request.config.doubles.push_back(d);
    }
    EXPECT_TRUE(ros::service::waitForService(ns + "/set_parameters", ros::Duration(10.0)));
    EXPECT_TRUE(ros::service::call(ns + "/set_parameters", srv));
    Values out;
    for (const auto& d : srv.response.config.doubles) out[d.name] = d.value;
    for (const auto& i : srv.response.config.ints) out[i.name] = i.value;
    return out;
  }

  /// A number on the parameter server (NaN when not set).
  double param(const std::string& key) const {
    double value = std::numeric_limits<double>::quiet_NaN();
    nh_.getParam(key, value);
    return value;
  }

  /// The cell id of airbag_<row>_<col>, from its states.
  uint32_t cellId(uint32_t row, uint32_t col) const {
    for (const auto& [id, s] : states_)
      if (s.row == row && s.col == col) return id;
    ADD_FAILURE() << "no state from airbag_" << row << "_" << col;
    return 0;
  }

  bool overpressure(uint32_t id) const { return (states_.at(id).faults & AirbagState::FAULT_OVERPRESSURE) != 0; }
};

TEST_F(ReconfigureFixture, ACellTakesAValidChangeAndActsOnIt) {
  const Values answer =
      reconfigure("/airbag_0_0", {{"controller_height_tolerance_m", 0.0006}, {"controller_hold_band_m", 0.0008}});
  EXPECT_DOUBLE_EQ(answer.at("controller_height_tolerance_m"), 0.0006);
  EXPECT_DOUBLE_EQ(answer.at("controller_hold_band_m"), 0.0008);
  // Saved where loadParams() reads it, so a restarted node keeps it.
  EXPECT_DOUBLE_EQ(param("/airbag_0_0/controller/height_tolerance_m"), 0.0006);
  EXPECT_DOUBLE_EQ(param("/airbag_0_0/controller/hold_band_m"), 0.0008);

  // The cell acts on a new threshold: a relief pressure below what its load needs at 50 mm.
  const uint32_t id = cellId(0, 0);
  ASSERT_TRUE(callCell("/airbag_0_0", id, 0.05).success);
  ASSERT_TRUE(settle({{id, 0.05}}, 2e-3, 0.5, 20.0)) << "the cell did not reach 50 mm";
  ASSERT_FALSE(overpressure(id));
  const Values low =
      reconfigure("/airbag_0_0", {{"controller_max_pressure_pa", 500.0}, {"safety_relief_pressure_pa", 1000.0}});
  EXPECT_DOUBLE_EQ(low.at("safety_relief_pressure_pa"), 1000.0);
  EXPECT_TRUE(waitFor([&] { return overpressure(id); }, 5.0)) << "the new relief pressure was not applied";
  reconfigure("/airbag_0_0", {{"controller_max_pressure_pa", 32000.0}, {"safety_relief_pressure_pa", 35000.0}});
  EXPECT_TRUE(waitFor([&] { return !overpressure(id); }, 5.0)) << "the relief pressure was not restored";
}

TEST_F(ReconfigureFixture, ACellRefusesAnInvalidChangeAndKeepsItsValues) {
  const Values before = reconfigure("/airbag_0_1", {});
  ASSERT_EQ(before.count("controller_hold_band_m"), 1u);
  // Below the deadband; a negative deadband (clamped to 0 by the server, still invalid); a
  // relief pressure under the controller's limit; and valid changes refused with a bad one.
  const Values requests[] = {{{"controller_hold_band_m", 0.0001}},
                             {{"controller_height_tolerance_m", -0.001}},
                             {{"safety_relief_pressure_pa", 30000.0}},
                             {{"controller_approach_band_m", 0.005}, {"controller_integral_limit_m", -1.0}}};
  for (const Values& request : requests) {
    const Values answer = reconfigure("/airbag_0_1", request);
    EXPECT_EQ(answer, before) << "refused: " << request.begin()->first;
  }
  EXPECT_DOUBLE_EQ(param("/airbag_0_1/controller_hold_band_m"), before.at("controller_hold_band_m"));
  EXPECT_DOUBLE_EQ(param("/airbag_0_1/controller_approach_band_m"), before.at("controller_approach_band_m"));
  EXPECT_TRUE(std::isnan(param("/airbag_0_1/controller/approach_band_m"))) << "a refused value was saved";
}

TEST_F(ReconfigureFixture, TheBedManagerTakesNewAlarmsAndPlanDefaults) {
  const Values answer = reconfigure("/bed_manager", {{"leak_alarm_s", 20.0}, {"plans_nominal_height_m", 0.08}});
  EXPECT_DOUBLE_EQ(answer.at("leak_alarm_s"), 20.0);
  EXPECT_DOUBLE_EQ(answer.at("plans_nominal_height_m"), 0.08);
  EXPECT_DOUBLE_EQ(param("/bed_manager/leak_alarm_s"), 20.0);
  EXPECT_DOUBLE_EQ(param("/bed_manager/plans/nominal_height_m"), 0.08);
  // A plan started now takes the new default.
  const SetPosture::Response res = posture("flat");
  EXPECT_TRUE(res.success) << res.message;
  EXPECT_NE(res.message.find("height_m=0.08"), std::string::npos) << res.message;
  EXPECT_TRUE(waitFor([this] { return bed_.plan == "flat" && bed_.parameters == "height_m=0.08"; }, 5.0))
      << bed_.plan << " " << bed_.parameters;
}

TEST_F(ReconfigureFixture, TheBedManagerRefusesInvalidValuesAndKeepsItsOwn) {
  const Values before = reconfigure("/bed_manager", {});
  ASSERT_EQ(before.count("leak_alarm_s"), 1u);
  // A leak alarm time <= 0 (clamped to 0 by the server, still invalid) and a transition too
  // long for the alternating cycle.
  EXPECT_EQ(reconfigure("/bed_manager", {{"leak_alarm_s", -1.0}}), before);
  EXPECT_EQ(reconfigure("/bed_manager", {{"plans_alternating_transition_s", 200.0}}), before);
  EXPECT_DOUBLE_EQ(param("/bed_manager/leak_alarm_s"), before.at("leak_alarm_s"));
  EXPECT_DOUBLE_EQ(param("/bed_manager/plans/alternating_transition_s"), 5.0);
  const SetPosture::Response res = posture("flat");
  EXPECT_TRUE(res.success) << res.message;
  std::ostringstream height;
  height << "height_m=" << before.at("plans_nominal_height_m");
  EXPECT_NE(res.message.find(height.str()), std::string::npos) << res.message;
}

}  // namespace test
}  // namespace nursing_bed
