// What keeps the fits fast without changing them (doc/gap_diagnosis.md, "Fitting the
// candidates"): the fit's results do not depend on how many threads replay, and a point already
// replayed is not replayed again; and the progress line's time left.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "nursing_bed/core/gap/diagnosis_stages.h"
#include "nursing_bed/core/gap/progress.h"
#include "nursing_bed/core/gap/synth.h"

namespace nb = nursing_bed;
namespace gs = nursing_bed::gap;

namespace {

/// The small protocol's runs with their roles, a leak of `leak_area_m2` in the cell.
std::vector<nb::RunData> runs(double leak_area_m2) {
  const nb::CellParams params;
  const nb::SynthProtocol protocol = nb::synthProtocol("small", params);
  std::mt19937 rng(3);
  std::vector<nb::RunData> out;
  for (const auto& spec : protocol.runs) {
    out.push_back(nb::simulateSynthRun(params, {nb::makeEffect("leak", {{"leak_area_m2", leak_area_m2}})}, protocol,
                                       spec, nb::SensorNoise{}, &rng));
    out.back().role = spec.role;
  }
  return out;
}

/// runs(1e-8) prepared and their noise model (default options), which points into them: not copied.
struct LeakingCell {
  const gs::PreparedRuns prepared = gs::prepareRuns(runs(1e-8));
  const gs::NoiseModel noise = gs::buildNoiseModel(prepared, nb::CellParams{}, nb::DiagnosisOptions{});
};

/// The same point, chi2 and replays.
void expectSameFit(const gs::FitOutcome& a, const gs::FitOutcome& b) {
  EXPECT_EQ(a.u, b.u);
  EXPECT_EQ(a.chi2, b.chi2);
  EXPECT_EQ(a.evaluations, b.evaluations);
}

}  // namespace

TEST(GapFitSpeed, AFitGivesTheSameResultWithOneThreadOrTwo) {
  const gs::PreparedRuns prepared = gs::prepareRuns(runs(1e-8));
  nb::DiagnosisOptions options;
  options.threads = 1;
  const gs::NoiseModel one = gs::buildNoiseModel(prepared, nb::CellParams{}, options);
  options.threads = 2;
  const gs::NoiseModel two = gs::buildNoiseModel(prepared, nb::CellParams{}, options);
  // Two effects: two Levenberg-Marquardt solves side by side, the Jacobian's columns together.
  const gs::ModelSpec model = gs::makeModelSpec({"leak", "heat_transfer"});
  const gs::FitOutcome a = gs::fitModel(one.fit, model, gs::gridStarts(model), 6);
  const gs::FitOutcome b = gs::fitModel(two.fit, model, gs::gridStarts(model), 6);
  ASSERT_TRUE(a.ok) << a.message;
  expectSameFit(a, b);
  EXPECT_LT(a.chi2, one.chi2_nominal);
}

TEST(GapFitSpeed, AStartTheGridProbeReplayedIsNotReplayedAgain) {
  const gs::PreparedRuns prepared = gs::prepareRuns(runs(1e-8));
  const gs::NoiseModel noise = gs::buildNoiseModel(prepared, nb::CellParams{}, nb::DiagnosisOptions{});
  const gs::ModelSpec leak = gs::makeModelSpec({"leak"});
  // No iteration: the start is probed (1 replay of the runs) and its Jacobian taken (1 more, the
  // start's residuals remembered from the probe).
  const gs::FitOutcome f = gs::fitModel(noise.fit, leak, {{0.5}}, 0);
  ASSERT_TRUE(f.ok) << f.message;
  EXPECT_EQ(f.evaluations, 2);
}

TEST(GapProgress, TheTimeLeftIsThePlannedWorkAtTheMeanCostSoFar) {
  gs::ProgressEstimate e;
  EXPECT_TRUE(std::isnan(e.secondsLeft(3.0)));
  EXPECT_NE(e.line(3.0).find("not yet known"), std::string::npos);
  e.start(5.0);  // the replays before the fits are not a unit of them
  e.plan(1, 2.0);
  e.plan(8, 1.0);
  e.done(2.0, 25.0);                            // 10 s a unit
  EXPECT_DOUBLE_EQ(e.secondsLeft(25.0), 80.0);  // 8 units left
  EXPECT_DOUBLE_EQ(e.secondsLeft(35.0), 70.0);  // the step under way has spent 10 s of it
  e.unplan(4, 1.0);                             // a stage that will not run
  EXPECT_DOUBLE_EQ(e.secondsLeft(25.0), 40.0);
  e.unplan(100, 1.0);  // never below what is done
  EXPECT_DOUBLE_EQ(e.secondsLeft(25.0), 0.0);
  EXPECT_EQ(e.line(25.0), "25 s elapsed, about 0 s left");
}

