// The airbag cell over the hardware boundary: no height sensor (the observer's height), a real
// (non-lockstep) hardware with its link lost and regained, pressure setpoints.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <memory>
#include <random>
#include <string>

#include "nursing_bed/core/control/airbag_cell.h"
#include "rig_without_height_sensor.h"

namespace nb = nursing_bed;

namespace {

using nursing_bed::test::rigWithoutHeightSensor;

/// Real-time-style hardware in front of a simulated plant (which runs on read(now)): the
/// pressure and the supply pressure only, as a valve terminal reads them.
class PressureOnlyHardware : public nb::CellHardware {
 public:
  explicit PressureOnlyHardware(std::shared_ptr<nb::SimulatedCellHardware> plant) : plant_(std::move(plant)) {}
  void configure(const nb::HardwareConfig&) override {}
  nb::HardwareCapabilities capabilities() const override { return {}; }
  nb::CellReadings read(double now_s) override {
    nb::CellReadings r = plant_->read(now_s);
    r.height_m = {};
    r.inflow_kg_s = {};
    r.gas_temperature_k = {};
    return r;
  }
  void write(const nb::ValveOpenings& v, double now_s) override { plant_->write(v, now_s); }
  std::shared_ptr<nb::SimulatedCellHardware> plant_;
};

/// Its link can be cut. The terminal then holds its outputs as last written until its watchdog
/// shuts them `hold_s` later (the rig emulator's: 0.1 s) and, when `reports_held`, the driver
/// says what they drove meanwhile (CellReadings::inlet_driven / vent_driven).
class CuttableHardware : public PressureOnlyHardware {
 public:
  using PressureOnlyHardware::PressureOnlyHardware;
  nb::CellReadings read(double now_s) override {
    nb::CellReadings r = PressureOnlyHardware::read(now_s);
    const double since_s = last_read_s_;
    last_read_s_ = now_s;
    if (!cut) {
      cut_at_s_ = -1.0;
      if (quantum_pa > 0.0 && r.gauge_pressure_pa.present()) {
        const double p = r.gauge_pressure_pa.value + noise_(random_);
        r.gauge_pressure_pa.value = quantum_pa * std::round(p / quantum_pa);
      }
      if (stale_every > 0 && ++reads_ % stale_every != 0 && last_sample_.present()) r.gauge_pressure_pa = last_sample_;
      last_sample_ = r.gauge_pressure_pa;
      return r;
    }
    if (cut_at_s_ < 0.0) cut_at_s_ = since_s;
    const double held = heldFraction(since_s, now_s);
    if (held < 1.0) plant_->write({}, now_s);  // the watchdog shut them
    r = nb::CellReadings{};
    r.link = nb::LinkState::kDown;
    r.link_error = "cut";
    if (reports_held) {
      r.inlet_driven = {held * written_.inlet, now_s};
      r.vent_driven = {held * written_.vent, now_s};
    }
    if (held < 1.0) written_ = {};
    return r;
  }
  void write(const nb::ValveOpenings& v, double now_s) override {
    if (cut) ++writes_while_cut;
    written_ = v;
    plant_->write(v, now_s);
  }
  std::string describe() const override { return "cuttable"; }
  bool cut = false;
  /// Readings with 8 Pa of noise rounded to this step (a pressure register's); 0: exact [Pa].
  double quantum_pa = 0.0;
  /// A new pressure sample every this many reads, the last one repeated (its stamp kept) in
  /// between: a bus slower than the control period; 0: every read.
  int stale_every = 0;
  double hold_s = 0.0;
  bool reports_held = false;
  int writes_while_cut = 0;

 private:
  /// The part of (from, to] before the watchdog shut the outputs.
  double heldFraction(double from_s, double to_s) const {
    if (to_s <= from_s) return 0.0;
    return std::clamp((cut_at_s_ + hold_s - from_s) / (to_s - from_s), 0.0, 1.0);
  }
  nb::ValveOpenings written_;
  double last_read_s_ = 0.0;
  double cut_at_s_ = -1.0;
  std::mt19937 random_{7};
  long reads_ = 0;
  nb::StampedReading last_sample_;
  std::normal_distribution<double> noise_{0.0, 8.0};
};

/// A cell without a height sensor on cuttable hardware, controlled every 10 ms, resting at
/// `height_m` under `load_n` and asked for `target_m`.
struct CuttableCell {
  /// The valves act `observer.params.valve_dead_time_s` late (the observer knows it).
  CuttableCell(double height_m, double load_n, double target_m, const nb::AirbagObserverSetup& observer = {}) {
    nb::AirbagCellParams p;
    p.control_period_s = 0.01;
    plant = rigWithoutHeightSensor(p, height_m, load_n, observer.params.valve_dead_time_s);
    hw = std::make_shared<CuttableHardware>(plant);
    cell = std::make_unique<nb::AirbagCell>(p, hw, observer);
    cell->resetToHeight(height_m, load_n);
    request_error = cell->requestHeight(target_m, 0.0);
  }
  /// Runs the cell's periods up to `end_s`, calling `each()` after every one.
  template <typename Each = void (*)()>
  void runTo(
      double end_s, Each each = [] {}) {
    for (; t < end_s - 1e-9; t += 0.01) {
      cell->advanceTo(t);
      each();
    }
  }
  std::shared_ptr<nb::SimulatedCellHardware> plant;
  std::shared_ptr<CuttableHardware> hw;
  std::unique_ptr<nb::AirbagCell> cell;
  std::string request_error;
  double t = 0.0;
};

/// A driver that opens its valves at most half way (a saturating proportional driver) and,
/// when `reports`, says what it applied (CellReadings::inlet_driven / vent_driven).
class HalfOpeningHardware : public PressureOnlyHardware {
 public:
  HalfOpeningHardware(std::shared_ptr<nb::SimulatedCellHardware> plant, bool reports)
      : PressureOnlyHardware(std::move(plant)), reports_(reports) {}
  nb::CellReadings read(double now_s) override {
    nb::CellReadings r = PressureOnlyHardware::read(now_s);
    if (reports_) {
      r.inlet_driven = {applied_.inlet, now_s};
      r.vent_driven = {applied_.vent, now_s};
    }
    return r;
  }
  void write(const nb::ValveOpenings& v, double now_s) override {
    applied_ = v;
    applied_.inlet = std::min(v.inlet, 0.5);
    applied_.vent = std::min(v.vent, 0.5);
    plant_->write(applied_, now_s);
  }
  std::string describe() const override { return "half-opening"; }

