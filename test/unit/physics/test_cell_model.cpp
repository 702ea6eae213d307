// The control-volume cell model: conservation, adiabatic law, effect hooks, convergence.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "nursing_bed/core/physics/basic_effects.h"
#include "nursing_bed/core/physics/cell_model.h"
#include "nursing_bed/core/physics/time_series.h"

namespace nb = nursing_bed;

namespace {

nb::CellInputs closedInputs(double load) {
  nb::CellInputs in;
  in.load_n = load;
  return in;
}

TEST(CellModel, FlatCellStartsAtAmbient) {
  nb::CellModel m{nb::CellParams{}};
  m.reset(0.6);
  const nb::CellVariables& v = m.variables();
  EXPECT_NEAR(v.gauge_pressure_pa, 0.0, 1e-6);
  EXPECT_NEAR(v.temperature_k, 293.15, 1e-9);
  EXPECT_LE(v.height_m, 0.0);
  EXPECT_NEAR(v.bed_contact_force_n, 0.6, 1e-9);  // the bed carries the plate
}

TEST(CellModel, ClosedCellConservesMass) {
  // Valves shut, plate dropped from one load to a heavier one: it bounces and settles, the gas
  // is squeezed, but no mass may appear or vanish.
  nb::CellModel m{nb::CellParams{}};
  m.resetToEquilibrium(0.12, 10.6);
  const double m0 = m.variables().mass_kg;
  m.advance(2.0, closedInputs(20.6));
  EXPECT_NEAR(m.variables().mass_kg, m0, 1e-9 * m0);
  EXPECT_LT(m.variables().height_m, 0.12);  // it did compress
}

TEST(CellModel, AdiabaticCompressionFollowsPoissonsLaw) {
  // Paper eq. 13: p V^gamma = const for the closed adiabatic cell, whatever the plate does.
  nb::CellModel m{nb::CellParams{}};
  m.resetToEquilibrium(0.12, 10.6);
  const double gamma = m.params().gas.heat_capacity_ratio;
  auto invariant = [&]() {
    const nb::CellVariables& v = m.variables();
    return v.pressure_pa * std::pow(v.structure.volume_m3, gamma);
  };
  const double c0 = invariant();
  const double v0 = m.variables().structure.volume_m3;
  // Load ramps 10.6 -> 20.6 N over 1 s, then holds.
  for (int i = 1; i <= 1500; ++i) {
    const double t = i * 1e-3;
    m.advance(1e-3, closedInputs(10.6 + 10.0 * std::min(t, 1.0)));
    ASSERT_NEAR(invariant(), c0, 1e-6 * c0) << "t " << t;
  }
  EXPECT_LT(m.variables().structure.volume_m3, 0.995 * v0);  // a real compression happened
}

TEST(CellModel, ZeroEffectsGiveBackTheNominalModelExactly) {
  nb::CellParams params;
  nb::CellModel nominal(params), with_effects(params);
  with_effects.addEffect(std::make_shared<nb::HeatTransferEffect>(0.0));
  with_effects.addEffect(std::make_shared<nb::LeakEffect>(0.0));
  nominal.reset(10.6);
  with_effects.reset(10.6);
  nb::CellInputs in = closedInputs(10.6);
  in.inlet_opening = 1.0;
  nominal.advance(3.0, in);
  with_effects.advance(3.0, in);
  EXPECT_EQ(nominal.variables().height_m, with_effects.variables().height_m);
  EXPECT_EQ(nominal.variables().pressure_pa, with_effects.variables().pressure_pa);
}

// Inflate for 5.5 s at 15.6 N, then hold closed for `hold_s`; returns the model.
nb::CellModel inflateAndHold(const nb::CellEffectPtr& effect, double hold_s) {
  nb::CellModel m{nb::CellParams{}};
  if (effect) m.addEffect(effect);
  m.reset(15.6);
  nb::CellInputs in = closedInputs(15.6);
  in.inlet_opening = 1.0;
  m.advance(5.5, in);
  in.inlet_opening = 0.0;
  m.advance(hold_s, in);
  return m;
}

TEST(CellModel, HeatTransferCoolsTheGasAndLowersThePressureAtHold) {
  const nb::CellModel adiabatic = inflateAndHold(nullptr, 30.0);
  const nb::CellModel cooled = inflateAndHold(std::make_shared<nb::HeatTransferEffect>(10.0), 30.0);
  // Compression heated the adiabatic gas; exchange brings it back to ambient.
  EXPECT_GT(adiabatic.variables().temperature_k, 298.0);
  EXPECT_NEAR(cooled.variables().temperature_k, 293.15, 0.2);
  EXPECT_LT(cooled.variables().gauge_pressure_pa, adiabatic.variables().gauge_pressure_pa - 300.0);
  // Signature: with the inlet closed the cooled cell's pressure relaxes to a lower plateau.
  const nb::CellModel cooled_early = inflateAndHold(std::make_shared<nb::HeatTransferEffect>(10.0), 0.5);
  EXPECT_LT(cooled.variables().gauge_pressure_pa, cooled_early.variables().gauge_pressure_pa - 300.0);
  const nb::CellModel adiabatic_early = inflateAndHold(nullptr, 0.5);
  EXPECT_NEAR(adiabatic.variables().gauge_pressure_pa, adiabatic_early.variables().gauge_pressure_pa, 50.0);
}

TEST(CellModel, LeakDrainsTheCellDuringHold) {
  const nb::CellModel sealed = inflateAndHold(nullptr, 20.0);
  const nb::CellModel leaky = inflateAndHold(std::make_shared<nb::LeakEffect>(1e-7), 20.0);
  EXPECT_LT(leaky.variables().mass_kg, 0.9 * sealed.variables().mass_kg);
  EXPECT_LT(leaky.variables().height_m, sealed.variables().height_m);
}

TEST(CellModel, HalvingTheStepChangesTheHeightAt5p5sByLessThanATenthMm) {
  for (double load : {0.6, 15.6}) {
    double heights[2];
    for (int k = 0; k < 2; ++k) {
      nb::CellParams params;
      params.time_step_s = k == 0 ? 2e-3 : 1e-3;
      nb::CellModel m(params);
      m.reset(load);
      nb::CellInputs in = closedInputs(load);
      in.inlet_opening = 1.0;
      m.advance(5.5, in);
      heights[k] = m.variables().height_m;
    }
    EXPECT_LT(std::abs(heights[0] - heights[1]), 1e-4) << "load " << load;
  }
}

TEST(CellModel, VentingLowersTheCell) {
  nb::CellModel m{nb::CellParams{}};
  m.resetToEquilibrium(0.14, 15.6);
  nb::CellInputs in = closedInputs(15.6);
  in.vent_opening = 1.0;
  m.advance(10.0, in);
  EXPECT_LT(m.variables().height_m, 0.01);
  EXPECT_LT(m.variables().gauge_pressure_pa, 1500.0);
}

TEST(CellModel, ReplayingTheInflowOfAValveRunReproducesIt) {
  // The paper's way: drive the model with a measured inflow curve. Replaying the inflow a
  // valve-driven run produced must give the same cell back.
  nb::CellParams params;
  nb::CellModel valve_run(params);
  valve_run.reset(10.6);
  nb::CellInputs in = closedInputs(10.6);
  in.inlet_opening = 1.0;
  std::vector<double> t{0.0}, q{valve_run.variables().inflow_kg_s}, h{valve_run.variables().height_m};
  for (int i = 1; i <= 400; ++i) {
    valve_run.advance(0.01, in);
    t.push_back(valve_run.time());
    q.push_back(valve_run.variables().inflow_kg_s);
    h.push_back(valve_run.variables().height_m);
  }
  const nb::TimeSeries inflow(t, q);
  nb::CellModel replay(params);
  replay.reset(10.6);
  nb::CellInputs rin = closedInputs(10.6);
  rin.prescribed_inflow = &inflow;
  double worst = 0.0;
  for (int i = 1; i <= 400; ++i) {
    replay.advance(0.01, rin);
    worst = std::max(worst, std::abs(replay.variables().height_m - h[i]));
  }
  EXPECT_LT(worst, 2e-3);  // 10 ms samples of a 2.5 g/s flow
  EXPECT_NEAR(replay.variables().mass_kg, valve_run.variables().mass_kg, 0.01 * valve_run.variables().mass_kg);
}

// Largest difference between the model's Jacobian and central differences of its rate, each
// entry scaled by its state's typical size and by the largest scaled entry of its row. The
// differences are small enough to resolve the folded flat cell (a 1 nm step of the plate there
// changes the pressure by under 1 Pa, within the orifices' smoothing band).
double jacobianMismatch(const nb::CellModel& m, const nb::CellInputs& in) {
  const nb::CellModel::StateVector x = m.state();
  const int n = m.stateSize();
  const nb::CellModel::StateMatrix model = m.jacobian(m.time(), x, in);
  nb::CellModel::StateMatrix reference(n, n);
  std::vector<double> scale(n, 1e-3);
  const double typical[] = {1e-4, 10.0, 1e-2, 1.0, 1e3, 1.0};
  for (int j = 0; j < n && j < 6; ++j) scale[j] = typical[j];
  for (int j = 0; j < n; ++j) {
    const double d = 1e-7 * std::max(std::fabs(x[j]), scale[j]);
    nb::CellModel::StateVector up = x, down = x;
    up[j] += d;
    down[j] -= d;
    reference.col(j) = (m.rate(m.time(), up, in) - m.rate(m.time(), down, in)) / (2.0 * d);
  }
  double worst = 0.0;
  for (int i = 0; i < n; ++i) {
    double row = 1e-300;
    for (int j = 0; j < n; ++j) row = std::max(row, std::fabs(reference(i, j)) * scale[j]);
    for (int j = 0; j < n; ++j) worst = std::max(worst, std::fabs(model(i, j) - reference(i, j)) * scale[j] / row);
  }
  return worst;
}

TEST(CellModel, JacobianMatchesFiniteDifferencesOfTheRate) {
  nb::CellModel lifting{nb::CellParams{}};
  lifting.reset(0.6);
  nb::CellInputs fill = closedInputs(0.6);
  fill.inlet_opening = 1.0;
  EXPECT_LT(jacobianMismatch(lifting, fill), 1e-4) << "flat, on the bed";
  lifting.advance(0.4, fill);
  EXPECT_LT(jacobianMismatch(lifting, fill), 1e-4) << "lifting off";

  nb::CellModel holding{nb::CellParams{}};
  holding.resetToEquilibrium(0.10, 15.6);
  nb::CellInputs ajar = closedInputs(15.6);
  ajar.inlet_opening = 0.02;
  ajar.vent_opening = 0.01;
  EXPECT_LT(jacobianMismatch(holding, ajar), 1e-4) << "holding, valves ajar";
  nb::CellInputs vacuum = closedInputs(15.6);
  vacuum.vent_opening = 1.0;
  vacuum.vent_back_pressure_pa = -5000.0;
  EXPECT_LT(jacobianMismatch(holding, vacuum), 1e-4) << "venting to vacuum";
  // The regulator's outlet (a state) just above the cell: the inlet within its smoothing band;
  // then below it: gas back out through the inlet.
  const double held_pa = holding.variables().gauge_pressure_pa;
  nb::CellInputs inlet_open = closedInputs(15.6);
  inlet_open.inlet_opening = 1.0;
  for (double regulator_pa : {held_pa + 0.4 * holding.params().orifice_linear_band_pa, held_pa - 3000.0}) {
    nb::CellModel m = holding;
    nb::CellModel::StateVector x = m.state();
    x[nb::CellModel::kRegulator] = regulator_pa;
    m.setState(m.time(), x);
    inlet_open.supply_pressure_pa = regulator_pa;
    EXPECT_LT(jacobianMismatch(m, inlet_open), 1e-4) << "regulator at " << regulator_pa << " Pa";
  }
  nb::CellInputs backflow = closedInputs(15.6);  // the vent's far side above the cell
  backflow.vent_opening = 1.0;
  backflow.vent_back_pressure_pa = held_pa + 2000.0;
  EXPECT_LT(jacobianMismatch(holding, backflow), 1e-4) << "back in through the vent";
  nb::CellInputs metered_out = closedInputs(15.6);
  metered_out.prescribed_inflow_kg_s = -1e-3;
  EXPECT_LT(jacobianMismatch(holding, metered_out), 1e-4) << "a metered outflow";

  nb::CellModel with_effects{nb::CellParams{}};
  with_effects.addEffect(std::make_shared<nb::HeatTransferEffect>(10.0));
  with_effects.addEffect(std::make_shared<nb::LeakEffect>(2e-9));
  with_effects.resetToEquilibrium(0.10, 15.6, 310.0);
  EXPECT_LT(jacobianMismatch(with_effects, ajar), 1e-4) << "with heat transfer and a leak";
}

// The cell at `height_m`, moving at `velocity_m_s`, its gas at `gauge_pa` and room temperature
// (film at rest, regulator at its setting): a state the integrator may meet on either side of
// flat, set directly.
nb::CellModel cellAt(double height_m, double velocity_m_s, double gauge_pa, double load_n) {
  nb::CellModel m{nb::CellParams{}};
  m.reset(load_n);
  nb::CellModel::StateVector x = m.state();
  const nb::GasProperties& gas = m.params().gas;
  const double volume = m.structure().evaluate(height_m, x.data() + nb::CellModel::kShape).volume_m3;
  const double temperature = 293.15;
  const double mass = nb::massFromState(gas, m.params().ambient_pressure_pa + gauge_pa, temperature, volume);
  x[nb::CellModel::kMass] = mass;
  x[nb::CellModel::kEnergy] = mass * gas.cv() * temperature;
  x[nb::CellModel::kHeight] = height_m;
  x[nb::CellModel::kVelocity] = velocity_m_s;
  x[nb::CellModel::kRegulator] = m.params().supply_pressure_pa;
  m.setState(0.0, x);
  return m;
}

TEST(CellModel, JacobianMatchesFiniteDifferencesAboveAndBelowFlat) {
  // Below flat the folds' gas is squeezed out (dV/dh = A_eff, dA_eff/dh = A_eff / delta, so
  // dp/dh = -p A_eff / V) and the bed pushes back with F = -k h (1 - alpha v): in contact
  // dF/dh = -k (1 - alpha v) and dF/dv = k alpha h; a plate rising faster than 1 / alpha
  // leaves the bed behind (F = 0) while still below flat.
  const double load = 20.6;
  nb::CellInputs fill = closedInputs(load);
  fill.inlet_opening = 1.0;
  nb::CellInputs vacuum = closedInputs(load);
  vacuum.vent_opening = 1.0;
  vacuum.vent_back_pressure_pa = -5000.0;
  const nb::PillowParams pillow;
  const double flat_area = std::pow(pillow.face_side_m + pillow.gusset_height_m, 2);
  const double depth = pillow.fold_fraction * pillow.dead_volume_m3 / flat_area;  // the folds', 47 um
  const double alpha = nb::CellParams{}.bed_contact_damping_s_m;
  struct Case {
    double height_m, velocity_m_s;
    bool contact;
  };
  const Case cases[] = {{2e-3, -0.05, false},
                        {2e-3, 0.05, false},
                        {-0.2 * depth, -0.02, true},
                        {-0.2 * depth, 0.3 / alpha, true},
                        {-0.2 * depth, 2.0 / alpha, false},
                        {-4.0 * depth, -0.01, true},
                        {-4.0 * depth, 0.5 / alpha, true},
                        {-4.0 * depth, 3.0 / alpha, false}};
  for (const Case& c : cases) {
    for (double gauge : {300.0, 5000.0}) {
      const nb::CellModel m = cellAt(c.height_m, c.velocity_m_s, gauge, load);
      const std::string where = "h " + std::to_string(c.height_m * 1e6) + " um, v " + std::to_string(c.velocity_m_s) +
                                " m/s, " + std::to_string(gauge) + " Pa";
      ASSERT_EQ(m.variables().bed_contact_force_n > 0.0, c.contact) << where;
      EXPECT_LT(jacobianMismatch(m, fill), 1e-4) << where << ", filling";
      EXPECT_LT(jacobianMismatch(m, vacuum), 1e-4) << where << ", venting to vacuum";
    }
  }
}

TEST(CellModel, TimeDerivativeMatchesDifferencesOfTheRateInTime) {
  // A metered series in and out; inside a segment the rate is linear in time, so central
  // differences are exact up to rounding. Without effects the series' slope, with them a
  // difference of the whole rate.
  const nb::TimeSeries series({0.0, 0.1, 0.2, 0.3}, {0.0, 2e-3, -1e-3, 5e-4});
  for (bool with_effect : {false, true}) {
    nb::CellModel m{nb::CellParams{}};
    if (with_effect) m.addEffect(std::make_shared<nb::HeatTransferEffect>(10.0));
    m.resetToEquilibrium(0.10, 15.6, 300.0);
    nb::CellInputs in = closedInputs(15.6);
    in.prescribed_inflow = &series;
    for (double t : {0.05, 0.13, 0.17, 0.26}) {
      const double d = 1e-4;
      const nb::CellModel::StateVector reference =
          (m.rate(t + d, m.state(), in) - m.rate(t - d, m.state(), in)) / (2.0 * d);
      const nb::CellModel::StateVector ft = m.timeDerivative(t, m.state(), in);
      const std::string where = std::string(with_effect ? "with" : "without") + " an effect, t " + std::to_string(t);
      EXPECT_NEAR(ft[nb::CellModel::kMass], reference[nb::CellModel::kMass], 1e-6 * std::fabs(reference[0])) << where;
      EXPECT_NEAR(ft[nb::CellModel::kEnergy], reference[nb::CellModel::kEnergy], 1e-6 * std::fabs(reference[1]))
          << where;
      EXPECT_LT((ft - reference).tail(ft.size() - 2).cwiseAbs().maxCoeff(), 1e-9) << where;
    }
    EXPECT_EQ(m.timeDerivative(0.5, m.state(), in)[nb::CellModel::kMass], 0.0);  // after the series
    // At a sample, and a rounding short of it, the slope the step goes on with.
    EXPECT_NEAR(m.timeDerivative(0.1, m.state(), in)[nb::CellModel::kMass], -3e-2, 1e-6);
    EXPECT_NEAR(m.timeDerivative(0.1 - 1e-15, m.state(), in)[nb::CellModel::kMass], -3e-2, 1e-6);
  }
}

TEST(CellModel, AdvanceTakesLongerStepsWhileTheCellHolds) {
  nb::CellModel m{nb::CellParams{}};
  m.resetToEquilibrium(0.10, 15.6);
  nb::CellInputs ajar = closedInputs(15.6);
  ajar.inlet_opening = 0.02;
  ajar.vent_opening = 0.01;
  m.advance(1.0, ajar);
  // At most max_time_step_s per step, and far fewer steps than the default step would take.
  EXPECT_GE(m.substeps(), static_cast<long>(1.0 / m.params().max_time_step_s));
  EXPECT_LT(m.substeps(), static_cast<long>(0.25 / m.params().time_step_s));
}

// The slow end of a vent through the open inlet, sampled every 50 ms while advance() takes long
// steps: the pressure follows a tightly integrated run to a few pascals, without the step-to-step
// ringing of stiff modes that a stale Jacobian leaves undamped (tens of pascals).
TEST(CellModel, LongStepsFollowTheSlowEndOfAVentWithoutRinging) {
  auto vent = [](double relative_tolerance) {
    nb::CellParams params;
    params.regulator_time_constant_s = 0.0;
    params.relative_tolerance = relative_tolerance;
    nb::CellModel m(params);
    m.resetToEquilibrium(0.14, 15.6);
    nb::CellInputs in = closedInputs(15.6);
    in.inlet_opening = 1.0;
    in.supply_pressure_pa = 0.0;
    std::vector<double> p;
    for (int i = 1; i <= 84; ++i) {
      m.advance(i * 0.05 - m.time(), in);
      p.push_back(m.variables().gauge_pressure_pa);
    }
    return p;
  };
  const std::vector<double> run = vent(1e-4), exact = vent(1e-8);
  ASSERT_GT(exact.back(), 300.0);  // still venting slowly at the last sample
  for (std::size_t i = 40; i < run.size(); ++i) EXPECT_NEAR(run[i], exact[i], 8.0) << "sample " << i;
}

// advance() keeps the rate at the state between calls while the inputs stay the same; a new
// pressure for the orifices (an observer's reading) is a new input, so the next call's first
// sub-step vents at it. The reference takes the same first call with inputs that give the same
// rate but compare unequal (the supply setting spelled out), so its second call starts afresh.
TEST(CellModel, AdvanceVentsAtANewlyGivenFlowPressureFromTheFirstSubStep) {
  auto run = [](bool spelled_out_supply) {
    nb::CellModel m{nb::CellParams{}};
    m.resetToEquilibrium(0.10, 15.6);
    nb::CellInputs in = closedInputs(15.6);
    in.vent_opening = 1.0;
    in.flow_gauge_pressure_pa = 0.0;  // no flow through the vent over the first call
    if (spelled_out_supply) in.supply_pressure_pa = m.params().supply_pressure_pa;
    m.advance(0.005, in);
    in.supply_pressure_pa = std::nan("");
    in.flow_gauge_pressure_pa = 5000.0;
    m.advance(0.005, in);
    return m.variables().mass_kg;
  };
  const double kept = run(false), afresh = run(true);
  EXPECT_NEAR(kept, afresh, 1e-12 * afresh);
}

TEST(CellModel, InvalidParametersAreRefusedByName) {
  nb::CellParams params;
  params.inlet_area_m2 = -1.0;
  params.time_step_s = 0.0;
  try {
    nb::CellModel m(params);
    FAIL() << "expected std::invalid_argument";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("inlet_area_m2"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("time_step_s"), std::string::npos);
  }
}

}  // namespace
