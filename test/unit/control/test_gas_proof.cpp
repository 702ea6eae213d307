// The proof of a cell's gas after an inconsistency (GasProof), driven by hand.
#include <gtest/gtest.h>

#include "nursing_bed/core/control/gas_proof.h"

namespace nb = nursing_bed;

namespace {

constexpr double kPeriod = 0.01;

/// Periods that cover the settling and the whole hold, and a few more.
int holdPeriods(const nb::GasProofParams& p) { return static_cast<int>((p.settle_s + p.hold_s) / kPeriod) + 2; }

}  // namespace

TEST(GasProof, AsksNothingUntilStartedAndNothingWhenItsHoldIsZero) {
  nb::GasProof proof(nb::GasProofParams{});
  EXPECT_FALSE(proof.pending());
  EXPECT_EQ(proof.update(true, 900.0, 0.06, kPeriod), nb::GasProof::Verdict::kNone);
  nb::GasProofParams none;
  none.hold_s = 0.0;
  nb::GasProof off(none);
  off.start();
  EXPECT_FALSE(off.pending());
}

TEST(GasProof, ASteadyHoldAtHeightProvesTheGasOnceItHasRunItsWholeLength) {
  const nb::GasProofParams p;
  nb::GasProof proof(p);
  proof.start();
  const int periods = holdPeriods(p);
  nb::GasProof::Verdict verdict = nb::GasProof::Verdict::kNone;
  int at = -1;
  for (int i = 0; i < periods && verdict == nb::GasProof::Verdict::kNone; ++i) {
    verdict = proof.update(true, 900.0 + (i % 2 ? 8.0 : -8.0), 0.06, kPeriod);
    at = i;
  }
  EXPECT_EQ(verdict, nb::GasProof::Verdict::kProved);
  EXPECT_GE((at + 1) * kPeriod, p.settle_s + p.hold_s - 1e-9) << "not before the hold's end";
  EXPECT_FALSE(proof.pending());
  EXPECT_EQ(proof.failures(), 0);
}

TEST(GasProof, AFallingPressureFailsTheHoldAndKeepsTheProofAsked) {
  const nb::GasProofParams p;
  nb::GasProof proof(p);
  proof.start();
  nb::GasProof::Verdict verdict = nb::GasProof::Verdict::kNone;
  for (int i = 0; i < holdPeriods(p) && verdict == nb::GasProof::Verdict::kNone; ++i)
    verdict = proof.update(true, 1500.0 - 300.0 * i * kPeriod, 0.08, kPeriod);
  EXPECT_EQ(verdict, nb::GasProof::Verdict::kFailed);
  EXPECT_TRUE(proof.pending());
  EXPECT_EQ(proof.failures(), 1);
  proof.reset();
  EXPECT_FALSE(proof.pending());
  EXPECT_EQ(proof.failures(), 0);
}

TEST(GasProof, AHoldBrokenByAValveOrAFlatEstimateStartsAgain) {
  const nb::GasProofParams p;
  nb::GasProof proof(p);
  proof.start();
  // Interrupted every half hold: never a whole hold, never a verdict.
  const int half = static_cast<int>(0.5 * (p.settle_s + p.hold_s) / kPeriod);
  for (int i = 0; i < 4 * holdPeriods(p); ++i)
    EXPECT_EQ(proof.update(i % half != 0, 900.0, 0.06, kPeriod), nb::GasProof::Verdict::kNone);
  for (int i = 0; i < 2 * holdPeriods(p); ++i)
    EXPECT_EQ(proof.update(true, 900.0, 0.5 * p.min_height_m, kPeriod), nb::GasProof::Verdict::kNone);
  EXPECT_TRUE(proof.pending());
}