 private:
  bool reports_;
  nb::ValveOpenings applied_;
};

}  // namespace

TEST(AirbagOnHardware, TheObserverIntegratesWhatTheDriverApplied) {
  // The gas passes through what the valves did, not what was asked of them.
  double error_m[2] = {0.0, 0.0};
  for (int reports = 0; reports < 2; ++reports) {
    nb::AirbagCellParams p;
    auto plant = rigWithoutHeightSensor(p, 0.0, 15.6);
    auto hw = std::make_shared<HalfOpeningHardware>(plant, reports == 1);
    nb::AirbagCell cell(p, hw, nb::AirbagObserverSetup{});
    cell.reset(15.6);
    ASSERT_EQ(cell.requestHeight(0.08, 0.0), "");
    for (double t = 0.005; t <= 4.0; t += 0.005) cell.advanceTo(t);
    error_m[reports] = std::fabs(plant->variables().height_m - cell.measurement().height_m);
  }
  std::cout << "[airbag] driver at most half open: estimate off by " << 1e3 * error_m[0] << " mm taking the command, "
            << 1e3 * error_m[1] << " mm taking what the driver applied\n";
  EXPECT_LT(error_m[1], 0.002);
  EXPECT_GT(error_m[0], 5.0 * error_m[1]);
}

TEST(AirbagOnHardware, StepWithoutAHeightSensorSettlesNearTheFlowLimit) {
  // Target: 20 -> 100 mm under 15.6 N settles within +-2 mm in <= 2x the flow-limited time.
  nb::AirbagCellParams p;
  auto rig = rigWithoutHeightSensor(p, 0.02, 15.6);
  nb::AirbagCell cell(p, rig, nb::AirbagObserverSetup{});
  cell.resetToHeight(0.02, 15.6);
  ASSERT_EQ(cell.heightSource(), nb::HeightSource::kEstimated);
  ASSERT_EQ(cell.requestHeight(0.10, 0.0), "");
  const double t_min = nb::flowLimitedMinimumTime(p.cell, 15.6, 0.02, 0.10);
  double settle = 0.0, worst_estimate_error = 0.0;
  for (double t = 0.005; t <= 6.0; t += 0.005) {
    cell.advanceTo(t);
    const double truth = rig->variables().height_m;
    if (std::fabs(truth - 0.10) > 0.002) settle = t;
    worst_estimate_error = std::max(worst_estimate_error, std::fabs(truth - cell.measurement().height_m));
  }
  std::cout << "[airbag] no height sensor: settled in " << settle << " s, flow limit " << t_min << " s ("
            << settle / t_min << "x); worst estimate error " << 1e3 * worst_estimate_error << " mm; sd "
            << 1e3 * cell.heightSd() << " mm\n";
  EXPECT_LE(settle, 2.0 * t_min);
  EXPECT_NEAR(rig->variables().height_m, 0.10, 0.002);
  EXPECT_GT(cell.heightSd(), 0.0);
}

