// The cell's checks of the observer's gas (GasVerifier), driven by hand: its states, its valve
// filters and the observer events that end them.
#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>
#include <string>

#include "nursing_bed/core/control/gas_verifier.h"

namespace nb = nursing_bed;

namespace {

constexpr double kPeriod = 0.01;

nb::ObserverEvents reanchored() {
  nb::ObserverEvents e;
  e.reanchored = true;
  return e;
}

const nb::ValveOpenings kWanted{0.7, 0.0, false};

}  // namespace

TEST(GasVerifierParams, RefusesBadValuesNamingThem) {
  auto expectRefused = [](const char* key, double nb::GasVerifierParams::*field, std::initializer_list<double> values) {
    for (const double v : values) {
      nb::GasVerifierParams p;
      p.*field = v;
      EXPECT_NE(p.validate().message().find(key), std::string::npos) << key << " " << v;
      EXPECT_THROW(nb::GasVerifier{p}, std::invalid_argument) << key << " " << v;
    }
  };
  // The gas check after a lost link: a short vent, not an emptying.
  expectRefused("resume_vent_s", &nb::GasVerifierParams::resume_vent_s, {-0.01, 0.5, std::nan("")});
  expectRefused("reanchor_below_m", &nb::GasVerifierParams::reanchor_below_m, {-0.01, std::nan("")});
  expectRefused("recount_doubt_m", &nb::GasVerifierParams::recount_doubt_m, {-0.01, std::nan("")});
  expectRefused("flag_doubt_m", &nb::GasVerifierParams::flag_doubt_m, {-0.01, std::nan("")});
  expectRefused("recount_max_load_n", &nb::GasVerifierParams::recount_max_load_n, {0.0, -1.0, std::nan("")});
  expectRefused("verify_hold_s", &nb::GasVerifierParams::verify_hold_s, {-0.1, 5.0, std::nan("")});
  expectRefused("link_steady_s", &nb::GasVerifierParams::link_steady_s, {-0.1, 20.0, std::nan("")});
  expectRefused("verify_tolerance_pa", &nb::GasVerifierParams::verify_tolerance_pa, {0.0, std::nan("")});
  expectRefused("verify_tolerance_rel", &nb::GasVerifierParams::verify_tolerance_rel, {-0.1, 1.0});
  expectRefused("prove_hold_s", &nb::GasVerifierParams::prove_hold_s, {-1.0, 60.0, std::nan("")});
  expectRefused("prove_settle_s", &nb::GasVerifierParams::prove_settle_s, {-0.1, 10.0, std::nan("")});
  expectRefused("prove_tolerance_pa", &nb::GasVerifierParams::prove_tolerance_pa, {0.0, -5.0, std::nan("")});
  expectRefused("prove_tolerance_rel", &nb::GasVerifierParams::prove_tolerance_rel, {-0.1, 1.0, std::nan("")});
  expectRefused("prove_min_height_m", &nb::GasVerifierParams::prove_min_height_m, {-0.01, std::nan("")});
  EXPECT_TRUE(nb::GasVerifierParams{}.validate().ok());
}

TEST(GasVerifier, AnUnverifiedGasIsVentedUntilTheObserverFindsTheCellFlat) {
  nb::CellObserver observer(nb::CellParams{}, nb::CellObserverParams{});
  nb::GasVerifier gas(nb::GasVerifierParams{});
  gas.reset(false);
  EXPECT_EQ(gas.knowledge(), nb::GasKnowledge::kUnverified);
  bool found = true;
  for (int i = 0; i < 3; ++i) {
    const nb::ValveOpenings v = gas.findingValves(kPeriod, &observer, kWanted, &found);
    EXPECT_EQ(v.inlet, 0.0);
    EXPECT_EQ(v.vent, 1.0);
    EXPECT_FALSE(found);
    EXPECT_TRUE(gas.findingGas());
  }
  gas.note(reanchored());
  const nb::ValveOpenings v = gas.findingValves(kPeriod, &observer, kWanted, &found);
  EXPECT_TRUE(found) << "found after venting: the controller restarts its integral";
  EXPECT_EQ(v.inlet, 0.0);
  EXPECT_EQ(v.vent, 0.0);
  EXPECT_EQ(gas.knowledge(), nb::GasKnowledge::kKnown);
  EXPECT_EQ(gas.findingValves(kPeriod, &observer, kWanted, &found).inlet, kWanted.inlet);
}

