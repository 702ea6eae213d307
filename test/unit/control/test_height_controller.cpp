// Height controller and the airbag cell's safety layer, on the plant model (no ROS).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "nursing_bed/core/control/airbag_cell.h"
#include "nursing_bed/core/physics/basic_effects.h"
#include "nursing_bed/core/physics/cell_params_io.h"

namespace nb = nursing_bed;

namespace {

struct StepResult {
  double settle_s;     // last time outside +-1 mm of the target
  double overshoot_m;  // largest excursion beyond the target in the direction of travel
  double final_m;
};

// Runs the airbag cell from rest at `from` to `to` under `load`, for `duration` s.
StepResult step(nb::AirbagCell& cell, double load, double from, double to, double duration = 3.0) {
  cell.resetToHeight(from, load);
  EXPECT_EQ(cell.requestHeight(to, 0.0), "");
  StepResult r{0.0, 0.0, 0.0};
  const double dir = to > from ? 1.0 : -1.0;
  for (double t = 0.005; t <= duration + 1e-9; t += 0.005) {
    cell.advanceTo(t);
    const double h = cell.variables().height_m;
    if (std::fabs(h - to) > 1e-3) r.settle_s = t;
    r.overshoot_m = std::max(r.overshoot_m, dir * (h - to));
  }
  r.final_m = cell.variables().height_m;
  return r;
}

TEST(HeightController, StepFrom20To100mmUnder15NIsNearTheFlowLimit) {
  // Target: settles within +-1 mm in at most 1.5x the flow-limited minimum time,
  // overshoot <= 2 mm (the benchmark reports the figures).
  nb::AirbagCell cell{nb::AirbagCellParams{}};
  const double t_min = nb::flowLimitedMinimumTime(cell.params().cell, 15.6, 0.02, 0.10);
  ASSERT_GT(t_min, 0.3);
  const StepResult r = step(cell, 15.6, 0.02, 0.10);
  EXPECT_LE(r.settle_s, 1.5 * t_min) << "t_min " << t_min;
  EXPECT_LE(r.overshoot_m, 0.002);
  EXPECT_NEAR(r.final_m, 0.10, 5e-4);
}

// The FE fold-table cell (doc/cell_geometry.md): its p(h) steepens several-fold within the
// move and its plate is soft near the fold, so a move gauged in rest height stopped short and
// restarted (three moves, 6.8 x T_min); gauged in the gas's invariant it is one move.
TEST(HeightController, OnTheFoldTableCellAStepIsOneMove) {
  nb::AirbagCellParams params;
  params.cell = nb::loadCellParamsYaml(std::string(NURSING_BED_SOURCE_DIR) + "/config/airbag_tpu_double_100_fe3d.yaml");
  nb::AirbagCell cell{params};
  const double t_min = nb::flowLimitedMinimumTime(params.cell, 15.6, 0.02, 0.10);
  cell.resetToHeight(0.02, 15.6);
  ASSERT_EQ(cell.requestHeight(0.10, 0.0), "");
  int moves = 0;
  nb::MovePhase last = nb::MovePhase::kNone;
  double settle = 0.0;
  for (double t = 0.005; t <= 3.0 + 1e-9; t += 0.005) {
    cell.advanceTo(t);
    const nb::MovePhase phase = cell.controller().movePhase();
    moves += last == nb::MovePhase::kNone && phase != nb::MovePhase::kNone;
    last = phase;
    if (std::fabs(cell.variables().height_m - 0.10) > 1e-3) settle = t;
  }
  EXPECT_EQ(moves, 1);
  EXPECT_LE(settle, 3.0 * t_min) << "t_min " << t_min;
  EXPECT_NEAR(cell.variables().height_m, 0.10, 1e-3);
}

// The same step as the default cell's target (#41: <= 1.5 x T_min, <= 2 mm). The plate is soft
// near the fold (T/2 = 0.13 s at the target, 23 ms at 20 mm): the open-loop tail, timed on the
// target's period, left a 4.5 mm swing; the landing aims the force at every period.
TEST(HeightController, OnTheFoldTableCellTheStepLandsNearTheFlowLimit) {
  nb::AirbagCellParams params;
  params.cell = nb::loadCellParamsYaml(std::string(NURSING_BED_SOURCE_DIR) + "/config/airbag_tpu_double_100_fe3d.yaml");
  nb::AirbagCell cell{params};
  const double t_min = nb::flowLimitedMinimumTime(params.cell, 15.6, 0.02, 0.10);
  const StepResult r = step(cell, 15.6, 0.02, 0.10);
  EXPECT_LE(r.settle_s, 1.5 * t_min) << "t_min " << t_min;
  EXPECT_LE(r.overshoot_m, 0.002);
  EXPECT_NEAR(r.final_m, 0.10, 1e-3);
}

// A slow ramp through the fold (1 mm/s in 0.1 mm steps, as the bed's rate-limited turns move a
// cell) on the bed's 30 kPa supply: under 10-22 N the rising fold snaps open near 105-110 mm.
// Braked or corrected before it landed, the snap stopped half way, the fold closed again and
// the plate fell 5-7 mm below its setpoint and overshot 4-5 mm after; let run, it stays the
// closed cell's own 2-3 mm jump.
TEST(HeightController, OnTheFoldTableCellASlowRampPassesTheSnapOnce) {
  nb::AirbagCellParams params;
  params.cell = nb::loadCellParamsYaml(std::string(NURSING_BED_SOURCE_DIR) + "/config/airbag_tpu_double_100_fe3d.yaml");
  params.cell.supply_pressure_pa = 30000.0;
  for (double load : {10.6, 14.0, 18.0, 22.0}) {
    SCOPED_TRACE(testing::Message() << load << " N");
    nb::AirbagCell cell{params};
    cell.resetToHeight(0.09, load);
    ASSERT_EQ(cell.requestHeight(0.09, 0.0), "");
    double t = 0.0;
    for (; t < 3.0; t += 0.02) cell.advanceTo(t);
    double below = 0.0, above = 0.0, setpoint = 0.09;
    for (int k = 0; k < 1650; ++k, t += 0.02) {  // 30 s of ramp, 3 s on the last setpoint
      if (k % 5 == 0) {
        setpoint = std::min(0.12, 0.09 + 1e-3 * k * 0.02);
        ASSERT_EQ(cell.requestHeight(setpoint, t), "");
      }
      cell.advanceTo(t);
      below = std::min(below, cell.variables().height_m - setpoint);
      above = std::max(above, cell.variables().height_m - setpoint);
    }
    EXPECT_GT(below, -3.5e-3);
    EXPECT_LT(above, 3.5e-3);
    EXPECT_NEAR(cell.variables().height_m, 0.12, 1e-3);
  }
}

// Under 13.3 N the closed fold has no rest between about 104.5 and 107.5 mm. A cell resting
// just below that gap and asked 1.2 mm up snaps open: taking gas back while the fold opens
// closes it again and drops the plate 3-5 mm below where it stood, then overshoots; a fold that
// stalls half open is tipped on along its snap. The cell passes the gap once and lands on its
// open side.
TEST(HeightController, ATargetInTheFoldsGapSnapsItOpenOnce) {
  nb::AirbagCellParams params;
  params.cell = nb::loadCellParamsYaml(std::string(NURSING_BED_SOURCE_DIR) + "/config/airbag_tpu_double_100_fe3d.yaml");
  params.cell.supply_pressure_pa = 30000.0;
  nb::AirbagCell cell{params};
  cell.resetToHeight(0.1043, 13.3);
  ASSERT_EQ(cell.requestHeight(0.1043, 0.0), "");
  double t = 0.0;
  for (; t < 3.0; t += 0.02) cell.advanceTo(t);
  const double start = cell.variables().height_m, target = 0.10552;
  ASSERT_LT(start, target - 1e-3);
  ASSERT_EQ(cell.requestHeight(target, t), "");
  double lowest = start, highest = start;
  for (int k = 0; k < 150; ++k, t += 0.02) {
    cell.advanceTo(t);
    lowest = std::min(lowest, cell.variables().height_m);
    highest = std::max(highest, cell.variables().height_m);
  }
  EXPECT_GT(lowest, start - 0.5e-3);
  EXPECT_LT(highest, target + 2.5e-3);
  EXPECT_NEAR(cell.variables().height_m, target, 0.5e-3);
  EXPECT_GT(cell.variables().shape[1], 0.9);  // on the fold's open side
}

// Height readings with 0.5 mm of noise: the landing's speed is tracked on the force balance
// (PlateTracker), so the noise does not reach the valves as chatter or a swing.
TEST(HeightController, ALandingOnNoisyHeightReadingsStaysNearTheFlowLimit) {
  for (std::uint32_t seed : {1u, 2u, 3u}) {
    nb::AirbagCellParams params;
    params.height_noise_m = 5e-4;
    params.pressure_noise_pa = 20.0;
    params.noise_seed = seed;
    nb::AirbagCell cell{params};
    const double t_min = nb::flowLimitedMinimumTime(params.cell, 15.6, 0.02, 0.10);
    cell.resetToHeight(0.02, 15.6);
    ASSERT_EQ(cell.requestHeight(0.10, 0.0), "");
    double settle = 0.0, overshoot = 0.0, opening_s = 0.0;
    for (double t = 0.005; t <= 3.0 + 1e-9; t += 0.005) {
      cell.advanceTo(t);
      const double h = cell.variables().height_m;
      if (std::fabs(h - 0.10) > 1.5e-3) settle = t;  // the noise's 3 sd
      overshoot = std::max(overshoot, h - 0.10);
      if (t > 1.0) opening_s += 0.005 * (cell.valves().inlet + cell.valves().vent);
    }
    SCOPED_TRACE(testing::Message() << "seed " << seed);
    EXPECT_LE(settle, 1.5 * t_min) << "t_min " << t_min;
    EXPECT_LE(overshoot, 0.002);
    EXPECT_LT(opening_s, 0.5) << "valve seconds spent on the readings' noise after the move";
  }
}

TEST(HeightController, StepResponsesFromSeveralLoadsAndStartHeights) {
  nb::AirbagCell cell{nb::AirbagCellParams{}};
  const double moves[][2] = {{0.0, 0.08}, {0.02, 0.10}, {0.05, 0.13}, {0.13, 0.05}, {0.10, 0.11}, {0.10, 0.09}};
  for (double load : {5.6, 15.6, 25.6}) {
    for (const auto& m : moves) {
      const StepResult r = step(cell, load, m[0], m[1], 4.0);
      const double t_min = nb::flowLimitedMinimumTime(cell.params().cell, load, m[0], m[1]);
      SCOPED_TRACE(testing::Message() << "load " << load << " from " << m[0] << " to " << m[1]);
      EXPECT_NEAR(r.final_m, m[1], 1e-3);
      EXPECT_LE(r.overshoot_m, 0.003);
      EXPECT_LE(r.settle_s, std::max(2.5 * t_min, 0.35));
    }
  }
}

TEST(HeightController, ReachesTheTargetWithNoisySensorsAndAnUnmodelledEffect) {
  nb::AirbagCellParams params;
  params.pressure_noise_pa = 20.0;
  params.height_noise_m = 1e-4;
  // The controller's characteristic is adiabatic; the plant exchanges heat with its film.
  nb::AirbagCell cell(params, {std::make_shared<nb::HeatTransferEffect>(10.0)});
  const StepResult r = step(cell, 15.6, 0.03, 0.12, 8.0);
  EXPECT_NEAR(r.final_m, 0.12, 1e-3);
  EXPECT_LE(r.overshoot_m, 0.004);
}

TEST(HeightController, EstimatesTheLoadItCarries) {
  nb::AirbagCell cell{nb::AirbagCellParams{}};
  cell.resetToHeight(0.08, 20.6);
  // Seeded wrongly: the estimate must find the true load while the plate rests.
  cell.requestHeight(0.08, 0.0);
  const_cast<nb::HeightController&>(cell.controller()).setLoadEstimate(10.0);
  cell.advanceTo(3.0);
  EXPECT_NEAR(cell.loadEstimate(), 20.6, 0.3);
  EXPECT_NEAR(cell.variables().height_m, 0.08, 1e-3);
}

TEST(HeightController, AMoveRunsItsPhasesInOrderAndEndsOnTarget) {
  nb::AirbagCell cell{nb::AirbagCellParams{}};
  cell.resetToHeight(0.02, 15.6);
  cell.requestHeight(0.10, 0.0);
  std::vector<nb::MovePhase> phases;
  for (double t = 0.005; t <= 3.0 + 1e-9; t += 0.005) {
    cell.advanceTo(t);
    const nb::MovePhase phase = cell.controller().movePhase();
    if (phases.empty() || phases.back() != phase) phases.push_back(phase);
  }
  // The loop (5 ms, no dead time) is faster than this plate: the move ends in the feedback
  // landing, which takes over full flow as soon as it asks for less (here right after the lead).
  ASSERT_GE(phases.size(), 3u);
  EXPECT_EQ(phases.front(), nb::MovePhase::kLead);
  EXPECT_EQ(phases[phases.size() - 2], nb::MovePhase::kLanding);
  EXPECT_EQ(phases.back(), nb::MovePhase::kNone);
  for (std::size_t i = 1; i + 1 < phases.size(); ++i) EXPECT_GT(phases[i], phases[i - 1]) << "phase " << i;
  EXPECT_NEAR(cell.variables().height_m, 0.10, 1e-3);
}

// The landing's poles: twice the plate's own frequency, within a quarter radian of the loop's
// delay; none where the valves act so late that the loop is slower than the plate.
TEST(HeightController, TheLandingIsAsFastAsTheLoopAllowsAndOnlyWhereItOutrunsThePlate) {
  nb::AirbagCell cell{nb::AirbagCellParams{}};
  nb::HeightController controller(nb::HeightControllerParams{}, nb::CellCharacteristic::shared(cell.params().cell));
  controller.setTarget(0.10);
  controller.setLoadEstimate(15.6);
  const double own = M_PI / controller.halfPeriod(), dt = 0.005;
  ASSERT_LT(own, 0.25 / dt);
  EXPECT_DOUBLE_EQ(controller.landingRate(dt), std::min(2.0 * own, 0.25 / dt));
  controller.setDeadTime(0.01);
  EXPECT_DOUBLE_EQ(controller.landingRate(dt), own <= 0.25 / 0.015 ? std::min(2.0 * own, 0.25 / 0.015) : 0.0);
  controller.setDeadTime(0.05);
  EXPECT_EQ(controller.landingRate(dt), 0.0) << "a loop 55 ms late lands with the open-loop tail";
}

TEST(HeightController, NewParametersAreTakenOnlyWhenValid) {
  nb::AirbagCell cell{nb::AirbagCellParams{}};
  nb::HeightController controller(nb::HeightControllerParams{}, nb::CellCharacteristic::shared(cell.params().cell));
  controller.setTarget(0.08);
  nb::HeightControllerParams bad;
  bad.height_tolerance_m = -1.0;
  bad.approach_band_m = 0.5;
  const std::string error = controller.setParams(bad);
  EXPECT_NE(error.find("height_tolerance_m"), std::string::npos) << error;
  EXPECT_NE(error.find("approach_band_m"), std::string::npos) << error;
  EXPECT_EQ(controller.params().height_tolerance_m, nb::HeightControllerParams{}.height_tolerance_m);
  EXPECT_EQ(controller.params().approach_band_m, nb::HeightControllerParams{}.approach_band_m);
  nb::HeightControllerParams good;
  good.approach_band_m = 0.006;
  good.integral_rate_per_s = 1.0;
  EXPECT_EQ(controller.setParams(good), "");
  EXPECT_EQ(controller.params().approach_band_m, 0.006);
  EXPECT_EQ(controller.params().integral_rate_per_s, 1.0);
  EXPECT_TRUE(controller.hasTarget()) << "the target is kept";
  EXPECT_EQ(controller.target(), 0.08);
}

TEST(AirbagCell, BadSetpointsAreRefusedWithoutChange) {
  nb::AirbagCell cell{nb::AirbagCellParams{}};
  cell.resetToHeight(0.05, 15.6);
  for (double bad : {std::nan(""), HUGE_VAL, -0.01, 0.16, 1.0}) {
    const std::string msg = cell.requestHeight(bad, 0.0);
    EXPECT_FALSE(msg.empty()) << bad;
    EXPECT_DOUBLE_EQ(cell.setpoint(), 0.05);
  }
  EXPECT_NE(cell.requestHeight(0.2, 0.0).find("outside"), std::string::npos);
  EXPECT_NE(cell.requestHeight(std::nan(""), 0.0).find("finite"), std::string::npos);
}

TEST(AirbagCell, ReliefPressureHoldsWithTheSupplyAboveIt) {
  nb::AirbagCellParams params;
  params.safety.relief_pressure_pa = 30000.0;
  params.controller.max_pressure_pa = 29000.0;
  nb::AirbagCell cell(params);
  cell.reset(45.0);  // a heavy load: the top height needs far more than the relief
  cell.setSupplyPressure(45000.0);
  ASSERT_EQ(cell.requestHeight(0.15, 0.0), "");
  double p_max = 0.0;
  for (double t = 0.01; t <= 6.0; t += 0.01) {
    cell.advanceTo(t);
    p_max = std::max(p_max, cell.variables().gauge_pressure_pa);
  }
  EXPECT_LE(p_max, 30000.0);
  EXPECT_GT(p_max, 25000.0);  // it did press against the limit
}

TEST(AirbagCell, ReliefVentsEvenWhenTheControllerWouldNot) {
  // The controller's own limit above the relief: the safety layer alone must hold it.
  nb::AirbagCellParams params;
  params.safety.relief_pressure_pa = 30000.0;
  params.controller.max_pressure_pa = 29999.0;
  params.safety.relief_margin_pa = 200.0;
  nb::AirbagCell cell(params);
  cell.reset(45.0);
  cell.setSupplyPressure(45000.0);
  cell.requestHeight(0.15, 0.0);
  double p_max = 0.0;
  bool flagged = false;
  for (double t = 0.01; t <= 6.0; t += 0.01) {
    cell.advanceTo(t);
    p_max = std::max(p_max, cell.variables().gauge_pressure_pa);
    flagged |= (cell.faults() & nb::kFaultOverpressure) != 0;
  }
  EXPECT_LE(p_max, 30000.0);
  EXPECT_TRUE(flagged);
}

TEST(AirbagCell, CommandTimeoutHoldsTheGas) {
  nb::AirbagCellParams params;
  params.safety.command_timeout_s = 0.5;
  nb::AirbagCell cell(params);
  cell.resetToHeight(0.03, 15.6);
  cell.requestHeight(0.12, 0.0);
  cell.advanceTo(0.2);
  EXPECT_EQ(cell.mode(), nb::AirbagMode::kHeight);
  cell.advanceTo(0.8);  // no heartbeat since t = 0
  EXPECT_EQ(cell.mode(), nb::AirbagMode::kSafe);
  EXPECT_TRUE(cell.faults() & nb::kFaultCommandTimeout);
  const double mass = cell.variables().mass_kg;
  cell.advanceTo(1.5);
  EXPECT_EQ(cell.valves().inlet, 0.0);
  EXPECT_EQ(cell.valves().vent, 0.0);
  EXPECT_NEAR(cell.variables().mass_kg, mass, 1e-12);
  for (double t = 1.5; t <= 4.0; t += 0.1) {  // the commander is back: heartbeats resume
    cell.heartbeat(t);
    cell.advanceTo(t);
  }
  EXPECT_EQ(cell.mode(), nb::AirbagMode::kHeight);
  EXPECT_NEAR(cell.variables().height_m, 0.12, 1e-3);
}

namespace {
// A cell filling from 30 mm towards 120 mm under 15.6 N, 0.1 s into the fill (inlet open).
nb::AirbagCell fillingCell() {
  nb::AirbagCell cell{nb::AirbagCellParams{}};
  cell.resetToHeight(0.03, 15.6);
  cell.requestHeight(0.12, 0.0);
  cell.advanceTo(0.1);
  return cell;
}
}  // namespace

TEST(AirbagCell, SensorFaultClosesTheValves) {
  nb::AirbagCell cell = fillingCell();
  ASSERT_GT(cell.valves().inlet, 0.0);
  cell.setSensorFailure(true);
  cell.advanceTo(0.2);
  EXPECT_EQ(cell.mode(), nb::AirbagMode::kSafe);
  EXPECT_TRUE(cell.faults() & nb::kFaultSensor);
  EXPECT_EQ(cell.valves().inlet, 0.0);
  EXPECT_EQ(cell.valves().vent, 0.0);
  EXPECT_TRUE(std::isnan(cell.measurement().gauge_pressure_pa));
  cell.setSensorFailure(false);
  cell.advanceTo(3.0);
  EXPECT_FALSE(cell.faults() & nb::kFaultSensor);
  EXPECT_NEAR(cell.variables().height_m, 0.12, 1e-3);
}

TEST(AirbagCell, AShortBadReadingHoldsTheGasWithoutASensorFault) {
  nb::AirbagCell cell = fillingCell();
  ASSERT_GT(cell.valves().inlet, 0.0);
  cell.setSensorFailure(true);  // 4 control periods of NaN readings, fewer than sensor_fault_periods
  cell.advanceTo(0.12);
  EXPECT_EQ(cell.valves().inlet, 0.0);
  EXPECT_EQ(cell.valves().vent, 0.0);
  EXPECT_EQ(cell.faults() & nb::kFaultSensor, 0u);
  cell.setSensorFailure(false);
  cell.advanceTo(3.0);
  EXPECT_EQ(cell.faults() & nb::kFaultSensor, 0u);
  EXPECT_EQ(cell.mode(), nb::AirbagMode::kHeight);
  EXPECT_NEAR(cell.variables().height_m, 0.12, 1e-3);
}

TEST(AirbagCell, ReadingsAreOfTheStateAtTheCellsTime) {
  // What advanceTo leaves in measurement() is the state at time(): a recording stamps it with
  // that time and a replay compares it there (read at the period's start, it lagged by a period).
  nb::AirbagCell cell{nb::AirbagCellParams{}};
  cell.resetToHeight(0.03, 15.6);
  cell.requestHeight(0.12, 0.0);
  for (double t = 0.02; t < 1.0; t += 0.02) {
    cell.advanceTo(t);
    ASSERT_EQ(cell.measurement().gauge_pressure_pa, cell.variables().gauge_pressure_pa) << "at " << t << " s";
    ASSERT_EQ(cell.measurement().height_m, cell.variables().height_m) << "at " << t << " s";
  }
}

TEST(AirbagCell, VentEmptiesTheCell) {
  nb::AirbagCell cell{nb::AirbagCellParams{}};
  cell.resetToHeight(0.12, 20.6);
  cell.requestVent(0.0);
  cell.advanceTo(6.0);
  EXPECT_LT(cell.variables().height_m, 0.01);
  EXPECT_EQ(cell.valves().vent, 1.0);
}

TEST(AirbagCell, CprVacuumEmptiesAnUnloadedCellWithinSeconds) {
  // A cell carrying only its plate has almost no pressure to push its air out: to ambient it
  // takes half a minute; the vacuum of CPR mode empties it in a couple of seconds.
  auto time_to_10mm = [](double vacuum_pa) {
    nb::AirbagCellParams p;
    p.cpr_vacuum_pa = vacuum_pa;
    nb::AirbagCell cell(p);
    cell.resetToHeight(0.12, 0.6);
    cell.requestVent(0.0);
    double t = 0.0;
    while (t < 60.0 && cell.variables().height_m >= 0.010) cell.advanceTo(t += 0.01);
    return t;
  };
  EXPECT_LT(time_to_10mm(-5000.0), 3.0);
  EXPECT_GT(time_to_10mm(0.0), 10.0);
}

TEST(AirbagCell, InvalidParametersAreRefusedByName) {
  nb::AirbagCellParams params;
  params.controller.max_pressure_pa = 40000.0;  // above the 35 kPa relief
  try {
    nb::AirbagCell cell(params);
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("relief"), std::string::npos) << e.what();
  }
  for (double band : {0.0002, 0.01, std::nan("")}) {  // inside the deadband, too wide, not a number
    SCOPED_TRACE(band);
    nb::AirbagCellParams p;
    p.controller.hold_band_m = band;
    try {
      nb::AirbagCell cell(p);
      FAIL();
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("hold_band_m"), std::string::npos) << e.what();
    }
  }
}