// A heavy part of the patient (36 N) on a cell held at 91 mm, its valves 40 ms late (bus,
// terminal and valve on a loaded machine). Corrections that ignored the gas still in flight
// would overshoot by its worth, and active damping a quarter of the loaded plate's period late
// would pump its swing: the cell would fill and vent at several Hz, and a few % of flow-timing
// error on that throughput drifts the observer's gas (doc/real_bed.md).
TEST(AirbagOnHardware, AHeavyCellHoldsQuietlyBehindTheValvesDeadTime) {
  nb::AirbagCellParams p;
  nb::AirbagObserverSetup observer;
  observer.params.valve_dead_time_s = 0.04;
  auto rig = rigWithoutHeightSensor(p, 0.02, 36.0, observer.params.valve_dead_time_s);
  nb::AirbagCell cell(p, rig, observer);
  cell.resetToHeight(0.02, 36.0);
  ASSERT_EQ(cell.requestHeight(0.091, 0.0), "");
  double t = 0.005;
  for (; t <= 8.0; t += 0.005) cell.advanceTo(t);
  int openings = 0;
  bool was_open = false;
  double sum = 0.0, sum_sq = 0.0, open_s = 0.0;
  long n = 0;
  for (; t <= 28.0; t += 0.005) {
    cell.advanceTo(t);
    const bool open = cell.valves().inlet > 0.0 || cell.valves().vent > 0.0;
    if (open && !was_open) ++openings;
    was_open = open;
    open_s += 0.005 * (cell.valves().inlet + cell.valves().vent);
    const double h = rig->variables().height_m;
    sum += h;
    sum_sq += h * h;
    ++n;
  }
  const double mean = sum / n, sd = std::sqrt(std::max(0.0, sum_sq / n - mean * mean));
  std::cout << "[airbag] 36 N held at 91 mm, valves 40 ms late: " << openings / 20.0 << " valve openings/s, " << open_s
            << " s of full opening in 20 s, plate " << 1e3 * mean << " mm, sd " << 1e3 * sd << " mm\n";
  EXPECT_LT(openings / 20.0, 1.0);
  EXPECT_LT(open_s, 0.5);
  EXPECT_LT(sd, 1e-3);
  EXPECT_NEAR(mean, 0.091, 2e-3);
}

TEST(AirbagOnHardware, ALostLinkFlagsStopsCommandingAndResumesToTheKeptSetpoint) {
  CuttableCell rig(0.05, 15.6, 0.09);
  ASSERT_EQ(rig.request_error, "");
  rig.runTo(0.3);
  rig.hw->cut = true;
  rig.runTo(0.31);
  EXPECT_TRUE(rig.cell->faults() & nb::kFaultCommunication);
  EXPECT_EQ(rig.cell->mode(), nb::AirbagMode::kSafe);
  rig.runTo(1.0);
  EXPECT_EQ(rig.hw->writes_while_cut, 0);
  EXPECT_NEAR(rig.cell->setpoint(), 0.09, 1e-12) << "the setpoint is kept";
  rig.hw->cut = false;
  rig.runTo(6.0);
  EXPECT_FALSE(rig.cell->faults() & nb::kFaultCommunication);
  EXPECT_EQ(rig.cell->mode(), nb::AirbagMode::kHeight);
  EXPECT_NEAR(rig.plant->variables().height_m, 0.09, 0.003);
}

TEST(AirbagOnHardware, CommandsWhileTheLinkIsDownKeepTheCellSafeAndActWhenItIsBack) {
  CuttableCell rig(0.05, 15.6, 0.09);
  rig.runTo(0.3);
  rig.hw->cut = true;
  rig.runTo(0.5);
  // The bed manager's resent setpoints and heartbeats keep coming: the cell stays SAFE.
  EXPECT_EQ(rig.cell->requestHeight(0.07, rig.t), "");
  rig.cell->heartbeat(rig.t);
  rig.runTo(1.0);
  EXPECT_EQ(rig.cell->mode(), nb::AirbagMode::kSafe);
  EXPECT_EQ(rig.hw->writes_while_cut, 0);
  EXPECT_NEAR(rig.cell->setpoint(), 0.07, 1e-12);
  EXPECT_EQ(rig.cell->requestPressure(3000.0, rig.t), "");
  EXPECT_EQ(rig.cell->mode(), nb::AirbagMode::kSafe);
  rig.cell->setCpr(true, rig.t);
  EXPECT_EQ(rig.cell->mode(), nb::AirbagMode::kSafe);
  rig.cell->setCpr(false, rig.t);
  EXPECT_EQ(rig.cell->requestHeight(0.08, rig.t), "");
  rig.hw->cut = false;
  rig.runTo(6.0);
  EXPECT_EQ(rig.cell->mode(), nb::AirbagMode::kHeight);
  EXPECT_NEAR(rig.plant->variables().height_m, 0.08, 0.003);
}

TEST(AirbagOnHardware, ABriefLinkLossKeepsALightCellsGas) {
  // The plate alone (0.6 N) held at 75 mm rests at ~46 Pa. A 50 ms bus timeout: when the link
  // returns the cell still holds its gas (the valves were shut), and the estimate must say so.
  // Re-anchored flat on the first reading below 60 Pa, the controller filled it to the top.
  CuttableCell rig(0.075, 0.6, 0.075);
  ASSERT_EQ(rig.request_error, "");
  rig.runTo(1.0);
  rig.hw->cut = true;
  rig.runTo(1.05);
  ASSERT_TRUE(rig.cell->faults() & nb::kFaultCommunication);
  rig.hw->cut = false;
  double worst_m = 0.0, highest_pa = 0.0;
  rig.runTo(4.0, [&] {
    worst_m = std::max(worst_m, std::fabs(rig.plant->variables().height_m - 0.075));
    highest_pa = std::max(highest_pa, rig.plant->variables().gauge_pressure_pa);
  });
  std::cout << "[airbag] light cell after a 50 ms link loss: worst " << 1e3 * worst_m << " mm off 75 mm, highest "
            << highest_pa << " Pa\n";
  EXPECT_FALSE(rig.cell->faults() & nb::kFaultCommunication);
  EXPECT_LE(worst_m, 0.005);
  EXPECT_LE(highest_pa, 500.0);
}