TEST(GasVerifier, ACellFoundFlatBeforeAnyCommandIsControlledAtOnce) {
  nb::CellObserver observer(nb::CellParams{}, nb::CellObserverParams{});
  nb::GasVerifier gas(nb::GasVerifierParams{});
  gas.reset(false);
  gas.note(nb::ObserverEvents{});  // no event: still unverified
  EXPECT_EQ(gas.knowledge(), nb::GasKnowledge::kUnverified);
  gas.note(reanchored());
  bool found = true;
  const nb::ValveOpenings v = gas.findingValves(kPeriod, &observer, kWanted, &found);
  EXPECT_FALSE(found);
  EXPECT_EQ(v.inlet, kWanted.inlet);
  EXPECT_EQ(gas.knowledge(), nb::GasKnowledge::kKnown);
}

TEST(GasVerifier, OnlyACellLoweredIntoTheLowBandFromAboveItAnchors) {
  nb::GasVerifierParams p;
  p.reanchor_below_m = 0.035;
  nb::GasVerifier gas(p);
  gas.heightRequested(0.03, 0.02);  // already in the band
  EXPECT_FALSE(gas.anchoringGas());
  gas.heightRequested(0.05, 0.10);  // above the band
  EXPECT_FALSE(gas.anchoringGas());
  gas.note(reanchored());  // an earlier re-anchor does not end the next anchoring
  gas.heightRequested(0.03, 0.10);
  EXPECT_TRUE(gas.anchoringGas());
  nb::CellObserver observer(nb::CellParams{}, nb::CellObserverParams{});
  bool found = true;
  EXPECT_EQ(gas.findingValves(kPeriod, &observer, kWanted, &found).vent, 1.0);
  gas.heightRequested(0.08, 0.05);  // raised out of the band before it was found flat
  EXPECT_EQ(gas.knowledge(), nb::GasKnowledge::kKnown);
  gas.heightRequested(0.03, 0.10);
  gas.pressureRequested();  // a pressure is held from where the cell is
  EXPECT_EQ(gas.knowledge(), nb::GasKnowledge::kKnown);
  p.reanchor_below_m = 0.0;  // never
  nb::GasVerifier never(p);
  never.heightRequested(0.0, 0.10);
  EXPECT_FALSE(never.anchoringGas());
}

TEST(GasVerifier, ADoubtfulCountOnALightCellAnchorsItWhateverTargetsComeUntilFoundFlat) {
  nb::GasVerifierParams p;  // recount_doubt_m 4 mm, recount_max_load_n 5 N
  nb::GasVerifier gas(p);
  gas.noteCountDoubt(0.003, 0.6);
  EXPECT_FALSE(gas.anchoringGas()) << "within the doubt allowed";
  gas.noteCountDoubt(0.01, 20.0);
  EXPECT_FALSE(gas.anchoringGas()) << "a loaded cell keeps its count";
  gas.noteCountDoubt(0.005, 0.6);
  EXPECT_TRUE(gas.anchoringGas());
  EXPECT_TRUE(gas.recounting());
  EXPECT_FALSE(gas.unproven()) << "its height is tracked meanwhile";
  EXPECT_TRUE(gas.unverified()) << "and flagged while the doubt lasts";
  gas.heightRequested(0.13, 0.12);  // a plan's next target, above the low band
  EXPECT_TRUE(gas.anchoringGas()) << "a new target does not end it";
  nb::CellObserver observer(nb::CellParams{}, nb::CellObserverParams{});
  bool found = true;
  EXPECT_EQ(gas.findingValves(kPeriod, &observer, kWanted, &found).vent, 1.0);
  gas.noteCountDoubt(0.02, 0.6);
  EXPECT_TRUE(gas.recounting()) << "one anchoring at a time";
  gas.noteCountDoubt(0.0, 0.6);  // the estimate's doubt in mm shrinks as it falls to flat
  EXPECT_FALSE(gas.doubtful());
  EXPECT_TRUE(gas.unverified()) << "flagged until the cell is found flat";
  gas.note(reanchored());
  gas.findingValves(kPeriod, &observer, kWanted, &found);
  EXPECT_TRUE(found);
  EXPECT_EQ(gas.knowledge(), nb::GasKnowledge::kKnown);
  EXPECT_FALSE(gas.recounting());
  EXPECT_FALSE(gas.unverified());
  p.recount_doubt_m = 0.0;  // never
  nb::GasVerifier never(p);
  never.noteCountDoubt(1.0, 0.6);
  EXPECT_FALSE(never.anchoringGas());
}