TEST(FlowLimit, MinimumTimeGrowsWithTheMove) {
  const nb::CellParams p;
  const double short_move = nb::flowLimitedMinimumTime(p, 15.6, 0.02, 0.06);
  const double long_move = nb::flowLimitedMinimumTime(p, 15.6, 0.02, 0.10);
  EXPECT_GT(short_move, 0.0);
  EXPECT_GT(long_move, short_move);
  EXPECT_TRUE(std::isnan(nb::flowLimitedMinimumTime(p, 15.6, 0.02, 0.5)));
}

}  // namespace

namespace {

// Loads: what a cell accepts, and that nothing it refuses changes it.
TEST(AirbagCellSafety, AbsurdLoadsAreRefusedAndChangeNothing) {
  nb::AirbagCell cell{nb::AirbagCellParams{}};
  cell.resetToHeight(0.10, 10.6);
  for (double bad : std::vector<double>{std::nan(""), HUGE_VAL, -HUGE_VAL, -1.0, 1e9, -1e9, 1000.1, 1e6}) {
    const std::string error = cell.setLoad(bad);
    EXPECT_NE(error.find("max_load_n"), std::string::npos) << bad << ": " << error;
    EXPECT_EQ(cell.load(), 10.6) << bad;
  }
  EXPECT_EQ(cell.setLoad(300.0), "");
  EXPECT_EQ(cell.load(), 300.0);
}

// A solve that leaves the plant in an invalid state resets the cell into a fault; a new
// height request recovers it.
TEST(AirbagCellSafety, AnInvalidPlantStateResetsIntoAFaultAndRecovers) {
  nb::AirbagCell cell{nb::AirbagCellParams{}};
  cell.resetToHeight(0.10, 10.6);
  nb::CellModel::StateVector broken = cell.model().state();
  broken[nb::CellModel::kEnergy] = -1.0;  // what 1e9 N did before: a negative temperature
  const_cast<nb::CellModel&>(cell.model()).setState(cell.time(), broken);
  cell.advanceTo(cell.time() + 0.02);
  EXPECT_TRUE(cell.faults() & nb::kFaultModel);
  EXPECT_EQ(cell.mode(), nb::AirbagMode::kSafe);
  EXPECT_GT(cell.variables().structure.volume_m3, 0.0);
  EXPECT_GT(cell.variables().temperature_k, 250.0);
  ASSERT_EQ(cell.requestHeight(0.05, cell.time()), "");
  EXPECT_FALSE(cell.faults() & nb::kFaultModel);
  cell.advanceTo(cell.time() + 4.0);
  EXPECT_NEAR(cell.measurement().height_m, 0.05, 2e-3);
}

// Bed-wide CPR: the cell vents and refuses every height until CPR is off; then it holds.
TEST(AirbagCellSafety, CprIsExclusive) {
  nb::AirbagCell cell{nb::AirbagCellParams{}};
  cell.resetToHeight(0.10, 10.6);
  cell.setCpr(true, 0.0);
  EXPECT_EQ(cell.mode(), nb::AirbagMode::kVent);
  EXPECT_NE(cell.requestHeight(0.15, 0.1).find("CPR"), std::string::npos);
  EXPECT_EQ(cell.mode(), nb::AirbagMode::kVent);
  EXPECT_NE(cell.requestPressure(5000.0, 0.1).find("CPR"), std::string::npos);
  EXPECT_NE(cell.checkPressure(5000.0).find("CPR"), std::string::npos);
  EXPECT_EQ(cell.mode(), nb::AirbagMode::kVent);
  cell.advanceTo(3.0);
  EXPECT_LT(cell.measurement().height_m, 0.01);
  cell.setCpr(false, 3.0);
  EXPECT_EQ(cell.mode(), nb::AirbagMode::kIdle);
  EXPECT_EQ(cell.requestHeight(0.05, 3.0), "");
}

}  // namespace