/// A cell held at 15 mm under `load_n` loses its link for 1 s. When `emptied`, its bed is
/// emptied meanwhile and sealed again with a puff of gas in (a restarted rig's cells): flat,
/// the plate floating on the residual gas at the pressure that just carries it (487 Pa under
/// 15.6 N), near what the cell held at 15 mm reads (560 Pa). With the observer's
/// `resume_vent_s`; returns the true height 6 s after the checks began (the link back and
/// steady for link_steady_s), `worst_m` the largest |true height - 15 mm| over the last 4.5 s,
/// `flat_pa` the emptied cell's pressure. The emptied cell reads ambient once vented and is
/// re-anchored after reanchor_time_s (0.5 s) of it, refilled by 1.5 s after the checks began.
double heightAfterALostLink(double load_n, bool emptied, double resume_vent_s, double* worst_m, double* flat_pa) {
  nb::AirbagObserverSetup observer;
  observer.gas_check.resume_vent_s = resume_vent_s;
  observer.params.valve_dead_time_s = 0.015;  // a terminal's: the controller holds quietly on target
  CuttableCell rig(0.015, load_n, 0.015, observer);
  rig.runTo(1.0);
  rig.hw->cut = true;
  rig.runTo(1.5);
  if (emptied) rig.plant->resetToHeight(0.0, load_n);
  *flat_pa = rig.plant->variables().gauge_pressure_pa;
  rig.runTo(2.0);
  rig.hw->cut = false;
  const double checks_s = 2.0 + observer.gas_check.link_steady_s;
  rig.runTo(checks_s + 1.5);
  *worst_m = 0.0;
  rig.runTo(checks_s + 6.0, [&] { *worst_m = std::max(*worst_m, std::fabs(rig.plant->variables().height_m - 0.015)); });
  return rig.plant->variables().height_m;
}

TEST(AirbagOnHardware, ACellEmptiedWhileTheLinkWasDownIsFoundFlatAndRefilled) {
  // Pressure alone cannot tell the two apart, and a cell holding on target does nothing that
  // would; the vent after the link is back does (the flat cell grounds and reads ambient).
  for (const double load_n : {15.6, 36.0}) {
    double worst_m = 0.0, flat_pa = 0.0;
    const double checked_m = heightAfterALostLink(load_n, true, 0.05, &worst_m, &flat_pa);
    std::cout << "[airbag] " << load_n << " N, emptied while the link was down (flat at " << flat_pa
              << " Pa): true height 6 s later " << 1e3 * checked_m << " mm, worst " << 1e3 * worst_m
              << " mm off over the last 4.5 s\n";
    EXPECT_GE(flat_pa, 200.0) << load_n << " N: the case must be a flat cell holding pressure";
    EXPECT_NEAR(checked_m, 0.015, 0.003) << load_n << " N";
    EXPECT_LE(worst_m, 0.004) << load_n << " N";
    // Not emptied: the check costs a dip that the controller restores.
    double kept_m = heightAfterALostLink(load_n, false, 0.05, &worst_m, &flat_pa);
    std::cout << "[airbag] " << load_n << " N, kept its gas: true height 6 s later " << 1e3 * kept_m << " mm, worst "
              << 1e3 * worst_m << " mm off over the last 4.5 s\n";
    EXPECT_NEAR(kept_m, 0.015, 0.002) << load_n << " N";
    EXPECT_LE(worst_m, 0.004) << load_n << " N";
  }
  double worst_m = 0.0, flat_pa = 0.0;
  const double unchecked_m = heightAfterALostLink(15.6, true, 0.0, &worst_m, &flat_pa);
  std::cout << "[airbag] 15.6 N, emptied, no check: true height 6 s later " << 1e3 * unchecked_m << " mm\n";
  EXPECT_LE(unchecked_m, 0.01) << "the case must be one the unchecked cell gets wrong";
}

TEST(AirbagOnHardware, ATerminalRestartedEmptyIsALinkEventNotACellFailure) {
  // A restarted rig's cells come back flat and empty, and the link check finds them flat. Over
  // a bus that brings a new sample every third period (a loaded machine's late polls), a flat
  // test restarted by each repeat never ended: the weight bound pulled the estimate down by the
  // whole height instead, which the monitor took for a cell failure (the bed levels the
  // patient for one).
  for (const double load_n : {0.6, 1.0, 2.0, 5.0, 15.6, 30.0}) {
    CuttableCell rig(0.06, load_n, 0.06);
    rig.hw->quantum_pa = 12.0;
    rig.hw->stale_every = 3;
    rig.runTo(2.0);
    rig.hw->cut = true;
    rig.runTo(2.1);
    rig.plant->reset(load_n);
    rig.runTo(5.0);
    rig.hw->cut = false;
    bool inconsistent = false, unverified = false;
    rig.runTo(6.0, [&] {
      inconsistent = inconsistent || (rig.cell->faults() & nb::kFaultInconsistent);
      unverified = unverified || rig.cell->heightUnverified();
    });
    rig.runTo(22.0, [&] { inconsistent = inconsistent || (rig.cell->faults() & nb::kFaultInconsistent); });
    EXPECT_TRUE(unverified) << load_n << " N: flagged while the check runs";
    EXPECT_FALSE(inconsistent) << load_n << " N";
    EXPECT_NEAR(rig.plant->variables().height_m, 0.06, 0.002) << load_n << " N";
    EXPECT_FALSE(rig.cell->heightUnverified()) << load_n << " N";
  }
}

