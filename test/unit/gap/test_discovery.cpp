// Discovery for what no candidate explains (discovery.h, discovery_terms.h): the dictionary's
// terms and their units, the sparse selection by stability across resamples, and end to end on
// the small protocol: a velocity-squared drag and a leak with a pressure exponent, planted outside
// both the effect and the distortion lists, are discovered with a term of the right form; clean
// data is not.
#include <gtest/gtest.h>

#include <Eigen/Core>

#include <cmath>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "nursing_bed/core/gap/diagnosis.h"
#include "nursing_bed/core/gap/diagnosis_stages.h"
#include "nursing_bed/core/gap/discovery.h"
#include "nursing_bed/core/gap/discovery_terms.h"
#include "nursing_bed/core/gap/effects.h"
#include "nursing_bed/core/gap/synth.h"
#include "nursing_bed/core/physics/cell_model.h"

#include "../../test_helpers.h"
#include "small_protocol_runs.h"

namespace nb = nursing_bed;
namespace gs = nursing_bed::gap;

namespace {

nb::CellVariables someState() {
  nb::CellVariables c;
  c.velocity_m_s = -0.04;
  c.height_m = 0.12;
  c.gauge_pressure_pa = 8000.0;
  c.temperature_k = 305.0;
  return c;
}

nb::EffectTerms termsOf(const std::string& name, double coefficient) {
  const nb::CellParams params;
  const std::string key = nb::effectSpec(name).params.front().name;
  const nb::CellEffectPtr e = nb::makeEffect(name, {{key, coefficient}});
  nb::EffectTerms t;
  e->contribute(params, someState(), nullptr, &t, nullptr);
  return t;
}

TEST(DiscoveryDictionary, EveryTermHasAUnitAnOffValueAndCorrectsOneBalance) {
  ASSERT_GE(nb::discoveryDictionary().size(), 8u);
  ASSERT_EQ(nb::discoveryCatalog().size(), nb::discoveryDictionary().size());
  for (const auto& e : nb::discoveryCatalog()) {
    SCOPED_TRACE(e.name);
    EXPECT_FALSE(e.candidate);
    ASSERT_EQ(e.params.size(), 1u);
    EXPECT_FALSE(e.params[0].unit.empty());
    EXPECT_EQ(e.params[0].off_value, 0.0);
    const nb::EffectTerms off = termsOf(e.name, 0.0);
    EXPECT_EQ(off.plate_force_n, 0.0);
    EXPECT_EQ(off.mass_flow_kg_s, 0.0);
    EXPECT_EQ(off.heat_flow_w, 0.0);
    const nb::EffectTerms on = termsOf(e.name, e.params[0].hi);
    const int balances = (on.plate_force_n != 0.0) + (on.mass_flow_kg_s != 0.0) + (on.heat_flow_w != 0.0);
    EXPECT_EQ(balances, 1) << "a term corrects exactly one balance";
  }
}

TEST(DiscoveryDictionary, AVelocitySquaredTermAddsItsCoefficientTimesAbsVTimesVToThePlateForce) {
  const nb::EffectTerms t = termsOf("discovered_plate_abs_v_v", -400.0);
  EXPECT_DOUBLE_EQ(t.plate_force_n, -400.0 * 0.04 * -0.04);
  const nb::EffectTerms leak = termsOf("discovered_mass_p", -2e-10);
  EXPECT_DOUBLE_EQ(leak.mass_flow_kg_s, -2e-10 * 8000.0);
  EXPECT_LT(leak.enthalpy_flow_w, 0.0) << "gas leaving carries its enthalpy";
}

TEST(DiscoveryDictionary, TheEquationNamesBalanceCoefficientUnitAndFunction) {
  const nb::DictionaryTerm* term = nb::dictionaryTerm("discovered_plate_abs_v_v");
  ASSERT_NE(term, nullptr);
  EXPECT_EQ(nb::termEquation(*term, -420.0), "plate force: −420 N·s²/m² · |v|v");
  EXPECT_EQ(nb::dictionaryTerm("leak"), nullptr);
}

TEST(DiscoveryDictionary, ACoefficientOutsideItsAdmissibleRangeIsRefusedByName) {
  const auto& spec = nb::effectSpec("discovered_plate_v");
  const std::string key = spec.params[0].name;
  try {
    nb::makeEffect("discovered_plate_v", {{key, 1e3 * spec.params[0].max_value}});
    FAIL() << "no exception";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find(key), std::string::npos) << e.what();
  }
  EXPECT_THROW(nb::makeEffect("discovered_plate_v", {{key, NAN}}), std::invalid_argument);
}