TEST(GapProgress, DurationsReadInSecondsThenHalfMinutes) {
  EXPECT_EQ(gs::roughDuration(0.4), "0 s");
  EXPECT_EQ(gs::roughDuration(45.0), "45 s");
  EXPECT_EQ(gs::roughDuration(89.0), "89 s");
  EXPECT_EQ(gs::roughDuration(150.0), "2.5 min");
  EXPECT_EQ(gs::roughDuration(1200.0), "20 min");
  EXPECT_EQ(gs::roughDuration(NAN), "?");
}

TEST(GapFitSpeed, ARepeatedStartIsSolvedOnce) {
  const LeakingCell cell;
  const gs::NoiseModel& noise = cell.noise;
  const gs::ModelSpec model = gs::makeModelSpec({"leak", "heat_transfer"});
  const std::vector<double> start{0.5, 0.5};
  const gs::FitOutcome once = gs::fitModel(noise.fit, model, {start}, 4);
  const gs::FitOutcome twice = gs::fitModel(noise.fit, model, {start, start}, 4);
  ASSERT_TRUE(once.ok) << once.message;
  expectSameFit(once, twice);
}

TEST(GapFitSpeed, TwoSolvesThatMeetGoOnAsTheLowerOne) {
  const LeakingCell cell;
  const gs::NoiseModel& noise = cell.noise;
  const gs::ModelSpec model = gs::makeModelSpec({"leak", "heat_transfer"});
  // Two starts 0.002 apart in each coordinate: the same basin from the first iteration.
  const std::vector<double> a{0.5, 0.5}, b{0.502, 0.498};
  const gs::FitOutcome fa = gs::fitModel(noise.fit, model, {a}, 6);
  const gs::FitOutcome fb = gs::fitModel(noise.fit, model, {b}, 6);
  const gs::FitOutcome both = gs::fitModel(noise.fit, model, {a, b}, 6);
  ASSERT_TRUE(fa.ok && fb.ok && both.ok);
  const gs::FitOutcome& lower = fa.chi2 <= fb.chi2 ? fa : fb;
  EXPECT_EQ(both.u, lower.u);
  EXPECT_EQ(both.chi2, lower.chi2);
  // The stopped solve spent its start only (and its probe), not its iterations.
  EXPECT_LT(both.evaluations, fa.evaluations + fb.evaluations);
}

TEST(GapFitSpeed, AFitThatCannotOvertakeStopsAndSaysSo) {
  const LeakingCell cell;
  const gs::NoiseModel& noise = cell.noise;
  const gs::ModelSpec model = gs::makeModelSpec({"heat_transfer"});
  const std::vector<std::vector<double>> starts{{0.9}};
  const gs::FitOutcome free = gs::fitModel(noise.fit, model, starts, 25);
  ASSERT_TRUE(free.ok) << free.message;
  EXPECT_FALSE(free.stopped);
  // A chi2 no fit of heat transfer reaches on a leaking cell: it stops within a few iterations.
  const gs::FitOutcome capped = gs::fitModel(noise.fit, model, starts, 25, 1e-3 * free.chi2);
  EXPECT_TRUE(capped.stopped);
  EXPECT_LE(capped.evaluations, free.evaluations);
  EXPECT_GE(capped.chi2, free.chi2);
  // A chi2 it already beats never stops it.
  const gs::FitOutcome reachable = gs::fitModel(noise.fit, model, starts, 25, 10.0 * free.chi2);
  EXPECT_FALSE(reachable.stopped);
  EXPECT_EQ(reachable.u, free.u);
}

TEST(GapFitSpeed, AStepCostsOneReplayAndAJacobianOnlyWhenTaken) {
  const LeakingCell cell;
  const gs::NoiseModel& noise = cell.noise;
  const gs::ModelSpec model = gs::makeModelSpec({"leak", "heat_transfer"});
  const std::vector<std::vector<double>> starts = gs::gridStarts(model);
  const gs::FitOutcome f = gs::fitModel(noise.fit, model, starts, 25);
  ASSERT_TRUE(f.ok) << f.message;
  // The grid probed once each; each of the two solves a Jacobian at its start (its residuals
  // remembered), then per iteration the step's replay, and a Jacobian where the step is taken;
  // a solve that ends on Ceres' tolerances ends on a step not counted as an iteration.
  // Ceres' default line search would replay a Jacobian at every trial along the step, too.
  const int k = static_cast<int>(model.axes.size());
  EXPECT_GT(f.iterations, 0);
  EXPECT_LE(f.evaluations, static_cast<int>(starts.size()) + 2 * (k + 1) + f.iterations * (k + 1))
      << f.iterations << " iterations: " << f.message;
}