/// Gas error (estimate over truth - 1) of a cell filling 20 -> 100 mm under 15.6 N right
/// after a 0.4 s link loss during which the terminal kept its inlet open for 0.25 s.
double gasErrorAfterAHeldLinkLoss(bool reports_held) {
  CuttableCell rig(0.02, 15.6, 0.10);
  rig.hw->hold_s = 0.25;
  rig.hw->reports_held = reports_held;
  rig.runTo(0.3);
  rig.hw->cut = true;
  rig.runTo(0.7);
  rig.hw->cut = false;
  rig.runTo(0.72);
  return rig.cell->observer()->estimate().mass_kg / rig.plant->model().state()(0) - 1.0;
}

TEST(AirbagOnHardware, GasTheTerminalPassedWhileTheLinkWasDownIsCounted) {
  // A lost link does not shut the valves: the terminal holds its outputs until its watchdog
  // trips. Filling at full inlet, 0.25 s of it is ~10 % of the gas; a driver that reports it
  // keeps the inventory (and the height estimate) right, else the cell fills on past its target.
  const double reported = gasErrorAfterAHeldLinkLoss(true);
  const double assumed_shut = gasErrorAfterAHeldLinkLoss(false);
  std::cout << "[airbag] gas error after a held link loss: reported " << 100.0 * reported << " %, taken as shut "
            << 100.0 * assumed_shut << " %\n";
  EXPECT_LE(std::fabs(reported), 0.01);
  EXPECT_LE(assumed_shut, -0.03) << "the case must be one a shut assumption gets wrong";
}

TEST(AirbagOnHardware, HoldsAPressureSetpointAndRefusesABadOne) {
  nb::AirbagCell cell{nb::AirbagCellParams{}};
  cell.resetToHeight(0.05, 15.6);
  EXPECT_NE(cell.requestPressure(-5.0, 0.0), "");
  EXPECT_NE(cell.requestPressure(std::nan(""), 0.0), "");
  EXPECT_EQ(cell.mode(), nb::AirbagMode::kHeight) << "a refused request changes nothing";
  ASSERT_EQ(cell.requestPressure(4000.0, 0.0), "");
  EXPECT_EQ(cell.mode(), nb::AirbagMode::kPressure);
  EXPECT_TRUE(std::isnan(cell.setpoint()));
  cell.advanceTo(8.0);
  EXPECT_NEAR(cell.variables().gauge_pressure_pa, 4000.0, 100.0);
  ASSERT_EQ(cell.requestHeight(0.05, 8.0), "");
  EXPECT_TRUE(std::isnan(cell.pressureSetpoint()));
}

/// A node restarted over a cell resting at `height_m` under `load_n`: the cell reset (the
/// observer flat), then commanded to 80 mm `command_s` later. Returns the true height 60 s
/// after the restart; `highest_m` the highest it reached, `vented` whether it vented to find
/// its gas.
double heightAfterARestart(double height_m, double load_n, double command_s, double* highest_m, bool* vented) {
  CuttableCell rig(height_m, load_n, 0.08);
  rig.cell->reset(load_n);
  *highest_m = 0.0;
  *vented = false;
  auto watch = [&] {
    *highest_m = std::max(*highest_m, rig.plant->variables().height_m);
    *vented = *vented || rig.cell->findingGas();
  };
  rig.runTo(command_s, watch);
  EXPECT_EQ(rig.cell->requestHeight(0.08, command_s), "");
  rig.runTo(60.0, watch);
  std::cout << "[airbag] restarted over " << load_n << " N at " << 1e3 * height_m << " mm, commanded after "
            << command_s << " s: " << (*vented ? "vented flat, " : "") << "true "
            << 1e3 * rig.plant->variables().height_m << " mm after 60 s (estimate "
            << 1e3 * rig.cell->observer()->estimate().height_m << "), highest " << 1e3 * *highest_m << " mm\n";
  return rig.plant->variables().height_m;
}

TEST(AirbagOnHardware, ANodeRestartedOverAnInflatedCellVentsItFlatBeforeControllingIt) {
  // Started flat, the observer counted every fill from nothing: commanded to 80 mm, a cell
  // already at 80 mm was filled to the bag's top at the supply pressure (140-150 mm, 20 kPa).
  for (const double load_n : {0.6, 15.6, 36.0}) {
    for (const double command_s : {0.0, 2.0}) {
      double highest_m = 0.0;
      bool vented = false;
      const double h = heightAfterARestart(0.08, load_n, command_s, &highest_m, &vented);
      EXPECT_TRUE(vented) << load_n << " N";
      EXPECT_NEAR(h, 0.08, 0.003) << load_n << " N";
      EXPECT_LE(highest_m, 0.085) << load_n << " N: never filled past its target";
    }
  }
  // Over a flat cell: found flat within half a second, a command after that fills at once.
  double highest_m = 0.0;
  bool vented = true;
  double h = heightAfterARestart(0.0, 15.6, 1.0, &highest_m, &vented);
  EXPECT_FALSE(vented);
  EXPECT_NEAR(h, 0.08, 0.003);
  // Commanded at once, it vents (flat already) until found so, then fills.
  h = heightAfterARestart(0.0, 15.6, 0.0, &highest_m, &vented);
  EXPECT_NEAR(h, 0.08, 0.003);
  EXPECT_LE(highest_m, 0.085);
}

