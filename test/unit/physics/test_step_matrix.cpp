// The Rosenbrock step's linear algebra: W = I - gamma h J solved exactly, with the plate's and
// the regulator's rows eliminated first where J has their pattern, and whole where it does not.
#include <gtest/gtest.h>

#include <random>
#include <string>

#include "nursing_bed/core/physics/step_matrix.h"

namespace nb = nursing_bed;

namespace {

constexpr int kN = nb::StepMatrix::kNominalStates;

// A dense n x n Jacobian; with `pattern`, its height row is dh/dt = v and its regulator row the
// regulator's own lag, as CellModel's.
nb::CellStateMatrix randomJacobian(std::mt19937* rng, int n, bool pattern) {
  std::normal_distribution<double> normal(0.0, 200.0);
  nb::CellStateMatrix j(n, n);
  for (int r = 0; r < n; ++r)
    for (int c = 0; c < n; ++c) j(r, c) = normal(*rng);
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
  const double gamma_h = 1.7071 * 0.02;
  for (int n : {kN, 7, 9, 5}) {
    for (bool pattern : {true, false}) {
      for (int trial = 0; trial < 30; ++trial) {
        nb::CellStateMatrix j = randomJacobian(&rng, n, pattern);
        if (trial % 3 == 2) {  // scaled like a stiff cell's: the plate's row and the gas mass's column
          j.row(3) *= 1e4;
          j.col(0) *= 1e3;
        }
        nb::StepMatrix w;
        w.factor(j, gamma_h);
        nb::CellStateVector b(n);
        for (int i = 0; i < n; ++i) b[i] = normal(rng);
        const nb::CellStateMatrix dense = nb::CellStateMatrix::Identity(n, n) - gamma_h * j;
        const nb::CellStateVector x = w.solve(b);
        const std::string where = std::to_string(n) + " states, " + (pattern ? "with" : "without") +
                                  " the pattern, trial " + std::to_string(trial);
        EXPECT_LT((dense * x - b).norm(), 1e-9 * (1.0 + dense.norm() * x.norm())) << where;
        if (n == kN) {
          const nb::StepMatrix::NominalVector y = w.solveNominal(b.head<kN>());
          EXPECT_LT((y - x.head<kN>()).norm(), 1e-12 * (1.0 + x.norm())) << where;
        }
      }
    }
  }
}

}  // namespace
