// The Rosenbrock step's linear algebra: W = I - gamma h J solved exactly, with the plate's and
// the regulator's rows eliminated first where J has their pattern, and whole where it does not.
#include <gtest/gtest.h>

#include <random>

#include "nursing_bed/core/physics/step_matrix.h"

namespace nb = nursing_bed;

namespace {

constexpr int kN = nb::StepMatrix::kNominalStates;

// A dense Jacobian of the cell's nominal size; with `pattern`, its height row is dh/dt = v and
// its regulator row the regulator's own lag, as CellModel's.
nb::CellStateMatrix randomJacobian(std::mt19937* rng, bool pattern) {
  std::normal_distribution<double> normal(0.0, 200.0);
  nb::CellStateMatrix j(kN, kN);
  for (int r = 0; r < kN; ++r)
    for (int c = 0; c < kN; ++c) j(r, c) = normal(*rng);
  if (pattern) {
    j.row(2).setZero();
    j(2, 3) = 1.0;
    j.row(4).setZero();
    j(4, 4) = -1.0 / 1.2;
  }
  return j;
}

TEST(StepMatrix, SolvesTheStepSystemWithAndWithoutThePlatesPattern) {
  std::mt19937 rng(7);
  std::normal_distribution<double> normal(0.0, 1.0);
  for (bool pattern : {true, false}) {
    for (int trial = 0; trial < 50; ++trial) {
      const nb::CellStateMatrix j = randomJacobian(&rng, pattern);
      const double gamma_h = 1.7071 * 0.02;
      nb::StepMatrix w;
      w.factor(j, gamma_h);
      nb::StepMatrix::NominalVector b;
      for (int i = 0; i < kN; ++i) b[i] = normal(rng);
      const nb::StepMatrix::NominalMatrix dense =
          nb::StepMatrix::NominalMatrix::Identity() - gamma_h * j.topLeftCorner<kN, kN>();
      const nb::StepMatrix::NominalVector x = w.solveNominal(b);
      EXPECT_LT((dense * x - b).norm(), 1e-9 * (1.0 + dense.norm() * x.norm()))
          << (pattern ? "with" : "without") << " the pattern, trial " << trial;
      const nb::CellStateVector y = w.solve(nb::CellStateVector(b));
      EXPECT_LT((y - nb::CellStateVector(x)).norm(), 1e-12 * (1.0 + x.norm()));
    }
  }
}

}  // namespace