namespace {

struct CycleResult {
  double top_error_m = 0.0;  ///< true minus estimated height, back at the top and held
  double lowest_m = 1.0;     ///< lowest true height over the cycle
  double low_error_m = 0.0;  ///< true minus estimated height in the low hold
  double low_m = 0.0;        ///< true height in the low hold
  int reanchors = 0;         ///< the observer's re-anchors over the cycle
};

/// A light cell without a height sensor at 120 mm whose observer vents 3 % more gas than the
/// valve passes (a miscalibrated vent area): lowered to `low_m` and held, then raised back to
/// 120 mm and held, with the gas check's reanchor_below_m `band_m`.
CycleResult lowAndBack(double low_m, double band_m, double recount_doubt_m = 0.0) {
  nb::AirbagObserverSetup setup;
  setup.gas_check.reanchor_below_m = band_m;
  setup.gas_check.recount_doubt_m = recount_doubt_m;
  setup.model.vent_area_m2 *= 1.03;
  CuttableCell rig(0.12, 0.6, 0.12, setup);
  CycleResult r;
  const int anchors_before = rig.cell->observer()->estimate().reanchors;
  auto watch = [&] { r.lowest_m = std::min(r.lowest_m, rig.plant->variables().height_m); };
  auto error = [&] { return rig.plant->variables().height_m - rig.cell->observer()->estimate().height_m; };
  rig.runTo(5.0, watch);
  EXPECT_EQ(rig.cell->requestHeight(low_m, rig.t), "");
  rig.runTo(60.0, watch);
  r.low_error_m = error();
  r.low_m = rig.plant->variables().height_m;
  EXPECT_EQ(rig.cell->requestHeight(0.12, rig.t), "");
  rig.runTo(100.0, watch);
  r.top_error_m = error();
  r.reanchors = rig.cell->observer()->estimate().reanchors - anchors_before;
  std::cout << "[airbag] 120 -> " << 1e3 * low_m << " -> 120 mm under 0.6 N, vent counted 3 % high, band "
            << 1e3 * band_m << " mm, recount doubt " << 1e3 * recount_doubt_m << " mm: lowest " << 1e3 * r.lowest_m
            << " mm, re-anchors " << r.reanchors << ", low hold at " << 1e3 * r.low_m << " mm (error "
            << 1e3 * r.low_error_m << " mm), back at the top error " << 1e3 * r.top_error_m << " mm\n";
  return r;
}

}  // namespace

TEST(AirbagOnHardware, ACellLoweredIntoTheLowBandPassesThroughFlatAndLeavesItsCountErrorThere) {
  // A descent's count error stays in the inventory, and near the top it is a large height
  // error: a plate alone at 120 mm moves 8-10 mm per 1 % of gas.
  const CycleResult kept = lowAndBack(0.03, 0.0);
  EXPECT_EQ(kept.reanchors, 0);
  EXPECT_GT(kept.lowest_m, 0.02);
  EXPECT_GT(kept.top_error_m, 0.005) << "the test's miscount must matter, else it shows nothing";
  // Lowered into the band, the cell vents flat, is re-anchored and filled to its target: the
  // vent's miscount is gone before the hold and the rise.
  const CycleResult anchored = lowAndBack(0.03, 0.035);
  EXPECT_EQ(anchored.reanchors, 1);
  EXPECT_LT(anchored.lowest_m, 0.002);
  EXPECT_NEAR(anchored.low_m, 0.03, 0.002);
  EXPECT_LT(std::abs(anchored.low_error_m), 0.001);
  EXPECT_LT(std::abs(anchored.top_error_m), 0.25 * kept.top_error_m);
  // Lowered to a height above the band, it keeps its gas.
  const CycleResult above = lowAndBack(0.05, 0.035);
  EXPECT_EQ(above.reanchors, 0);
  EXPECT_GT(above.lowest_m, 0.04);
}

/// A light cell (the plate alone) high in its bag, moved 8 mm up and down every 2 s for 2 min
/// as a plan's levelling moves the cells beside a body, its valves acting `offset_s` later than
/// the observer takes them to, with the gas check's recount_doubt_m.
struct LevellingResult {
  double worst_m = 0.0;        ///< largest |true - estimated height| after the first second
  double worst_doubt_m = 0.0;  ///< the observer's count doubt then
  int recounts = 0;
  double flat_s = 0.0;  ///< time the plate spent below 10 mm
};