TEST(GasVerifier, ADoubtfulCountIsFlaggedButControlledUntilTheDoubtEnds) {
  nb::GasVerifierParams p;  // flag_doubt_m 3 mm
  nb::GasVerifier gas(p);
  gas.noteCountDoubt(0.0029, 40.0);
  EXPECT_FALSE(gas.unverified()) << "a doubt within the flag's bound";
  gas.noteCountDoubt(0.0035, 40.0);  // a loaded cell: not re-anchored, its count kept
  EXPECT_TRUE(gas.doubtful());
  EXPECT_TRUE(gas.unverified());
  EXPECT_FALSE(gas.unproven());
  EXPECT_FALSE(gas.gasUnknown()) << "still controlled: inflated and vented as its plan asks";
  EXPECT_FALSE(gas.anchoringGas());
  gas.noteCountDoubt(0.0, 40.0);  // found flat: the observer's doubt ends
  EXPECT_FALSE(gas.unverified());
  p.flag_doubt_m = 0.0;  // never
  nb::GasVerifier never(p);
  never.noteCountDoubt(1.0, 40.0);
  EXPECT_FALSE(never.unverified());
}

TEST(GasVerifier, AfterALostLinkItVentsBrieflyThenHoldsForTheReanchorTest) {
  nb::CellObserver observer(nb::CellParams{}, nb::CellObserverParams{});
  nb::GasVerifierParams p;
  p.resume_vent_s = 0.025;
  nb::GasVerifier gas(p);
  EXPECT_EQ(gas.linkCheckValves(0.0, kPeriod, 500.0, &observer, kWanted).inlet, kWanted.inlet) << "no check pending";
  gas.linkRestored(-gas.params().link_steady_s);  // back, and steady by t = 0
  const double openings[] = {1.0, 1.0, 0.5};      // 25 ms of full vent at 10 ms periods
  double t = 0.0;
  for (const double opening : openings) {
    const nb::ValveOpenings v = gas.linkCheckValves(t, kPeriod, 500.0, &observer, kWanted);
    EXPECT_EQ(v.inlet, 0.0);
    EXPECT_NEAR(v.vent, opening, 1e-12);
    t += kPeriod;
  }
  // Both valves shut for the test: from the vent's last period, one period, the dead time and
  // twice the re-anchor time.
  const double until =
      2 * kPeriod + kPeriod + observer.params().valve_dead_time_s + 2.0 * observer.params().reanchor_time_s;
  for (; t < until - 1e-9; t += kPeriod) {
    const nb::ValveOpenings v = gas.linkCheckValves(t, kPeriod, 500.0, &observer, kWanted);
    EXPECT_EQ(v.inlet + v.vent, 0.0) << "at " << t;
  }
  EXPECT_EQ(gas.linkCheckValves(until + 1e-9, kPeriod, 500.0, &observer, kWanted).inlet, kWanted.inlet);
}

TEST(GasVerifier, TheLinkChecksWaitUntilTheLinkHasStayedUp) {
  // A link that drops replies comes and goes every few tenths of a second: its checks would
  // vent for as long as the terminal's watchdog holds each written vent. The valves stay shut
  // and the gas unverified until the link has stayed up link_steady_s.
  nb::CellObserver observer(nb::CellParams{}, nb::CellObserverParams{});
  nb::GasVerifier gas(nb::GasVerifierParams{});
  const double steady_s = gas.params().link_steady_s;
  ASSERT_GT(steady_s, 0.2);
  gas.linkLost(1500.0);
  gas.linkRestored(0.0);
  double t = 0.0;
  for (; t < 0.2 - 1e-9; t += kPeriod) {
    const nb::ValveOpenings v = gas.linkCheckValves(t, kPeriod, 1500.0, &observer, kWanted);
    EXPECT_EQ(v.inlet + v.vent, 0.0) << "at " << t;
  }
  gas.linkLost(1500.0);  // down again, then back
  gas.linkRestored(0.3);
  for (t = 0.3; t < 0.3 + steady_s - 1e-9; t += kPeriod) {
    EXPECT_TRUE(gas.unverified()) << "at " << t;
    const nb::ValveOpenings v = gas.linkCheckValves(t, kPeriod, 1500.0, &observer, kWanted);
    EXPECT_EQ(v.inlet + v.vent, 0.0) << "no vent before the link is steady, at " << t;
  }
  // Steady: the hold runs (valves shut), then the short vent.
  bool vented = false;
  for (int i = 0; i < 100 && !vented; ++i, t += kPeriod)
    vented = gas.linkCheckValves(t, kPeriod, 1500.0, &observer, kWanted).vent > 0.0;
  EXPECT_TRUE(vented) << "the checks run once the link is steady";
}