namespace {

// Peak gauge pressure [Pa] of a cell holding 0.10 m under 10.6 N when the outside load steps to
// `load_n` over `rise_s`.
double peakPressureUnderLoadStep(const nb::AirbagCellParams& params, double load_n, double rise_s) {
  nb::AirbagCell cell(params);
  cell.resetToHeight(0.10, 10.6);
  EXPECT_EQ(cell.requestHeight(0.10, 0.0), "");
  cell.advanceTo(1.0);
  double peak = 0.0;
  for (double t = 1.0; t < 3.0; t += 0.001) {
    const double f = rise_s > 0.0 ? std::min(1.0, (t - 1.0) / rise_s) : 1.0;
    cell.setLoad(10.6 + f * (load_n - 10.6));
    cell.advanceTo(t);
    peak = std::max(peak, cell.variables().gauge_pressure_pa);
  }
  return peak;
}

// Relief under outside load: the relief valve (ISO 6358, beside the vent) holds a sudden 300 N
// on an inflated cell within relief + 10 %; without it the vent alone is outrun.
TEST(AirbagCellSafety, ReliefValveHoldsSuddenOutsideLoads) {
  nb::AirbagCellParams params;
  params.cell.supply_pressure_pa = 30000.0;  // the bed's supply (sim.launch)
  const double limit = 1.1 * params.safety.relief_pressure_pa;
  for (double load : {150.0, 300.0})
    for (double rise : {0.0, 0.05}) EXPECT_LE(peakPressureUnderLoadStep(params, load, rise), limit) << load << " N";
  params.cell.relief_sonic_conductance_m3_s_pa = 0.0;
  EXPECT_GT(peakPressureUnderLoadStep(params, 300.0, 0.0), limit) << "the vent alone would have held it";
}

}  // namespace