LevellingResult levelling(double recount_doubt_m, double offset_s, double load_n = 0.6) {
  nb::AirbagCellParams p;
  p.control_period_s = 0.01;
  nb::AirbagObserverSetup setup;
  setup.gas_check.recount_doubt_m = recount_doubt_m;
  setup.params.valve_dead_time_s = 0.02;
  auto plant = rigWithoutHeightSensor(p, 0.13, load_n, 0.02 + offset_s);
  auto hw = std::make_shared<CuttableHardware>(plant);
  nb::AirbagCell cell(p, hw, setup);
  cell.resetToHeight(0.13, load_n);
  LevellingResult r;
  for (double t = 0.0; t < 120.0 - 1e-9; t += 0.01) {
    if (std::fmod(t + 1e-9, 2.0) < 0.01) {
      EXPECT_EQ(cell.requestHeight(std::fmod(t + 1e-9, 4.0) < 2.0 ? 0.122 : 0.13, t), "");
    }
    const bool recounting = cell.recountingGas();
    cell.advanceTo(t);
    if (cell.recountingGas() && !recounting) ++r.recounts;
    const double truth = plant->variables().height_m;
    if (truth < 0.01) r.flat_s += 0.01;
    const double error = std::fabs(truth - cell.observer()->estimate().height_m);
    if (t > 1.0 && error > r.worst_m) {
      r.worst_m = error;
      r.worst_doubt_m = cell.observer()->estimate().count_doubt_m;
    }
  }
  std::cout << "[airbag] " << load_n << " N levelled 122/130 mm for 2 min, valves " << 1e3 * offset_s
            << " ms late, recount doubt " << 1e3 * recount_doubt_m << " mm: worst error " << 1e3 * r.worst_m
            << " mm (doubt then " << 1e3 * r.worst_doubt_m << " mm), recounts " << r.recounts << ", flat for "
            << r.flat_s << " s\n";
  return r;
}

TEST(AirbagOnHardware, ALightCellWhoseVentCountIsDoubtfulIsReanchoredAtItsTarget) {
  // Each levelling move rings the light plate, whose swing the flows at the readings miss: the
  // counted gas drifts, and high in the bag 1 % of it is 5-15 mm. The count's doubt re-anchors it.
  const LevellingResult kept = levelling(0.0, 0.0);
  EXPECT_GT(kept.worst_m, 0.006) << "the drift must matter, else the test shows nothing";
  EXPECT_GT(kept.worst_doubt_m, kept.worst_m) << "the doubt covers the drift";
  const LevellingResult recounted = levelling(0.004, 0.0);
  EXPECT_GE(recounted.recounts, 1);
  EXPECT_LT(recounted.worst_m, 0.003);
  EXPECT_LT(recounted.flat_s, 0.2 * 120.0) << "a few seconds flat per re-anchoring";
  // A loaded cell (under the body) keeps its count: flat, it would let the body bottom out.
  const LevellingResult loaded = levelling(0.004, 0.0, 10.0);
  EXPECT_EQ(loaded.recounts, 0);
  EXPECT_EQ(loaded.flat_s, 0.0);
}

TEST(AirbagOnHardware, ACellRaisedOutOfTheLowBandBeforeItIsFoundFlatStopsVenting) {
  CuttableCell rig(0.12, 0.6, 0.12);  // the observer's defaults: reanchor_below_m 35 mm
  rig.runTo(1.0);
  EXPECT_EQ(rig.cell->requestHeight(0.03, rig.t), "");
  rig.runTo(2.0);
  EXPECT_TRUE(rig.cell->anchoringGas());
  EXPECT_TRUE(std::isfinite(rig.cell->heightSd())) << "its height is tracked while it vents";
  EXPECT_EQ(rig.cell->requestHeight(0.10, rig.t), "");
  EXPECT_FALSE(rig.cell->anchoringGas());
  rig.runTo(40.0);
  EXPECT_NEAR(rig.plant->variables().height_m, 0.10, 0.003);
}

TEST(AirbagOnHardware, GasCountedOverALostLinkIsTheCountsDoubt) {
  // A fill under way when the link goes: the terminal holds the inlet open until its watchdog
  // (0.1 s) and the driver says so, so the count is right, but it rests on that record alone.
  // The gas counted from the loss until 0.5 s after the link is back is the count's doubt.
  CuttableCell rig(0.06, 15.6, 0.06);
  rig.hw->hold_s = 0.1;
  rig.hw->reports_held = true;
  rig.runTo(2.0);
  const double quiet_doubt_m = rig.cell->observer()->estimate().count_doubt_m;
  ASSERT_EQ(rig.cell->requestHeight(0.10, rig.t), "");
  rig.runTo(2.05);
  rig.hw->cut = true;
  rig.runTo(2.5);
  rig.hw->cut = false;
  rig.runTo(6.0);
  const nb::CellEstimate e = rig.cell->observer()->estimate();
  std::cout << "[airbag] count doubt after a lost link during a fill: " << 1e3 * e.count_doubt_m << " mm (held "
            << 1e3 * quiet_doubt_m << " mm before), estimate " << 1e3 * e.height_m << " mm, truth "
            << 1e3 * rig.plant->variables().height_m << " mm\n";
  EXPECT_EQ(quiet_doubt_m, 0.0) << "a hold counts nothing";
  EXPECT_GT(e.count_doubt_m, 0.002) << "the inlet's held 0.1 s and the check's vent";
  EXPECT_TRUE(rig.cell->heightUnverified()) << "beyond flag_doubt_m: flagged";
  EXPECT_FALSE(rig.cell->gasVerifier().unproven()) << "the link check passed: still controlled";
  EXPECT_NEAR(rig.plant->variables().height_m, 0.10, 0.003);
}