TEST(DiscoveryDictionary, GapSynthRefusesToPlantADictionaryTermAsAnEffect) {
  std::vector<std::string> names;
  std::vector<std::map<std::string, double>> params;
  std::vector<nb::CellEffectPtr> effects;
  EXPECT_THROW(nb::resolveSynthEffects({nb::parseEffectRequest("discovered_plate_v")}, 1, &names, &params, &effects),
               std::invalid_argument);
  EXPECT_TRUE(effects.empty());
}

// ---- selection ----------------------------------------------------------------------------------

/// Residuals r0 = -a J_k + noise of unit variance, n rows, 5 columns of independent noise.
struct LinearCase {
  Eigen::MatrixXd J;
  Eigen::VectorXd r0;
};

LinearCase linearCase(int planted, double amplitude, std::uint32_t seed) {
  const int n = 2000;
  std::mt19937 rng(seed);
  std::normal_distribution<double> normal;
  LinearCase c{Eigen::MatrixXd(n, 5), Eigen::VectorXd(n)};
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < 5; ++j) c.J(i, j) = normal(rng);
    c.r0(i) = normal(rng);
  }
  if (planted >= 0) c.r0 -= amplitude * c.J.col(planted);
  return c;
}

std::vector<std::pair<int, int>> blocksOf(int n, int size) {
  std::vector<std::pair<int, int>> b;
  for (int i = 0; i < n; i += size) b.emplace_back(i, std::min(n, i + size));
  return b;
}

TEST(DiscoverySelection, ForwardSelectionFindsThePlantedColumnAndNothingInNoise) {
  const double penalty = std::log(2000.0) + 20.0;
  const Eigen::VectorXd ones = Eigen::VectorXd::Ones(2000);
  const LinearCase planted = linearCase(3, 0.5, 1);
  EXPECT_EQ(gs::forwardSelect(planted.J, planted.r0, ones, penalty, 3), std::vector<int>{3});
  const LinearCase noise = linearCase(-1, 0.0, 2);
  EXPECT_TRUE(gs::forwardSelect(noise.J, noise.r0, ones, penalty, 3).empty());
}

std::vector<int> countsOver(const LinearCase& c, const std::vector<Eigen::VectorXd>& weights, double penalty) {
  std::vector<int> counts(c.J.cols(), 0);
  for (const auto& w : weights)
    for (int j : gs::forwardSelect(c.J, c.r0, w, penalty, 3)) ++counts[j];
  return counts;
}

TEST(DiscoverySelection, ABlockBootstrapDrawsAsManyBlocksAsThereAreWithReplacement) {
  const auto weights = gs::blockBootstrap(blocksOf(2000, 100), 2000, 20, 5);
  ASSERT_EQ(weights.size(), 20u);
  bool some_block_twice = false;
  for (const auto& w : weights) {
    EXPECT_DOUBLE_EQ(w.sum(), 2000.0);
    for (int b = 0; b < 2000; b += 100) {
      EXPECT_EQ(w.segment(b, 100).minCoeff(), w.segment(b, 100).maxCoeff()) << "a block is drawn whole";
      some_block_twice = some_block_twice || w(b) >= 2.0;
    }
  }
  EXPECT_TRUE(some_block_twice);
}

TEST(DiscoverySelection, APlantedTermIsStableAcrossResamplesAndNoiseIsNot) {
  const double penalty = std::log(2000.0) + 20.0;
  const auto weights = gs::blockBootstrap(blocksOf(2000, 100), 2000, 20, 5);
  const std::vector<int> counts = countsOver(linearCase(1, 0.5, 3), weights, penalty);
  EXPECT_EQ(counts[1], 20);
  for (int j : {0, 2, 3, 4}) EXPECT_LT(counts[j], 16) << "column " << j;
  for (int c : countsOver(linearCase(-1, 0.0, 4), weights, penalty)) EXPECT_LT(c, 16);
}

