// Candidate effects of the gap diagnosis: off == nominal bit for bit, each effect's signature in a
// short run of the run-data protocol, the catalogue and the factory's refusals.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <set>

#include "nursing_bed/core/gap/effects.h"
#include "nursing_bed/core/physics/cell_model.h"
#include "nursing_bed/core/physics/paper_experiment.h"

namespace nb = nursing_bed;

namespace {

struct Sample {
  double t;
  nb::CellVariables v;
  nb::Readings m;
  nb::CellModel::StateVector x;
};

struct Protocol {
  double load_n = 15.6;
  double mass_kg = 3.4e-3;  // ~145 mm at rest under 15.6 N
  double inflate_s = 5.5;
  double hold_s = 20.0;
  double vent_s = 5.0;
  double sample_s = 0.05;
  double relative_tolerance = nb::CellParams{}.relative_tolerance;  // the integrator's
};

// The run-data protocol: paper-shaped prescribed inflow, inlet closed, then vent through the
// fully open inlet to a supply at 0 gauge (valve-driven).
std::vector<Sample> runProtocol(const std::vector<nb::CellEffectPtr>& effects, const Protocol& pr = Protocol{}) {
  nb::CellParams params;
  params.regulator_time_constant_s = 0.0;
  params.relative_tolerance = pr.relative_tolerance;
  nb::CellModel model(params);
  for (const auto& e : effects) model.addEffect(e);
  model.reset(pr.load_n);
  const nb::TimeSeries inflow = nb::paperShapedInflow(pr.mass_kg, 1.0, pr.inflate_s, 0.01);
  std::vector<Sample> out;
  auto record = [&]() { out.push_back({model.time(), model.variables(), model.measure(), model.state()}); };
  record();
  const long n = std::lround((pr.inflate_s + pr.hold_s + pr.vent_s) / pr.sample_s);
  nb::CellInputs in;
  in.load_n = pr.load_n;
  for (long i = 1; i <= n; ++i) {
    const double t = i * pr.sample_s;
    in.prescribed_inflow = nullptr;
    in.inlet_opening = 0.0;
    in.supply_pressure_pa = NAN;
    if (t <= pr.inflate_s + 1e-9) {
      in.prescribed_inflow = &inflow;
    } else if (t > pr.inflate_s + pr.hold_s + 1e-9) {
      in.inlet_opening = 1.0;
      in.supply_pressure_pa = 0.0;
    }
    model.advance(t - model.time(), in);
    record();
  }
  return out;
}

nb::CellEffectPtr effect(const std::string& name, const std::map<std::string, double>& params) {
  return nb::makeEffect(name, params);
}

// Sample nearest to time t.
const Sample& at(const std::vector<Sample>& s, double t) {
  std::size_t best = 0;
  for (std::size_t i = 0; i < s.size(); ++i)
    if (std::fabs(s[i].t - t) < std::fabs(s[best].t - t)) best = i;
  return s[best];
}

void expectIdentical(const std::vector<Sample>& a, const std::vector<Sample>& b, const std::string& what) {
  ASSERT_EQ(a.size(), b.size()) << what;
  for (std::size_t i = 0; i < a.size(); ++i) {
    ASSERT_EQ(a[i].x.size(), b[i].x.size()) << what;
    for (int k = 0; k < a[i].x.size(); ++k)
      ASSERT_EQ(a[i].x[k], b[i].x[k]) << what << " t " << a[i].t << " state " << k;
    ASSERT_EQ(a[i].m.gauge_pressure_pa, b[i].m.gauge_pressure_pa) << what << " t " << a[i].t;
    ASSERT_EQ(a[i].m.height_m, b[i].m.height_m) << what << " t " << a[i].t;
    ASSERT_EQ(a[i].m.inflow_kg_s, b[i].m.inflow_kg_s) << what << " t " << a[i].t;
    ASSERT_EQ(a[i].m.gas_temperature_k, b[i].m.gas_temperature_k) << what << " t " << a[i].t;
  }
}

const std::vector<Sample>& nominal() {
  static const std::vector<Sample> s = runProtocol({});
  return s;
}

// ---- catalogue and factory -------------------------------------------------------------------

TEST(GapEffects, CatalogueHasTheSevenCandidatesAndFourOutOfLibraryEffects) {
  const std::vector<std::string> expected = {"heat_transfer",       "leak",        "membrane_viscoelasticity",
                                             "pressure_sensor_lag", "supply_line", "inflow_bias",
                                             "plate_friction"};
  EXPECT_EQ(nb::candidateEffectNames(), expected);
  EXPECT_FALSE(nb::effectSpec("ambient_drift").candidate);
  EXPECT_FALSE(nb::effectSpec("pressure_offset_drift").candidate);
  EXPECT_FALSE(nb::effectSpec("plate_quadratic_drag").candidate);
  EXPECT_FALSE(nb::effectSpec("power_leak").candidate);
  EXPECT_EQ(nb::effectCatalog().size(), 11u);
  for (const auto& e : nb::effectCatalog()) {
    EXPECT_FALSE(e.params.empty()) << e.name;
    if (!e.switch_param.empty()) {
      EXPECT_NE(e.param(e.switch_param), nullptr) << e.name;
    }
    for (const auto& p : e.params) {
      SCOPED_TRACE(e.name + "/" + p.name);
      EXPECT_LT(p.lo, p.hi);
      EXPECT_LE(p.min_value, p.off_value);
      EXPECT_GE(p.max_value, p.off_value);
      if (p.log_scale) {
        EXPECT_GT(p.lo, 0.0);
      }
      const double lo = p.symmetric ? -p.hi : p.lo;
      EXPECT_LE(p.min_value, lo);
      EXPECT_GE(p.max_value, p.hi);
      EXPECT_FALSE(p.unit.empty());
    }
    // The effect built from its off values and from drawn values has the right name/params.
    const nb::CellEffectPtr off = nb::makeEffect(e.name, e.offParams());
    EXPECT_EQ(off->name(), e.name);
    EXPECT_EQ(off->parameters(), e.offParams());
    EXPECT_EQ(off->stateSize(), 0) << e.name << ": off must carry no state";
  }
}

TEST(GapEffects, RandomParametersStayInTheirPlausibleRange) {
  std::mt19937 rng(42);
  for (const auto& e : nb::effectCatalog()) {
    std::map<std::string, std::vector<double>> draws;
    for (int i = 0; i < 2000; ++i) {
      const auto params = nb::randomEffectParams(e.name, rng);
      ASSERT_EQ(params.size(), e.params.size());
      for (const auto& [k, v] : params) draws[k].push_back(v);
      ASSERT_NO_THROW(nb::makeEffect(e.name, params)) << e.name;
    }
    for (const auto& p : e.params) {
      SCOPED_TRACE(e.name + "/" + p.name);
      std::vector<double>& d = draws[p.name];
      int negative = 0;
      for (double v : d) {
        const double mag = p.symmetric ? std::fabs(v) : v;
        ASSERT_GE(mag, p.lo);
        ASSERT_LE(mag, p.hi);
        negative += v < 0.0;
      }
      if (p.symmetric) {
        EXPECT_NEAR(negative / 2000.0, 0.5, 0.05);
      }
      // Log-uniform: the median sits at the geometric mean; uniform: at the mean.
      std::sort(d.begin(), d.end());
      const double median = p.symmetric ? 0.0 : d[d.size() / 2];
      if (p.log_scale) {
        EXPECT_NEAR(std::log(median), 0.5 * (std::log(p.lo) + std::log(p.hi)), 0.1 * std::log(p.hi / p.lo));
      } else if (!p.symmetric) {
        EXPECT_NEAR(median, 0.5 * (p.lo + p.hi), 0.1 * (p.hi - p.lo));
      }
    }
  }
}

void expectRefused(const std::string& name, const std::map<std::string, double>& params,
                   const std::vector<std::string>& fragments) {
  try {
    nb::makeEffect(name, params);
    ADD_FAILURE() << "accepted " << nb::describeEffect(name, params);
  } catch (const std::invalid_argument& e) {
    for (const auto& f : fragments) EXPECT_NE(std::string(e.what()).find(f), std::string::npos) << e.what();
  }
}

TEST(GapEffects, FactoryRefusesBadNamesAndParameters) {
  expectRefused("leek", {{"leak_area_m2", 1e-9}}, {"unknown effect 'leek'", "leak", "supply_line"});
  expectRefused("leak", {{"leak_area", 1e-9}}, {"effect 'leak'", "unknown parameter 'leak_area'", "leak_area_m2"});
  expectRefused("leak", {}, {"effect 'leak'", "missing parameter 'leak_area_m2'"});
  expectRefused("leak", {{"leak_area_m2", -1e-9}}, {"leak_area_m2", "-1e-09", "admissible range"});
  expectRefused("leak", {{"leak_area_m2", NAN}}, {"leak_area_m2", "nan"});
  expectRefused("heat_transfer", {{"heat_transfer_coefficient_w_m2_k", INFINITY}},
                {"heat_transfer_coefficient_w_m2_k", "inf"});
  expectRefused("supply_line", {{"line_volume_m3", 1e-5}}, {"missing parameter 'line_area_m2'"});
  expectRefused("supply_line", {{"line_volume_m3", 1e-5}, {"line_area_m2", 0.0}}, {"line_area_m2", "admissible"});
  expectRefused("membrane_viscoelasticity", {{"relaxation_time_s", 0.0}, {"relative_stiffness", 0.1}},
                {"relaxation_time_s"});
  expectRefused("inflow_bias", {{"scale_error", 0.1}, {"offset_kg_s", 0.0}, {"offset", 1.0}},
                {"unknown parameter 'offset'"});
  // Values between the off value and the plausible range are admissible (a fit may go there).
  EXPECT_NO_THROW(nb::makeEffect("leak", {{"leak_area_m2", 1e-12}}));
  EXPECT_NO_THROW(nb::makeEffect("pressure_sensor_lag", {{"time_constant_s", 0.01}}));
}

// ---- off == nominal, bit for bit -------------------------------------------------------------

TEST(GapEffects, EveryEffectOffGivesTheNominalModelBitForBit) {
  for (const auto& e : nb::effectCatalog()) {
    expectIdentical(runProtocol({effect(e.name, e.offParams())}), nominal(), e.name + " off");
    // The switch parameter alone turns it off, whatever the other parameters say.
    if (!e.switch_param.empty() && e.params.size() > 1) {
      std::mt19937 rng(7);
      auto params = nb::randomEffectParams(e.name, rng);
      params[e.switch_param] = e.param(e.switch_param)->off_value;
      expectIdentical(runProtocol({effect(e.name, params)}), nominal(), e.name + " switched off");
    }
  }
  // All of them at once.
  std::vector<nb::CellEffectPtr> all;
  for (const auto& e : nb::effectCatalog()) all.push_back(effect(e.name, e.offParams()));
  expectIdentical(runProtocol(all), nominal(), "all off");
}

// ---- signatures ------------------------------------------------------------------------------

constexpr double kHoldStart = 5.5, kHoldEnd = 25.5;

TEST(GapEffects, HeatTransferRelaxesThePressureToALowerPlateauAfterInflow) {
  const auto s = runProtocol({effect("heat_transfer", {{"heat_transfer_coefficient_w_m2_k", 10.0}})});
  const double p0 = at(s, kHoldStart).v.gauge_pressure_pa, p_end = at(s, kHoldEnd).v.gauge_pressure_pa;
  const double p_late = at(s, kHoldEnd - 5.0).v.gauge_pressure_pa;
  EXPECT_LT(p_end, p0 - 300.0);                               // relaxes down...
  EXPECT_LT(std::fabs(p_end - p_late), 0.05 * (p0 - p_end));  // ...to a plateau
  EXPECT_NEAR(at(s, kHoldEnd).v.temperature_k, 293.15, 0.2);
  // Nominal (adiabatic): flat hold.
  EXPECT_NEAR(at(nominal(), kHoldEnd).v.gauge_pressure_pa, at(nominal(), kHoldStart).v.gauge_pressure_pa, 5.0);
}

TEST(GapEffects, LeakMakesPressureAndHeightFallDuringHold) {
  const auto s = runProtocol({effect("leak", {{"leak_area_m2", 5e-9}})});
  const Sample &a = at(s, kHoldStart + 1.0), &mid = at(s, kHoldStart + 10.0), &b = at(s, kHoldEnd);
  EXPECT_LT(b.v.mass_kg, a.v.mass_kg * 0.995);
  // Both keep falling through the hold.
  EXPECT_LT(mid.m.height_m, a.m.height_m - 1e-4);
  EXPECT_LT(b.m.height_m, mid.m.height_m - 1e-4);
  EXPECT_LT(mid.m.gauge_pressure_pa, a.m.gauge_pressure_pa - 50.0);
  EXPECT_LT(b.m.gauge_pressure_pa, mid.m.gauge_pressure_pa - 50.0);
}

TEST(GapEffects, ViscoelasticFilmCreepsAtConstantMass) {
  const auto s =
      runProtocol({effect("membrane_viscoelasticity", {{"relaxation_time_s", 5.0}, {"relative_stiffness", 0.3}})});
  const Sample &a = at(s, kHoldStart + 0.5), &b = at(s, kHoldEnd);
  const Sample &na = at(nominal(), kHoldStart + 0.5), &nb_ = at(nominal(), kHoldEnd);
  EXPECT_EQ(a.v.mass_kg, b.v.mass_kg);  // closed: constant mass
  // The film creeps (its stretch grows at constant mass), so the height creeps up and,
  // near full height where the geometry pins the height, the pressure relaxes markedly.
  EXPECT_GT(b.v.shape[0] - a.v.shape[0], 1e-3);
  EXPECT_GT(b.m.height_m - a.m.height_m, 1e-4);
  EXPECT_LT(b.m.gauge_pressure_pa, a.m.gauge_pressure_pa - 1000.0);
  EXPECT_LT(std::fabs(nb_.m.height_m - na.m.height_m), 2e-5);
  EXPECT_LT(std::fabs(nb_.m.gauge_pressure_pa - na.m.gauge_pressure_pa), 5.0);
  // The internal stretch catches up with the film.
  const int internal = static_cast<int>(b.x.size()) - 1;
  EXPECT_LT(std::fabs(b.x[internal] - b.v.shape[0]), 0.2 * std::fabs(a.x[internal] - a.v.shape[0]));
  // Loading/unloading loops differ: while loading fast the film is stiffer (less stretched)
  // than the elastic film at the same time.
  EXPECT_LT(at(s, 3.0).v.shape[0], at(nominal(), 3.0).v.shape[0] - 1e-3);
}

TEST(GapEffects, SensorLagDelaysTheMeasuredPressure) {
  const double tau = 0.3;
  const auto s = runProtocol({effect("pressure_sensor_lag", {{"time_constant_s", tau}})});
  // The reading is the true pressure through a first-order filter: filter the true samples
  // (exact for a piecewise-linear input) and compare.
  double filtered = s.front().v.gauge_pressure_pa, largest_lag = 0.0;
  for (std::size_t i = 1; i < s.size(); ++i) {
    const double h = s[i].t - s[i - 1].t;
    const double p0 = s[i - 1].v.gauge_pressure_pa, p1 = s[i].v.gauge_pressure_pa;
    const double slope = (p1 - p0) / h;
    filtered = p1 - tau * slope + (filtered - p0 + tau * slope) * std::exp(-h / tau);
    const double lag = p1 - s[i].m.gauge_pressure_pa;
    largest_lag = std::max(largest_lag, lag);
    ASSERT_NEAR(s[i].m.gauge_pressure_pa, filtered, 10.0 + 0.02 * std::fabs(lag)) << "t " << s[i].t;
  }
  EXPECT_GT(largest_lag, 2000.0);  // rising pressure reads low, worst where dp/dt is large
  EXPECT_NEAR(at(s, kHoldStart + 3.0).m.gauge_pressure_pa, at(s, kHoldStart + 3.0).v.gauge_pressure_pa, 1.0);
  // The true cell is the nominal one. The lag's state joins the step control, so the two runs
  // take different steps; each is accurate to the integrator's relative tolerance (1e-4 of
  // 1 cm + h per step in height), so they agree to a micron, not to the last digits.
  EXPECT_NEAR(at(s, 10.0).v.height_m, at(nominal(), 10.0).v.height_m, 1e-6);
}

TEST(GapEffects, SupplyLineReadsHighWhileFlowingAndDropsWhenTheFlowStops) {
  // Integrated to 1e-7: the gas balance below compares two runs to 1e-4 of the line's gas
  // (5e-10 kg, 1.5e-7 of the cell's), finer than two runs at the default tolerance agree.
  Protocol tight;
  tight.relative_tolerance = 1e-7;
  const auto s = runProtocol({effect("supply_line", {{"line_volume_m3", 2e-5}, {"line_area_m2", 4e-6}})}, tight);
  const auto reference = runProtocol({}, tight);  // the nominal cell
  // Inflow peak near 1 s: the line reads well above the cell.
  EXPECT_GT(at(s, 1.0).m.gauge_pressure_pa - at(s, 1.0).v.gauge_pressure_pa, 300.0);
  // Flow stopped: the line equalises with the cell.
  EXPECT_NEAR(at(s, kHoldStart + 1.0).m.gauge_pressure_pa, at(s, kHoldStart + 1.0).v.gauge_pressure_pa, 2.0);
  // Venting through the line: it reads low, and the meter reads the flow out of the line.
  const Sample& v = at(s, kHoldEnd + 0.3);
  EXPECT_LT(v.m.gauge_pressure_pa, v.v.gauge_pressure_pa - 300.0);
  EXPECT_LT(v.m.inflow_kg_s, -1e-4);
  // The line delays the cell: less gas reached it by 0.5 s than without the line.
  EXPECT_LT(at(s, 0.5).v.mass_kg, at(reference, 0.5).v.mass_kg);
  // Once equalised, the cell holds the metered gas less what pressurises the line.
  const nb::CellParams params;
  const Sample& h = at(s, kHoldStart + 1.0);
  const double in_line = 2e-5 * h.m.gauge_pressure_pa / (params.gas.gas_constant_j_kg_k * params.supply_temperature_k);
  EXPECT_NEAR(h.v.mass_kg + in_line, at(reference, kHoldStart + 1.0).v.mass_kg, 1e-4 * in_line);
}

TEST(GapEffects, PlateFrictionShiftsThePressureAgainstTheMotion) {
  const double fc = 2.0;
  const auto s = runProtocol({effect("plate_friction", {{"friction_force_n", fc}})});
  // Gas force minus load while the plate moves: + F_c rising, - F_c falling (on top of the
  // guide's viscous damping and inertia, which the nominal run has too).
  auto meanOffset = [](const std::vector<Sample>& run, bool rising) {
    double sum = 0.0;
    int n = 0;
    for (const auto& x : run) {
      const double v = x.v.velocity_m_s;
      if ((rising && v > 0.01) || (!rising && v < -0.01 && x.v.height_m > 0.01)) {
        sum += x.v.gauge_pressure_pa * x.v.structure.effective_area_m2 - x.v.load_n -
               20.0 * v;  // guide damping of CellParams
        ++n;
      }
    }
    return n > 0 ? sum / n : std::nan("");
  };
  EXPECT_NEAR(meanOffset(s, true), fc, 0.3 * fc);
  EXPECT_NEAR(meanOffset(s, false), -fc, 0.3 * fc);
  EXPECT_NEAR(meanOffset(nominal(), true), 0.0, 0.3);
  // h(p) loop: at the same height, rising reads higher than falling by about 2 F_c / A_eff.
  auto pressureAtHeight = [](const std::vector<Sample>& run, double h, bool rising) {
    for (std::size_t i = 1; i < run.size(); ++i) {
      const double h0 = run[i - 1].v.height_m, h1 = run[i].v.height_m;
      if (rising ? (h0 < h && h1 >= h) : (h0 > h && h1 <= h)) {
        const double f = (h - h0) / (h1 - h0);
        return run[i - 1].v.gauge_pressure_pa + f * (run[i].v.gauge_pressure_pa - run[i - 1].v.gauge_pressure_pa);
      }
    }
    return std::nan("");
  };
  const double loop_friction = pressureAtHeight(s, 0.08, true) - pressureAtHeight(s, 0.08, false);
  const double loop_nominal = pressureAtHeight(nominal(), 0.08, true) - pressureAtHeight(nominal(), 0.08, false);
  EXPECT_GT(loop_friction - loop_nominal, 2.0 * fc / 0.03);
}

// Long holding and venting steps keep their Jacobian while its secant test passes. With stiff,
// nonlinear effects plugged in (the friction's tanh in the plate's speed, a film relaxing with
// its own state), a kept Jacobian that no longer damps their modes leaves the pressure ringing
// by tens of pascals; the run follows a tightly integrated one as closely as with a fresh
// Jacobian on every long step (the default tolerance's own error, well below the ringing).
TEST(GapEffects, KeptJacobiansFollowStiffEffectsWithoutRinging) {
  auto run = [](double relative_tolerance) {
    Protocol pr;
    pr.relative_tolerance = relative_tolerance;
    return runProtocol({effect("plate_friction", {{"friction_force_n", 2.0}}),
                        effect("membrane_viscoelasticity", {{"relaxation_time_s", 5.0}, {"relative_stiffness", 0.3}}),
                        effect("heat_transfer", {{"heat_transfer_coefficient_w_m2_k", 10.0}})},
                       pr);
  };
  const auto s = run(nb::CellParams{}.relative_tolerance), exact = run(1e-8);
  ASSERT_EQ(s.size(), exact.size());
  double worst = 0.0;
  for (std::size_t i = 0; i < s.size(); ++i)
    if (s[i].t > kHoldStart + 0.5)
      worst = std::max(worst, std::fabs(s[i].v.gauge_pressure_pa - exact[i].v.gauge_pressure_pa));
  EXPECT_LT(worst, 16.0);
}

TEST(GapEffects, InflowBiasMassErrorGrowsWithIntegratedFlow) {
  const double k = 0.1;
  const auto s = runProtocol({effect("inflow_bias", {{"scale_error", k}, {"offset_kg_s", 0.0}})});
  // Prescribed (metered) inflow: the cell got 1/(1+k) of it; the error grows with the
  // integrated flow.
  const double m0 = nominal().front().v.mass_kg;
  for (double t : {1.0, 2.0, 5.5}) {
    const double metered = at(nominal(), t).v.mass_kg - m0;
    const double received = at(s, t).v.mass_kg - m0;
    EXPECT_NEAR(received, metered / (1.0 + k), 1e-3 * metered) << "t " << t;
  }
  // Valve-driven (vent): the meter reads (1 + k) q_true.
  const Sample& v = at(s, kHoldEnd + 0.5);
  EXPECT_NEAR(v.m.inflow_kg_s, (1.0 + k) * v.v.inflow_kg_s, 1e-12);
  // An offset: a closed inlet reads b, and a prescribed series carrying b is corrected.
  const double b = 1e-5;
  const auto o = runProtocol({effect("inflow_bias", {{"scale_error", 0.0}, {"offset_kg_s", b}})});
  EXPECT_EQ(at(o, kHoldStart + 2.0).m.inflow_kg_s, b);
  EXPECT_NEAR(at(o, 5.5).v.mass_kg - m0, at(nominal(), 5.5).v.mass_kg - m0 - b * 5.5, 1e-8);
}

TEST(GapEffects, AmbientDriftMovesThePressureDuringHold) {
  // Against the same exchange with fixed surroundings (heat_transfer at 8 W/(m^2 K)), the
  // pressure drifts with the sign of the drift, more and more.
  const auto fixed = runProtocol({effect("heat_transfer", {{"heat_transfer_coefficient_w_m2_k", 8.0}})});
  for (double r : {0.05, -0.05}) {
    const auto s = runProtocol({effect("ambient_drift", {{"drift_k_s", r}})});
    auto excess = [&](double t) { return at(s, t).m.gauge_pressure_pa - at(fixed, t).m.gauge_pressure_pa; };
    EXPECT_NEAR(excess(0.5), 0.0, 5.0);
    EXPECT_GT(excess(kHoldStart + 5.0) * r, 0.0) << "drift " << r;
    EXPECT_GT(excess(kHoldEnd) * r, 2.0 * excess(kHoldStart + 5.0) * r) << "drift " << r;
    EXPECT_GT(std::fabs(excess(kHoldEnd)), 100.0) << "drift " << r;
  }
}

TEST(GapEffects, PressureOffsetDriftAddsAReadingGrowingWithTime) {
  const auto s = runProtocol({effect("pressure_offset_drift", {{"drift_pa_s", 3.0}})});
  for (double t : {1.0, 10.0, 28.0}) {
    const Sample& x = at(s, t);
    EXPECT_NEAR(x.m.gauge_pressure_pa - x.v.gauge_pressure_pa, 3.0 * t, 1e-6);
    EXPECT_EQ(x.v.height_m, at(nominal(), t).v.height_m);
  }
}

TEST(GapEffects, EffectsCombine) {
  std::vector<nb::CellEffectPtr> all;
  std::mt19937 rng(3);
  for (const auto& e : nb::effectCatalog()) all.push_back(effect(e.name, nb::randomEffectParams(e.name, rng)));
  const auto s = runProtocol(all);
  for (const auto& x : s) {
    ASSERT_TRUE(x.x.allFinite()) << "t " << x.t;
    ASSERT_TRUE(std::isfinite(x.m.gauge_pressure_pa) && std::isfinite(x.m.inflow_kg_s));
  }
  EXPECT_GT(at(s, kHoldStart).v.height_m, 0.08);
  // Pressure readings compose: lag and line and drift add their deviations.
  const auto lag_line = runProtocol({effect("pressure_sensor_lag", {{"time_constant_s", 0.2}}),
                                     effect("supply_line", {{"line_volume_m3", 2e-5}, {"line_area_m2", 4e-6}})});
  const auto line_lag = runProtocol({effect("supply_line", {{"line_volume_m3", 2e-5}, {"line_area_m2", 4e-6}}),
                                     effect("pressure_sensor_lag", {{"time_constant_s", 0.2}})});
  EXPECT_NEAR(at(lag_line, 2.0).m.gauge_pressure_pa, at(line_lag, 2.0).m.gauge_pressure_pa, 1.0);
}

TEST(GapEffects, FlowReadingsComposeInCatalogueOrder) {
  // Valve-driven throughout (inflate from the regulator, then vent), so inflow_bias changes only
  // the reading: with a supply line, the meter (upstream of the line) must read
  // (1 + k) q_line + b whatever order the effects were given in.
  auto run = [](std::vector<nb::CellEffectPtr> effects) {
    nb::sortEffectsForModel(&effects);
    nb::CellParams params;
    params.regulator_time_constant_s = 0.0;
    nb::CellModel m(params);
    for (const auto& e : effects) m.addEffect(e);
    m.reset(10.6);
    nb::CellInputs in;
    in.load_n = 10.6;
    in.inlet_opening = 1.0;
    std::vector<double> q;
    for (int i = 0; i < 80; ++i) {
      if (i == 50) in.supply_pressure_pa = 0.0;  // vent back through the inlet
      m.advance(0.05, in);
      q.push_back(m.measure().inflow_kg_s);
    }
    return q;
  };
  const auto line = effect("supply_line", {{"line_volume_m3", 2e-5}, {"line_area_m2", 4e-6}});
  const auto bias = effect("inflow_bias", {{"scale_error", 0.1}, {"offset_kg_s", 2e-6}});
  std::vector<nb::CellEffectPtr> order = {bias, line};
  nb::sortEffectsForModel(&order);
  EXPECT_EQ(order[0]->name(), "supply_line");
  const auto q_line = run({line});
  const auto q_both = run({bias, line});
  double q_min = 0.0, q_max = 0.0;
  for (std::size_t i = 0; i < q_line.size(); ++i) {
    EXPECT_NEAR(q_both[i], 1.1 * q_line[i] + 2e-6, 1e-12) << "sample " << i;
    q_min = std::min(q_min, q_line[i]);
    q_max = std::max(q_max, q_line[i]);
  }
  EXPECT_GT(q_max, 5e-4);   // it did inflate...
  EXPECT_LT(q_min, -1e-4);  // ...and vent
}

}  // namespace