TEST(AirbagOnHardware, GasCountedOverLatePeriodsIsTheCountsDoubt) {
  // A starved thread: for 1.2 s of a fill the cell's periods come 60 ms apart instead of 10.
  // The valves act for all of each period and the count takes its flows at the period's end:
  // what was counted then is the count's doubt (here it leaves the count millimetres off).
  double doubt_m[2] = {0.0, 0.0};
  bool flagged[2] = {false, false};
  double error_m[2] = {0.0, 0.0};
  for (int late = 0; late < 2; ++late) {
    CuttableCell rig(0.06, 15.6, 0.06);
    rig.runTo(1.0);
    ASSERT_EQ(rig.cell->requestHeight(0.10, rig.t), "");
    if (late == 1)
      for (int k = 0; k < 20; ++k) rig.cell->advanceTo(rig.t += 0.06);
    rig.runTo(6.0);
    const nb::CellEstimate e = rig.cell->observer()->estimate();
    doubt_m[late] = e.count_doubt_m;
    flagged[late] = rig.cell->heightUnverified();
    error_m[late] = std::fabs(e.height_m - rig.plant->variables().height_m);
  }
  std::cout << "[airbag] count doubt after a fill: " << 1e3 * doubt_m[0] << " mm on time, " << 1e3 * doubt_m[1]
            << " mm with 20 periods 60 ms late (estimate off by " << 1e3 * error_m[0] << " / " << 1e3 * error_m[1]
            << " mm)\n";
  EXPECT_LT(doubt_m[0], 0.0005) << "a fill on time: its few vent edges' doubt only";
  EXPECT_FALSE(flagged[0]);
  EXPECT_GT(doubt_m[1], 0.003) << "the late periods' gas, as height";
  EXPECT_TRUE(flagged[1]) << "beyond flag_doubt_m: flagged";
}

namespace {

/// A driver over a link that loses most of its replies (holdSamples()): down for a period,
/// then a new sample only every `each_s`, each repeated with its own stamp until the next.
class RepeatingHardware : public PressureOnlyHardware {
 public:
  using PressureOnlyHardware::PressureOnlyHardware;
  nb::CellReadings read(double now_s) override {
    nb::CellReadings r = PressureOnlyHardware::read(now_s);
    if (values_.empty()) return r;
    if (!flapped_) {  // one period down
      flapped_ = true;
      r = nb::CellReadings{};
      r.link = nb::LinkState::kDown;
      r.link_error = "no reply";
      return r;
    }
    if (!(now_s < sample_.stamp_s + each_s_)) {  // the next sample comes
      if (next_ == values_.size()) {
        values_.clear();
        return r;
      }
      sample_ = {values_[next_++], now_s};
    }
    r.gauge_pressure_pa = sample_;
    return r;
  }
  /// Serves `values_pa` (quantised noisy readings) in turn, each for `each_s`, then the plant's.
  void holdSamples(std::vector<double> values_pa, double each_s) {
    values_ = std::move(values_pa);
    each_s_ = each_s;
    next_ = 0;
    flapped_ = false;
    sample_ = {};
  }
  std::string describe() const override { return "repeating"; }

 private:
  std::vector<double> values_;
  double each_s_ = 0.0;
  std::size_t next_ = 0;
  bool flapped_ = false;
  nb::StampedReading sample_;
};

}  // namespace

TEST(AirbagOnHardware, ARepeatedSampleIsOneReadingNotAFlatCell) {
  // The plate alone held at 25 mm rests at about 23 Pa. Over a lossy link the driver repeats
  // its last sample until a new one comes: three low ones (0, 12, 0 Pa: a 12 Pa register step
  // and the sensor's noise), each taken again every period for 0.2 s, read as a flat cell: the
  // observer re-anchored the lifted plate at 0 and the next fill overshot.
  nb::AirbagCellParams p;
  p.control_period_s = 0.01;
  const nb::AirbagObserverSetup observer;
  auto plant = rigWithoutHeightSensor(p, 0.025, 0.6, observer.params.valve_dead_time_s);
  auto hw = std::make_shared<RepeatingHardware>(plant);
  nb::AirbagCell cell(p, hw, observer);
  cell.resetToHeight(0.025, 0.6);
  ASSERT_EQ(cell.requestHeight(0.025, 0.0), "");
  double t = 0.0;
  auto runTo = [&](double end_s, double* worst_m) {
    for (; t < end_s - 1e-9; t += 0.01) {
      cell.advanceTo(t);
      if (worst_m) *worst_m = std::max(*worst_m, std::fabs(cell.measurement().height_m - plant->variables().height_m));
    }
  };
  runTo(3.0, nullptr);
  const int anchors_before = cell.observer()->estimate().reanchors;
  hw->holdSamples({0.0, 12.0, 0.0}, 0.2);
  double worst_m = 0.0;
  runTo(6.0, &worst_m);
  std::cout << "[airbag] light plate at 25 mm after low samples repeated 0.6 s: worst estimate error " << 1e3 * worst_m
            << " mm, true height " << 1e3 * plant->variables().height_m << " mm\n";
  EXPECT_EQ(cell.observer()->estimate().reanchors, anchors_before) << "not found flat";
  EXPECT_LT(worst_m, 0.003);
  EXPECT_NEAR(plant->variables().height_m, 0.025, 0.003);
}