// The controller predicts with the structure the cell has. It used the pillow model on an FE
// table cell: asked for 100 mm under 10.6 N it stalled at 84 mm, hunting, and asked for 70 mm
// under 15.6 N it read the load as 26 N and filled on to 94 mm.
TEST(HeightController, OnTheFeTableCellReachesAndHoldsItsTarget) {
  nb::AirbagCellParams p;
  p.cell =
      nb::loadCellParamsYaml(std::string(NURSING_BED_SOURCE_DIR) + "/config/airbag_tpu_double_100_fe.yaml", p.cell);
  p.cell.supply_pressure_pa = 30000.0;
  struct Case {
    double load_n, target_m;
  };
  for (const Case c : {Case{15.6, 0.07}, Case{10.6, 0.10}, Case{15.6, 0.02}}) {
    nb::AirbagCell cell(p);
    cell.reset(c.load_n);
    ASSERT_EQ(cell.requestHeight(c.target_m, 0.0), "");
    double t = 0.0, worst_late = 0.0;
    for (; t < 12.0; t += 0.02) {
      cell.advanceTo(t);
      cell.heartbeat(t);
      if (t > 6.0) worst_late = std::max(worst_late, std::fabs(cell.measurement().height_m - c.target_m));
    }
    EXPECT_LT(worst_late, 2e-3) << c.load_n << " N to " << c.target_m << " m";
    EXPECT_NEAR(cell.loadEstimate(), c.load_n, 0.5) << c.load_n << " N to " << c.target_m << " m";
    EXPECT_EQ(cell.faults(), 0u);
  }
}