TEST(DiscoverySelection, TheBestSingleTermLeavesTheLeastAndOnlyIfItIsSignificant) {
  std::mt19937 rng(6);
  std::normal_distribution<double> normal;
  const int n = 1000;
  Eigen::VectorXd noise(n), signal(n);
  for (int i = 0; i < n; ++i) {
    noise(i) = normal(rng);
    signal(i) = 3.0 * std::sin(2.0 * M_PI * i / 100.0);  // whole periods: no mean a constant slope takes
  }
  // Term 0 removes the signal at its fit; term 1 leaves it; neither moves much around its fit.
  std::vector<gs::SingleTermFit> singles(2);
  singles[0].residuals = noise;
  singles[1].residuals = noise + signal;
  for (auto& f : singles) {
    f.slope = Eigen::VectorXd::Constant(n, 1e-3);
    f.ok = true;
  }
  const Eigen::VectorXd ones = Eigen::VectorXd::Ones(n);
  const double penalty = std::log(1000.0) + 20.0;
  EXPECT_EQ(gs::bestSingleTerm(singles, noise + signal, ones, penalty), 0);
  EXPECT_EQ(gs::bestSingleTerm(singles, noise + 0.05 * signal, ones, penalty), -1) << "a drop below the penalty";
  singles[0].ok = false;
  EXPECT_EQ(gs::bestSingleTerm(singles, noise + signal, ones, penalty), -1) << "a failed fit is never selected";
}

// ---- end to end (small protocol) -----------------------------------------------------------------

nb::DiagnosisOptions fastOptions() {
  nb::DiagnosisOptions o;
  o.candidates = {"leak", "plate_friction"};
  o.pair_pool = 0;
  return o;
}

std::vector<nb::RunData> smallRuns(const std::vector<nb::CellEffectPtr>& effects, std::uint32_t seed) {
  return nb::test::smallProtocolRuns(effects, seed);
}

nb::DiagnosisReport diagnose(const std::vector<nb::CellEffectPtr>& planted, std::uint32_t seed) {
  const nb::DiagnosisReport r = nb::diagnoseRuns(smallRuns(planted, seed), nb::CellParams{}, fastOptions());
  std::cout << "             status " << r.status << ", withheld nrmse " << r.withheld_before << " -> "
            << r.withheld_after << "\n";
  for (const auto& line : r.reasons)
    if (line.rfind("discover", 0) == 0) std::cout << "             " << line << "\n";
  return r;
}

TEST(DiscoveryEndToEnd, AVelocitySquaredDragOnThePlateIsDiscoveredAsAnAbsVTimesVTerm) {
  const nb::DiagnosisReport r =
      diagnose({nb::makeEffect("plate_quadratic_drag", {{"drag_coefficient_n_s2_m2", 1500.0}})}, 11);
  EXPECT_EQ(r.status, "discovered");
  ASSERT_EQ(r.verdict_effects, std::vector<std::string>{"discovered_plate_abs_v_v"});
  const double c = r.verdict_params.at("plate_abs_v_v_coefficient");
  EXPECT_GT(c, -1500.0 * 1.5);
  EXPECT_LT(c, -1500.0 / 1.5);
  ASSERT_EQ(r.discovered.size(), 1u);
  EXPECT_NE(r.discovered[0].find("plate force: −"), std::string::npos) << r.discovered[0];
  EXPECT_NE(r.discovered[0].find("N·s²/m² · |v|v, stable in"), std::string::npos) << r.discovered[0];
  EXPECT_LT(r.withheld_after, 0.5 * r.withheld_before);
}

TEST(DiscoveryEndToEnd, ALeakWithAPressureExponentIsDiscoveredAsAGasMassTerm) {
  const nb::DiagnosisReport r =
      diagnose({nb::makeEffect("power_leak", {{"leak_flow_kg_s", 3e-6}, {"exponent", 1.5}})}, 12);
  EXPECT_EQ(r.status, "discovered");
  ASSERT_FALSE(r.verdict_effects.empty());
  for (const auto& e : r.verdict_effects) EXPECT_EQ(e.rfind("discovered_mass_", 0), 0u) << e;
  for (const auto& [key, c] : r.verdict_params) EXPECT_LT(c, 0.0) << key << ": a leak takes gas out";
  EXPECT_LT(r.withheld_after, 0.5 * r.withheld_before);
}

TEST(DiscoveryEndToEnd, CleanRunsDiscoverNothingEvenWhenAsked) {
  for (std::uint32_t seed : {21u, 22u}) {
    const gs::PreparedRuns prepared = gs::prepareRuns(smallRuns({}, seed));
    const nb::CellParams params;
    const nb::DiagnosisOptions options = fastOptions();
    const gs::NoiseModel noise = gs::buildNoiseModel(prepared, params, options);
    const gs::DiscoveryResult d = gs::discoverTerms(prepared, noise, params, {}, options, nullptr);
    EXPECT_FALSE(d.discovered) << "seed " << seed;
    EXPECT_TRUE(d.terms.empty());
    EXPECT_EQ(d.resamples, 20);
    EXPECT_EQ(d.selected.size(), nb::discoveryDictionary().size());
  }
}

}  // namespace