TEST(GasVerifier, ALinkCheckEndsAtTheReanchorAndAtAGroundedReading) {
  nb::CellObserver observer(nb::CellParams{}, nb::CellObserverParams{});
  nb::GasVerifier gas(nb::GasVerifierParams{});
  gas.linkRestored(-gas.params().link_steady_s);  // back, and steady by t = 0
  // A reading already below the flat pressure: no vent at all, straight to the test.
  const nb::ValveOpenings first = gas.linkCheckValves(0.0, kPeriod, 0.0, &observer, kWanted);
  EXPECT_EQ(first.vent, 0.0);
  EXPECT_EQ(gas.linkCheckValves(kPeriod, kPeriod, 0.0, &observer, kWanted).inlet, 0.0);
  gas.note(reanchored());
  EXPECT_EQ(gas.linkCheckValves(2 * kPeriod, kPeriod, 0.0, &observer, kWanted).inlet, kWanted.inlet);
  nb::GasVerifierParams off;
  off.resume_vent_s = 0.0;
  nb::GasVerifier none(off);
  none.linkRestored(-none.params().link_steady_s);
  EXPECT_EQ(none.linkCheckValves(0.0, kPeriod, 500.0, &observer, kWanted).inlet, kWanted.inlet);
}

/// Runs the link check's hold (verify_hold_s) at `pressure_pa`; every period's valves must be
/// shut and the gas unverified meanwhile.
void runHold(nb::GasVerifier* gas, nb::CellObserver* observer, double pressure_pa) {
  const int periods = static_cast<int>(std::lround(gas->params().verify_hold_s / kPeriod));
  for (int i = 0; i < periods; ++i) {
    EXPECT_TRUE(gas->unverified()) << i;
    const nb::ValveOpenings v = gas->linkCheckValves(i * kPeriod, kPeriod, pressure_pa, observer, kWanted);
    EXPECT_EQ(v.inlet + v.vent, 0.0) << "both valves shut through the hold, period " << i;
  }
}

TEST(GasVerifier, ALostLinkLeavesTheGasUnverifiedUntilItsCheckEnds) {
  nb::CellObserver observer(nb::CellParams{}, nb::CellObserverParams{});
  nb::GasVerifier gas(nb::GasVerifierParams{});
  EXPECT_FALSE(gas.unverified());
  gas.linkLost(1500.0);
  EXPECT_TRUE(gas.unverified()) << "while the link is down";
  gas.linkRestored(-gas.params().link_steady_s);  // back, and steady by t = 0
  runHold(&gas, &observer, 1480.0);
  EXPECT_FALSE(gas.holdMismatched());
  EXPECT_EQ(gas.knowledge(), nb::GasKnowledge::kKnown);
  EXPECT_TRUE(gas.unverified()) << "the vent check still runs";
  double t = 1.0;
  for (int i = 0; i < 10; ++i, t += kPeriod)
    EXPECT_EQ(gas.linkCheckValves(t, kPeriod, 1480.0, &observer, kWanted).inlet, 0.0);
  gas.note(reanchored());
  EXPECT_EQ(gas.linkCheckValves(t, kPeriod, 1480.0, &observer, kWanted).inlet, kWanted.inlet);
  EXPECT_FALSE(gas.unverified());
}

TEST(GasVerifier, APressureThatMovedOverALostLinkSendsTheCellToBeFoundFlat) {
  // A terminal restarted empty: the plate lies on the bed, the cell reads its own pressure.
  nb::CellObserver observer(nb::CellParams{}, nb::CellObserverParams{});
  nb::GasVerifier gas(nb::GasVerifierParams{});
  gas.linkLost(1500.0);
  gas.linkRestored(-gas.params().link_steady_s);  // back, and steady by t = 0
  runHold(&gas, &observer, 12.0);
  EXPECT_TRUE(gas.holdMismatched());
  EXPECT_EQ(gas.knowledge(), nb::GasKnowledge::kUnverified);
  bool found = true;
  const nb::ValveOpenings v = gas.findingValves(kPeriod, &observer, kWanted, &found);
  EXPECT_EQ(v.inlet, 0.0);
  EXPECT_EQ(v.vent, 1.0) << "vented until found flat";
  EXPECT_TRUE(gas.unverified());
  gas.note(reanchored());
  gas.findingValves(kPeriod, &observer, kWanted, &found);
  EXPECT_TRUE(found);
  EXPECT_FALSE(gas.unverified());
}