// A load taken off a lifted plate. Near the FE table's top the cell is stiff (one period of
// inflow adds kPa), the plate chatters after the drop, and a load estimate that learned only at
// rest would keep the old load for good (from 10.6 N to 0.6 N the cell would hunt at 110-112 mm
// for a 100 mm target). The force balance learns while it moves.
TEST(HeightController, AfterALoadDropTheCellComesBackToItsTarget) {
  nb::AirbagCellParams fe;
  fe.cell =
      nb::loadCellParamsYaml(std::string(NURSING_BED_SOURCE_DIR) + "/config/airbag_tpu_double_100_fe.yaml", fe.cell);
  fe.cell.supply_pressure_pa = 30000.0;
  struct Case {
    const char* cell;
    nb::AirbagCellParams params;
    double from_n, to_n;
  };
  for (const Case& c :
       {Case{"fe", fe, 10.6, 0.6}, Case{"fe", fe, 20.6, 0.6}, Case{"fe", fe, 0.6, 10.6},
        Case{"pillow", nb::AirbagCellParams{}, 10.6, 0.6}, Case{"pillow", nb::AirbagCellParams{}, 20.6, 0.6}}) {
    SCOPED_TRACE(testing::Message() << c.cell << " cell, " << c.from_n << " N -> " << c.to_n << " N at 0.10 m");
    nb::AirbagCell cell(c.params);
    cell.reset(c.from_n);
    ASSERT_EQ(cell.requestHeight(0.10, 0.0), "");
    double t = 0.0;
    for (; t < 10.0; t += 0.02) {
      cell.advanceTo(t);
      cell.heartbeat(t);
    }
    ASSERT_NEAR(cell.measurement().height_m, 0.10, 2e-3);
    ASSERT_EQ(cell.setLoad(c.to_n), "");
    double worst_late = 0.0;
    for (; t < 30.0; t += 0.02) {
      cell.advanceTo(t);
      cell.heartbeat(t);
      if (t > 25.0) worst_late = std::max(worst_late, std::fabs(cell.measurement().height_m - 0.10));
    }
    EXPECT_LT(worst_late, 2e-3);
    EXPECT_NEAR(cell.loadEstimate(), c.to_n, 0.5);
    EXPECT_EQ(cell.faults(), 0u);
  }
}