TEST(GasVerifier, ASuspectedGasIsFoundFlatAgainBeforeItIsTrusted) {
  nb::CellObserver observer(nb::CellParams{}, nb::CellObserverParams{});
  nb::GasVerifier gas(nb::GasVerifierParams{});
  gas.suspect();
  EXPECT_TRUE(gas.unverified());
  bool found = true;
  EXPECT_EQ(gas.findingValves(kPeriod, &observer, kWanted, &found).vent, 1.0);
  EXPECT_TRUE(gas.findingGas());
  gas.note(reanchored());
  EXPECT_EQ(gas.findingValves(kPeriod, &observer, kWanted, &found).inlet, 0.0);
  EXPECT_TRUE(found);
  EXPECT_FALSE(gas.unverified());
  EXPECT_EQ(gas.findingValves(kPeriod, &observer, kWanted, &found).inlet, kWanted.inlet);
}

namespace {
/// Found flat after an inconsistency: the gas is known again from the flat cell.
void findFlat(nb::GasVerifier* gas, nb::CellObserver* observer) {
  bool found = false;
  gas->findingValves(kPeriod, observer, kWanted, &found);
  gas->note(reanchored());
  gas->findingValves(kPeriod, observer, kWanted, &found);
  ASSERT_TRUE(found);
}
}  // namespace

TEST(GasVerifier, AnInconsistentCellFoundFlatStaysUnverifiedUntilAHoldAtHeightKeepsItsPressure) {
  nb::CellObserver observer(nb::CellParams{}, nb::CellObserverParams{});
  nb::GasVerifier gas(nb::GasVerifierParams{});
  gas.suspectInconsistent();
  findFlat(&gas, &observer);
  EXPECT_FALSE(gas.gasUnknown()) << "found flat: refilled";
  EXPECT_TRUE(gas.unverified()) << "but not proved";
  EXPECT_TRUE(gas.proving());
  bool found = true;
  EXPECT_EQ(gas.findingValves(kPeriod, &observer, kWanted, &found).inlet, kWanted.inlet);
  // Held at a flat cell's height, or moving: nothing proved.
  for (int i = 0; i < 500; ++i) gas.noteHold(true, 900.0, 0.005, kPeriod);
  for (int i = 0; i < 500; ++i) gas.noteHold(i % 50 != 0, 900.0, 0.06, kPeriod);
  EXPECT_TRUE(gas.unverified());
  const int periods = static_cast<int>((gas.params().prove_settle_s + gas.params().prove_hold_s) / kPeriod) + 2;
  for (int i = 0; i < periods; ++i) gas.noteHold(true, 900.0 + (i % 2 ? 8.0 : -8.0), 0.06, kPeriod);
  EXPECT_FALSE(gas.proving()) << "a steady hold at height proves the valves";
  EXPECT_TRUE(gas.gasUnknown()) << "and the gas is counted afresh from one more flat cell";
  EXPECT_EQ(gas.failedProofs(), 0);
  findFlat(&gas, &observer);
  EXPECT_FALSE(gas.unverified());
}

TEST(GasVerifier, AHoldWhosePressureSinksSendsTheCellFlatAgain) {
  nb::CellObserver observer(nb::CellParams{}, nb::CellObserverParams{});
  nb::GasVerifier gas(nb::GasVerifierParams{});
  gas.suspectInconsistent();
  findFlat(&gas, &observer);
  // A plate sinking on a vent stuck open: its pressure falls along the structure.
  const int periods = static_cast<int>((gas.params().prove_settle_s + gas.params().prove_hold_s) / kPeriod) + 2;
  for (int i = 0; i < periods; ++i) gas.noteHold(true, 1500.0 - 300.0 * i * kPeriod, 0.08, kPeriod);
  EXPECT_EQ(gas.failedProofs(), 1);
  EXPECT_TRUE(gas.gasUnknown()) << "vented flat again";
  bool found = true;
  EXPECT_EQ(gas.findingValves(kPeriod, &observer, kWanted, &found).vent, 1.0);
  findFlat(&gas, &observer);
  EXPECT_TRUE(gas.unverified()) << "and proved again";
}

TEST(GasVerifier, ASuspicionWithoutAnInconsistencyNeedsNoHold) {
  nb::CellObserver observer(nb::CellParams{}, nb::CellObserverParams{});
  nb::GasVerifierParams p;
  nb::GasVerifier gas(p);
  gas.suspect();
  findFlat(&gas, &observer);
  EXPECT_FALSE(gas.unverified());
  p.prove_hold_s = 0.0;
  nb::GasVerifier found_flat_proves(p);
  found_flat_proves.suspectInconsistent();
  findFlat(&found_flat_proves, &observer);
  EXPECT_FALSE(found_flat_proves.unverified()) << "prove_hold_s 0: found flat proves the gas";
}
