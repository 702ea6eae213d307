// The bed supervisor on simulated time: cell health, leak alarm, plans and their reverts,
// resume, CPR, requests and what is sent to the cells.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <string>
#include <tuple>
#include <vector>

#include "nursing_bed/core/bed/bed_supervisor.h"

namespace nb = nursing_bed;

namespace {

constexpr double kStartS = 1000.0;  // the simulated clock at start [s]
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

bool contains(const std::string& text, const std::string& fragment) { return text.find(fragment) != std::string::npos; }

nb::BedGrid grid2x3() {
  nb::BedGrid g;
  g.rows = 2;
  g.cols = 3;
  g.pitch_m = 0.1;
  g.min_height_m = 0.0;
  g.max_height_m = 0.15;
  return g;
}

std::vector<nb::BedCell> cellsOf(const nb::BedGrid& g) {
  std::vector<nb::BedCell> cells;
  for (int r = 0; r < g.rows; ++r)
    for (int c = 0; c < g.cols; ++c) {
      const std::string name = "airbag_" + std::to_string(r) + "_" + std::to_string(c);
      cells.push_back({g.id(r, c), name, name + "_link", g.min_height_m, g.max_height_m});
    }
  return cells;
}

// A 2 x 3 bed whose cells report on the simulated clock; `now` only moves forward.
class Bed {
 public:
  explicit Bed(nb::BedSupervisorParams params = {})
      : grid_(grid2x3()),
        sup(params, grid_, cellsOf(grid_), kStartS),
        heights(grid_.cells(), 0.10),
        silent(grid_.cells(), false),
        faults(grid_.cells(), 0),
        connected(grid_.cells(), true) {}

  /// Every cell that is not silent reports its height and faults now.
  void report() {
    for (std::uint32_t id = 0; id < heights.size(); ++id) {
      if (silent[id]) continue;
      nb::CellSnapshot s;
      s.id = id;
      s.height_m = heights[id];
      s.height_sd_m = 0.001;
      s.faults = faults[id];
      s.gauge_pressure_pa = 3000.0;
      s.external_load_n = 40.0;
      s.seen_s = now;
      sup.onCellState(s);
    }
  }
  /// Reports, then one plan step; the output is kept in `out`.
  nb::BedStatus step() {
    report();
    const nb::BedStatus status = sup.step(now);
    out = sup.takeOutput();
    return status;
  }
  /// Steps at 10 Hz for `duration_s`; returns the last status. `sent` and `events` collect
  /// the commands and events of the run.
  nb::BedStatus run(double duration_s) {
    nb::BedStatus status;
    sent.clear();
    events.clear();
    const double end = now + duration_s;
    while (now < end - 1e-9) {
      now += 0.1;
      status = step();
      sent.insert(sent.end(), out.commands.begin(), out.commands.end());
      events.insert(events.end(), out.events.begin(), out.events.end());
    }
    return status;
  }
  nb::RequestResult posture(const std::string& plan, std::vector<std::string> keys = {},
                            std::vector<std::string> values = {}, std::vector<double> custom = {}) {
    const nb::RequestResult r = sup.setPosture(plan, keys, values, custom, now);
    out = sup.takeOutput();
    return r;
  }
  nb::RequestResult setHeights(std::vector<std::uint32_t> ids, std::vector<double> hs) {
    const nb::RequestResult r = sup.setHeights(ids, hs, connected, now);
    out = sup.takeOutput();
    return r;
  }
  /// The last setpoint of each cell in `sent`, and the number of vents there.
  std::map<std::uint32_t, double> setpoints() const {
    std::map<std::uint32_t, double> m;
    for (const nb::CellCommand& c : sent)
      if (!c.vent) m[c.id] = c.height_m;
    return m;
  }
  std::size_t vents() const {
    return std::count_if(sent.begin(), sent.end(), [](const nb::CellCommand& c) { return c.vent; });
  }
  /// An event of `kind` containing `fragment` came with the last call or run.
  bool logged(nb::BedEvent::Kind kind, const std::string& fragment) const {
    for (const auto* list : {&out.events, &events})
      for (const nb::BedEvent& e : *list)
        if (e.kind == kind && contains(e.text, fragment)) return true;
    return false;
  }

  nb::BedGrid grid_;
  nb::BedSupervisor sup;
  std::vector<double> heights;
  std::vector<bool> silent;
  std::vector<std::uint32_t> faults;
  std::vector<bool> connected;
  nb::SupervisorOutput out;
  std::vector<nb::CellCommand> sent;
  std::vector<nb::BedEvent> events;
  double now = kStartS;
};

// ---- cell health ------------------------------------------------------------------------------

TEST(BedSupervisor, ACellSilentPastTheTimeoutIsDeadAndTheBedLevelsAtTheHealthyCellsMean) {
  nb::BedSupervisorParams params;
  params.cell_timeout_s = 0.45;  // between two steps of the simulated clock
  Bed bed(params);
  bed.heights = {0.06, 0.08, 0.10, 0.12, 0.14, 0.05};
  ASSERT_TRUE(bed.posture("flat").ok);
  bed.run(2.5);  // past the start-up's settling
  bed.silent[5] = true;
  nb::BedStatus status = bed.run(0.4);  // silent within the timeout: alive
  EXPECT_TRUE(status.dead_cells.empty());
  EXPECT_EQ(status.plan, nb::PlanKind::kFlat);
  status = bed.run(0.1);
  EXPECT_EQ(status.dead_cells, std::vector<std::uint32_t>{5});
  EXPECT_EQ(status.plan, nb::PlanKind::kSafeLevel);
  EXPECT_EQ(status.parameters, "height_m=0.1");  // mean of 0.06..0.14
  EXPECT_TRUE(bed.logged(nb::BedEvent::Kind::kCellFailed,
                         "cell 5 (airbag_1_2) stopped reporting; levelling the bed at 0.100 m"));
  ASSERT_TRUE(bed.out.resume_record);
  EXPECT_EQ(bed.out.resume_record->running.request.plan, "safe_level");
  ASSERT_EQ(bed.out.resume_record->running.request.heights_m.size(), 1u);
  EXPECT_NEAR(bed.out.resume_record->running.request.heights_m[0], 0.1, 1e-12);
  // The failure is acted on once: the next steps keep safe_level from its first start.
  EXPECT_NEAR(bed.run(1.0).elapsed_s, 1.0, 1e-6);
  EXPECT_EQ(bed.sup.report(bed.now).cells[5].severity, nb::Severity::kError);
}

TEST(BedSupervisor, CellsThatNeverReportedAreDeadOnlyAfterTheStartUpGrace) {
  nb::BedSupervisorParams params;
  params.startup_grace_s = 10.0;
  Bed bed(params);
  bed.silent[2] = true;
  ASSERT_TRUE(bed.posture("flat").ok);
  nb::BedStatus status = bed.run(9.9);
  EXPECT_TRUE(status.dead_cells.empty());
  EXPECT_EQ(status.plan, nb::PlanKind::kFlat);
  EXPECT_EQ(bed.sup.report(bed.now).cells[2].message, "no state received");
  status = bed.run(0.2);
  EXPECT_EQ(status.dead_cells, std::vector<std::uint32_t>{2});
  EXPECT_EQ(status.plan, nb::PlanKind::kSafeLevel);
}

TEST(BedSupervisor, ACellReportingASensorOrModelFaultIsFaultyAndTheBedLevels) {
  for (const std::uint32_t fault : {nb::kFaultSensor, nb::kFaultModel}) {
    Bed bed;
    ASSERT_TRUE(bed.posture("alternating", {"pattern"}, {"1in2"}).ok);
    bed.run(1.0);
    bed.heights[3] = 0.0;
    bed.faults[3] = fault;
    const nb::BedStatus status = bed.run(0.1);
    EXPECT_EQ(status.faulty_cells, std::vector<std::uint32_t>{3}) << fault;
    EXPECT_TRUE(status.dead_cells.empty());
    EXPECT_EQ(status.plan, nb::PlanKind::kSafeLevel);
    EXPECT_EQ(status.parameters, "height_m=0.1");  // the faulty cell's 0 m is left out
    EXPECT_TRUE(bed.logged(nb::BedEvent::Kind::kCellFailed, "cell 3 (airbag_1_0) reports a sensor or model fault"));
    EXPECT_EQ(bed.sup.report(bed.now).cells[3].severity, nb::Severity::kWarn);
  }
}

TEST(BedSupervisor, AfterTheRigRestartedEmptyTheBedLevelsAtTheTargetsNotAtFlat) {
  // Every cell held at 0.08 m, then the rig restarts empty: the cells report flat while they
  // refill, and one of them fails meanwhile. The bed levels at what the cells were sent.
  Bed bed;
  bed.heights.assign(bed.heights.size(), 0.08);
  ASSERT_TRUE(bed.posture("flat", {"height_m"}, {"0.08"}).ok);
  bed.run(3.0);
  bed.heights.assign(bed.heights.size(), 0.002);
  bed.run(0.3);
  bed.faults[4] = nb::kFaultInconsistent;
  const nb::BedStatus status = bed.run(0.1);
  EXPECT_EQ(status.faulty_cells, std::vector<std::uint32_t>{4});
  EXPECT_EQ(status.plan, nb::PlanKind::kSafeLevel);
  EXPECT_EQ(status.parameters, "height_m=0.08");  // not the flat cells' 0.002 m, clamped to min_height
  EXPECT_TRUE(bed.logged(nb::BedEvent::Kind::kCellFailed, "levelling the bed at 0.080 m"));
}

TEST(BedSupervisor, OtherFaultsAreReportedButDoNotLevelTheBed) {
  Bed bed;
  ASSERT_TRUE(bed.posture("flat").ok);
  bed.faults[1] = nb::kFaultOverpressure | nb::kFaultLowPressure;
  const nb::BedStatus status = bed.run(0.5);
  EXPECT_TRUE(status.faulty_cells.empty());
  EXPECT_EQ(status.plan, nb::PlanKind::kFlat);
  const nb::BedReport report = bed.sup.report(bed.now);
  EXPECT_EQ(report.cells[1].severity, nb::Severity::kWarn);
  EXPECT_EQ(report.cells[1].message, "faults: overpressure low-pressure");
  EXPECT_EQ(report.severity, nb::Severity::kWarn);
  EXPECT_EQ(report.message, "6 cells, 0 not reporting, 1 with faults, 0 unverified");
  EXPECT_EQ(report.plan, "flat (holding)");
}

TEST(BedSupervisor, WithNoHealthyCellTheBedLevelsAtTheNominalHeight) {
  nb::BedSupervisorParams params;
  params.startup_grace_s = 10.0;
  Bed bed(params);
  std::fill(bed.silent.begin(), bed.silent.end(), true);
  const nb::BedStatus status = bed.run(10.2);
  EXPECT_EQ(status.dead_cells.size(), 6u);
  // Nothing known: the bed levels at the nominal height.
  EXPECT_EQ(status.plan, nb::PlanKind::kSafeLevel);
  EXPECT_EQ(status.parameters, "height_m=0.1");
  EXPECT_EQ(bed.sup.report(bed.now).severity, nb::Severity::kError);
}

TEST(BedSupervisor, CellsStalledWhileOthersAreStillLoadingAreNotDeadBeforeEveryCellReports) {
  Bed bed;
  ASSERT_TRUE(bed.posture("flat").ok);
  // Cells 3..5 are still being loaded and have not reported; 0..2 reported once, then stall
  // for 3 s (a loading process runs nothing else), far past the timeout.
  for (std::uint32_t id = 3; id < 6; ++id) bed.silent[id] = true;
  bed.run(0.1);
  for (std::uint32_t id = 0; id < 3; ++id) bed.silent[id] = true;
  nb::BedStatus status = bed.run(3.0);
  EXPECT_TRUE(status.dead_cells.empty());
  EXPECT_EQ(status.plan, nb::PlanKind::kFlat);
  EXPECT_FALSE(bed.sup.health().judging());
  // Every cell up and reporting: the start-up is over and the cells are judged from here.
  std::fill(bed.silent.begin(), bed.silent.end(), false);
  status = bed.run(1.0);
  EXPECT_TRUE(bed.sup.health().judging());
  EXPECT_TRUE(status.dead_cells.empty());
  // The cells loaded last may stall a moment after their first state: 2 s before silences count.
  for (std::uint32_t id = 3; id < 6; ++id) bed.silent[id] = true;
  status = bed.run(1.0);
  EXPECT_TRUE(status.dead_cells.empty());
  std::fill(bed.silent.begin(), bed.silent.end(), false);
  status = bed.run(1.0);
  EXPECT_EQ(status.plan, nb::PlanKind::kFlat);
  bed.silent[4] = true;
  status = bed.run(0.6);
  EXPECT_EQ(status.dead_cells, std::vector<std::uint32_t>{4});
  EXPECT_EQ(status.plan, nb::PlanKind::kSafeLevel);
}

TEST(BedSupervisor, ACellSilentAtTheEndOfTheGraceIsJudgedFromThenOn) {
  nb::BedSupervisorParams params;
  params.startup_grace_s = 10.0;
  Bed bed(params);
  ASSERT_TRUE(bed.posture("flat").ok);
  bed.silent[5] = true;  // never reports: the start-up ends with the grace
  bed.run(1.0);
  bed.silent[0] = true;  // reported, then silent from 1 s on
  nb::BedStatus status = bed.run(8.9);
  EXPECT_TRUE(status.dead_cells.empty());
  status = bed.run(0.2);
  EXPECT_EQ(status.dead_cells, std::vector<std::uint32_t>{5});  // silent from the grace's end on
  status = bed.run(0.4);
  EXPECT_EQ(status.dead_cells, (std::vector<std::uint32_t>{0, 5}));
}

TEST(BedSupervisor, WatchBetweenStepsFindsADeadCellWithinTheTimeoutAndAWatchPeriod) {
  Bed bed;
  ASSERT_TRUE(bed.posture("flat").ok);
  bed.run(2.5);
  const double last_state_s = bed.now;
  bed.silent[2] = true;
  double found_s = kNaN;
  for (const double end = bed.now + 1.0; bed.now < end && std::isnan(found_s);) {
    bed.now += 0.02;
    bed.report();
    if (bed.sup.watch(bed.now) > 0) found_s = bed.now;
  }
  ASSERT_FALSE(std::isnan(found_s));
  EXPECT_LE(found_s - last_state_s, 0.5);
  EXPECT_EQ(bed.sup.health().deadCells(), std::vector<std::uint32_t>{2});
  bed.out = bed.sup.takeOutput();
  EXPECT_TRUE(bed.logged(nb::BedEvent::Kind::kCellFailed, "cell 2 (airbag_0_2) stopped reporting"));
  EXPECT_EQ(bed.sup.watch(found_s + 0.02), 0u);  // acted on once
}

TEST(BedSupervisor, ALostHardwareLinkIsABedAlarmNamingTheCellsAndAnErrorOnDiagnostics) {
  Bed bed;
  ASSERT_TRUE(bed.posture("flat").ok);
  bed.run(1.0);
  bed.faults[3] = bed.faults[4] = nb::kFaultCommunication | nb::kFaultCommandTimeout;
  bed.now += 0.02;
  bed.report();
  EXPECT_EQ(bed.sup.watch(bed.now), 1u);  // the link-lost set changed: the caller publishes at once
  EXPECT_EQ(bed.sup.watch(bed.now + 0.02), 0u);
  const nb::BedStatus status = bed.run(0.1);
  // The cells hold their gas and keep their targets: the plan goes on, the bed alarms.
  EXPECT_TRUE(status.faulty_cells.empty());
  EXPECT_EQ(status.plan, nb::PlanKind::kFlat);
  ASSERT_FALSE(status.alarms.empty());
  EXPECT_EQ(status.alarms.front(),
            "hardware link lost (cells holding their gas, mode SAFE): cells 3 (airbag_1_0), 4 (airbag_1_1)");
  EXPECT_TRUE(bed.logged(nb::BedEvent::Kind::kCellFailed, "hardware link lost"));
  bed.run(0.5);
  EXPECT_FALSE(bed.logged(nb::BedEvent::Kind::kCellFailed, "hardware link lost"));  // logged once
  const nb::BedReport report = bed.sup.report(bed.now);
  EXPECT_EQ(report.severity, nb::Severity::kError);
  EXPECT_EQ(report.cells[3].severity, nb::Severity::kError);
  EXPECT_EQ(report.cells[3].message, "hardware link lost, faults: command-timeout communication");
  EXPECT_TRUE(contains(report.message,
                       "6 cells, 0 not reporting, 2 with a lost hardware link, 0 with faults, 0 unverified; "
                       "hardware link lost"))
      << report.message;
  // The link back: the alarm ends.
  bed.faults[3] = bed.faults[4] = 0;
  EXPECT_TRUE(bed.run(0.1).alarms.empty());
  EXPECT_EQ(bed.sup.report(bed.now).severity, nb::Severity::kOk);
}

TEST(BedSupervisor, ARequestedPlanEndsACprItNeverHeardOfButAResumeOrAFailureDoNot) {
  {  // resumed after a restart: no announcement (a CPR begun meanwhile may be running)
    nb::BedSupervisorParams params;
    params.startup_grace_s = 10.0;
    Bed bed(params);
    nb::ResumeRecord record;
    record.running = {{"flat", {}, {}}, kStartS - 4.0};
    ASSERT_TRUE(bed.sup.resume(record, bed.now).ok);
    EXPECT_FALSE(bed.sup.takeOutput().cpr);
    bed.silent[1] = true;  // a failure's safe_level does not announce either
    bed.run(10.5);
    EXPECT_EQ(bed.sup.step(bed.now).plan, nb::PlanKind::kSafeLevel);
    EXPECT_FALSE(bed.sup.takeOutput().cpr);
    // A nurse's plan does: CPR off, once.
    ASSERT_TRUE(bed.posture("flat").ok);
    ASSERT_TRUE(bed.out.cpr);
    EXPECT_FALSE(*bed.out.cpr);
    ASSERT_TRUE(bed.posture("flat", {"height_m"}, {"0.08"}).ok);
    EXPECT_FALSE(bed.out.cpr);
  }
  {  // manual heights too
    Bed bed;
    bed.run(0.5);
    ASSERT_TRUE(bed.setHeights({0}, {0.08}).ok);
    ASSERT_TRUE(bed.out.cpr);
    EXPECT_FALSE(*bed.out.cpr);
  }
}

// ---- leak alarm -------------------------------------------------------------------------------

TEST(BedSupervisor, ACellHeldBelowItsTargetForLongRaisesTheLeakAlarmUntilItRecovers) {
  Bed bed;
  ASSERT_TRUE(bed.posture("flat").ok);
  bed.run(1.0);
  bed.heights[1] = 0.085;  // 15 mm below the 0.10 m it was sent
  nb::BedStatus status = bed.run(15.0);
  EXPECT_TRUE(status.alarms.empty());
  status = bed.run(0.2);
  ASSERT_EQ(status.alarms.size(), 1u);
  EXPECT_TRUE(contains(status.alarms[0], "cell 1 (airbag_0_1) low pressure or leak: 15 mm below its target for 15.1"))
      << status.alarms[0];
  EXPECT_EQ(bed.sup.report(bed.now).severity, nb::Severity::kWarn);
  bed.heights[1] = 0.095;  // within the error
  status = bed.run(0.1);
  EXPECT_TRUE(status.alarms.empty());
  // A smaller error never raises it.
  status = bed.run(20.0);
  EXPECT_TRUE(status.alarms.empty());
}

// ---- max_inflate and resume -------------------------------------------------------------------

TEST(BedSupervisor, MaxInflateRevertsToTheInterruptedPlanWhereItLeftOff) {
  Bed bed;
  ASSERT_TRUE(bed.posture("alternating", {"pattern", "period_s"}, {"1in2", "60"}).ok);
  nb::BedStatus status = bed.run(20.0);
  EXPECT_NEAR(status.elapsed_s, 20.0, 1e-6);
  ASSERT_TRUE(bed.posture("max_inflate", {"timeout_s"}, {"10.05"}).ok);
  ASSERT_TRUE(bed.out.resume_record && bed.out.resume_record->interrupted);
  EXPECT_EQ(bed.out.resume_record->interrupted->request.plan, "alternating");
  status = bed.run(10.0);
  EXPECT_EQ(status.plan, nb::PlanKind::kMaxInflate);
  status = bed.run(0.1);
  EXPECT_EQ(status.plan, nb::PlanKind::kAlternating);
  EXPECT_NEAR(status.elapsed_s, 20.0, 1e-6);  // it carries on; its clock stood still meanwhile
  EXPECT_TRUE(bed.logged(nb::BedEvent::Kind::kPlanReverted, "max_inflate timed out, back to alternating"));
  ASSERT_TRUE(bed.out.resume_record);
  EXPECT_EQ(bed.out.resume_record->running.request.plan, "alternating");
  EXPECT_FALSE(bed.out.resume_record->interrupted);
  // The reverted plan's targets go out to every cell at once.
  EXPECT_EQ(bed.setpoints().size(), 6u);
}

TEST(BedSupervisor, MaxInflateOverNothingRevertsToSafeLevelAtTheNominalHeight) {
  Bed bed;
  ASSERT_TRUE(bed.posture("max_inflate", {"timeout_s"}, {"5"}).ok);
  const nb::BedStatus status = bed.run(5.1);
  EXPECT_EQ(status.plan, nb::PlanKind::kSafeLevel);
  EXPECT_EQ(status.parameters, "height_m=0.1");
  EXPECT_TRUE(bed.logged(nb::BedEvent::Kind::kPlanReverted, "back to safe_level"));
}

TEST(BedSupervisor, ASavedRecordResumesWithThePlanItInterrupted) {
  Bed bed;
  nb::ResumeRecord record;
  record.running = {{"max_inflate", {{"timeout_s", "10"}}, {}}, kStartS - 4.0};
  record.interrupted = nb::SavedPlan{{"flat", {{"height_m", "0.08"}}, {}}, kStartS - 100.0};
  const nb::RequestResult r = bed.sup.resume(record, bed.now);
  bed.out = bed.sup.takeOutput();
  ASSERT_TRUE(r.ok) << r.message;
  EXPECT_TRUE(bed.logged(nb::BedEvent::Kind::kPlanResumed,
                         "restarted: resuming plan max_inflate (height_m=0.15 timeout_s=10), started 4.0 s ago, "
                         "then back to flat"));
  ASSERT_TRUE(bed.out.resume_record && bed.out.resume_record->interrupted);
  EXPECT_EQ(bed.out.resume_record->running.start_s, kStartS - 4.0);
  nb::BedStatus status = bed.run(5.9);
  EXPECT_EQ(status.plan, nb::PlanKind::kMaxInflate);
  EXPECT_NEAR(status.elapsed_s, 9.9, 1e-6);
  status = bed.run(0.2);
  EXPECT_EQ(status.plan, nb::PlanKind::kFlat);
  EXPECT_EQ(status.parameters, "height_m=0.08");
  EXPECT_TRUE(contains(bed.sup.report(bed.now).plan, "resumed after a restart"));
}

TEST(BedSupervisor, ASavedSafeLevelResumesAtItsHeight) {
  Bed bed;
  const nb::RequestResult r =
      bed.sup.resume(nb::ResumeRecord{{{"safe_level", {}, {0.07}}, kStartS - 1.0}, std::nullopt}, bed.now);
  ASSERT_TRUE(r.ok) << r.message;
  const nb::BedStatus status = bed.run(0.1);
  EXPECT_EQ(status.plan, nb::PlanKind::kSafeLevel);
  EXPECT_EQ(status.parameters, "height_m=0.07");
}

TEST(BedSupervisor, ABadSavedRecordIsRefusedWithTheReasonAndNothingRuns) {
  const std::vector<std::pair<nb::SavedPlan, std::string>> bad = {
      {{{"sit_up", {}, {}}, kStartS - 1.0}, "the saved plan 'sit_up' cannot be resumed (unknown plan 'sit_up'"},
      {{{"flat", {{"height_m", "0.9"}}, {}}, kStartS - 1.0}, "flat: height_m = 0.9 is outside"},
      {{{"flat", {}, {}}, kStartS + 5.0}, "bad start time"},
      {{{"flat", {}, {}}, 0.0}, "bad start time 0"},
      {{{"safe_level", {}, {0.1, 0.1}}, kStartS - 1.0}, "unknown plan 'safe_level'"},
  };
  for (const auto& [saved, why] : bad) {
    Bed bed;
    const nb::RequestResult r = bed.sup.resume(nb::ResumeRecord{saved, std::nullopt}, bed.now);
    bed.out = bed.sup.takeOutput();
    EXPECT_FALSE(r.ok) << why;
    EXPECT_TRUE(contains(r.message, why)) << r.message;
    EXPECT_TRUE(bed.logged(nb::BedEvent::Kind::kResumeRefused, why)) << why;
    EXPECT_FALSE(bed.out.resume_record);
    EXPECT_FALSE(bed.run(0.1).plan) << why;
  }
  Bed bed;
  EXPECT_FALSE(bed.sup.resume(std::nullopt, bed.now).ok);
}

TEST(BedSupervisor, ABadInterruptedPlanIsDroppedAndTheSavedPlanStillResumes) {
  Bed bed;
  nb::ResumeRecord record;
  record.running.request = {"max_inflate", {{"timeout_s", "2"}}, {}};
  record.running.start_s = kStartS - 1.0;
  nb::SavedPlan interrupted;  // built apart: GCC 12 takes a nested brace-init's optional as maybe uninitialised
  interrupted.request.plan = "flat";
  interrupted.start_s = -5.0;
  record.interrupted = interrupted;
  ASSERT_TRUE(bed.sup.resume(record, bed.now).ok);
  bed.out = bed.sup.takeOutput();
  EXPECT_TRUE(bed.logged(nb::BedEvent::Kind::kResumeRefused, "the saved plan 'flat' cannot be resumed (bad start"));
  ASSERT_TRUE(bed.out.resume_record);
  EXPECT_FALSE(bed.out.resume_record->interrupted);
  EXPECT_EQ(bed.run(1.2).plan, nb::PlanKind::kSafeLevel);  // max_inflate over nothing
}

// ---- CPR --------------------------------------------------------------------------------------

TEST(BedSupervisor, CprStartedFromOutsideIsFollowedAndEndsWithTheNextPlan) {
  Bed bed;
  ASSERT_TRUE(bed.posture("flat").ok);
  bed.run(1.0);
  bed.sup.onCpr(false, bed.now);  // an end of CPR without CPR changes nothing
  bed.out = bed.sup.takeOutput();
  EXPECT_TRUE(bed.out.events.empty());
  bed.sup.onCpr(true, bed.now);
  bed.out = bed.sup.takeOutput();
  EXPECT_TRUE(bed.logged(nb::BedEvent::Kind::kCprFollowed, "CPR started from outside"));
  ASSERT_TRUE(bed.out.cpr);
  EXPECT_TRUE(*bed.out.cpr);
  nb::BedStatus status = bed.run(0.1);
  EXPECT_EQ(status.plan, nb::PlanKind::kCpr);
  EXPECT_EQ(bed.vents(), 6u);
  EXPECT_TRUE(std::isnan(status.target_heights_m[0]));
  bed.sup.onCpr(true, bed.now);  // its own announcement coming back: already running
  EXPECT_TRUE(bed.sup.takeOutput().events.empty());
  ASSERT_TRUE(bed.posture("flat").ok);
  ASSERT_TRUE(bed.out.cpr);
  EXPECT_FALSE(*bed.out.cpr);
  ASSERT_TRUE(bed.posture("alternating", {"pattern"}, {"1in3"}).ok);
  EXPECT_FALSE(bed.out.cpr);  // announced off once
}

TEST(BedSupervisor, CprRefusesManualHeights) {
  Bed bed;
  ASSERT_TRUE(bed.posture("cpr").ok);
  bed.run(0.1);
  const nb::RequestResult r = bed.setHeights({0}, {0.1});
  EXPECT_FALSE(r.ok);
  EXPECT_EQ(r.message, "CPR is running: start a plan (e.g. flat) to end it before setting heights");
  EXPECT_EQ(bed.run(0.1).plan, nb::PlanKind::kCpr);
}

TEST(BedSupervisor, CellsDeadDuringCprDoNotEndIt) {
  Bed bed;
  ASSERT_TRUE(bed.posture("cpr").ok);
  bed.run(2.2);
  bed.silent[0] = true;
  const nb::BedStatus status = bed.run(1.0);
  EXPECT_EQ(status.dead_cells, std::vector<std::uint32_t>{0});
  EXPECT_EQ(status.plan, nb::PlanKind::kCpr);
}

// ---- requests ---------------------------------------------------------------------------------

TEST(BedSupervisor, EveryRefusedHeightRequestSaysWhyAndChangesNothing) {
  struct Case {
    std::vector<std::uint32_t> ids;
    std::vector<double> heights;
    std::string message;
  };
  const std::vector<Case> cases = {
      {{}, {}, "no cells given"},
      {{0, 1}, {0.1}, "2 cell ids but 1 heights"},
      {{0, 99}, {0.1, 0.1}, "cell 99 does not exist (the bed has 6 cells, ids 0..5)"},
      {{1, 1}, {0.1, 0.1}, "cell 1 is given twice"},
      {{1}, {kNaN}, "height for cell 1 is not a finite number"},
      {{1}, {0.5}, "height 0.5 m for cell 1 (airbag_0_1_link) is outside [0.02, 0.15] m"},
      {{1}, {0.01}, "height 0.01 m for cell 1 (airbag_0_1_link) is outside [0.02, 0.15] m"},
      {{0, 4}, {0.1, 0.1}, "cell 4 (airbag_1_1) is not reporting"},
      {{5}, {0.1}, "cell 5 (airbag_1_2) is not connected yet"},
  };
  Bed bed;
  ASSERT_TRUE(bed.posture("flat").ok);
  bed.run(2.5);
  bed.silent[4] = true;
  bed.connected[5] = false;
  bed.run(0.6);
  for (const Case& c : cases) {
    const nb::RequestResult r = bed.setHeights(c.ids, c.heights);
    EXPECT_FALSE(r.ok) << c.message;
    EXPECT_EQ(r.message, c.message);
    EXPECT_TRUE(bed.out.events.empty() && bed.out.commands.empty() && !bed.out.resume_record) << c.message;
  }
  EXPECT_EQ(bed.run(0.1).plan, nb::PlanKind::kSafeLevel);  // cell 4 died; no request changed that
}

TEST(BedSupervisor, EveryRefusedPostureRequestSaysWhyAndChangesNothing) {
  struct Case {
    std::string plan;
    std::vector<std::string> keys, values;
    std::string message;
  };
  const std::vector<Case> cases = {
      {"lateral_turn", {"side", "side"}, {"left", "right"}, "argument 'side' is given twice"},
      {"flat", {"height_m", "ramp_s"}, {"0.1"}, "2 keys but 1 values"},
      {"sit_up",
       {},
       {},
       "unknown plan 'sit_up' (known: adaptive, alternating, cpr, custom, flat, lateral_turn, max_inflate)"},
      {"safe_level", {}, {}, "unknown plan 'safe_level'"},
      {"flat", {"height_m"}, {"0x10"}, "flat: height_m must be a number"},
  };
  Bed bed;
  ASSERT_TRUE(bed.posture("flat").ok);
  bed.run(0.5);
  for (const Case& c : cases) {
    const nb::RequestResult r = bed.posture(c.plan, c.keys, c.values);
    EXPECT_FALSE(r.ok) << c.message;
    EXPECT_TRUE(contains(r.message, c.message)) << r.message;
    EXPECT_TRUE(bed.out.events.empty() && !bed.out.resume_record) << c.message;
  }
  const nb::BedStatus status = bed.run(0.1);
  EXPECT_EQ(status.plan, nb::PlanKind::kFlat);
  EXPECT_NEAR(status.elapsed_s, 0.6, 1e-6);
}

TEST(BedSupervisor, HugeUnicodeAndManyArgumentsAreRefusedWithoutQuotingThem) {
  Bed bed;
  ASSERT_TRUE(bed.posture("flat").ok);
  const std::string huge(40000, '9');
  const std::vector<std::tuple<std::string, std::vector<std::string>, std::vector<std::string>, std::string>> cases{
      {huge, {}, {}, "the plan name has 40000 characters (at most 64)"},
      {"fl\xc3\xa4t", {}, {}, "the plan name holds a character that is not printable ASCII (byte 195 at 2)"},
      {"flat", {"height_m"}, {huge}, "the value of 'height_m' has 40000 characters (at most 256)"},
      {"flat", {"height_m"}, {"\xef\xbc\x90.\xef\xbc\x91"}, "the value of 'height_m' holds a character"},
      {"flat", {std::string("h\0", 2)}, {"0.1"}, "argument 1's name holds a character that is not printable"},
      {"flat", std::vector<std::string>(33, "height_m"), std::vector<std::string>(33, "0.1"),
       "33 arguments (a plan takes at most 32)"},
      {"flat", {"height_m"}, {std::string(200, '1')}, "height_m must be a number of at most 64 characters"},
  };
  for (const auto& [plan, keys, values, message] : cases) {
    const nb::RequestResult r = bed.posture(plan, keys, values);
    EXPECT_FALSE(r.ok);
    EXPECT_TRUE(contains(r.message, message)) << r.message;
    EXPECT_LT(r.message.size(), 200u);
    EXPECT_TRUE(bed.out.commands.empty() && !bed.out.resume_record);
  }
  EXPECT_EQ(bed.run(0.1).plan, nb::PlanKind::kFlat);
}

TEST(BedSupervisor, AcceptedRequestsStartTheirPlanAndSaveIt) {
  Bed bed;
  const nb::RequestResult r = bed.posture("lateral_turn", {"side", "angle_deg"}, {"left", "20"});
  ASSERT_TRUE(r.ok) << r.message;
  EXPECT_EQ(r.message, "started lateral_turn side=left angle_deg=20 ramp_s=60 dwell_s=600 return=yes");
  ASSERT_TRUE(bed.out.resume_record);
  EXPECT_EQ(bed.out.resume_record->running.request.args.at("side"), "left");
  EXPECT_EQ(bed.out.resume_record->running.start_s, bed.now);
  EXPECT_TRUE(bed.logged(nb::BedEvent::Kind::kPlanStarted, "plan lateral_turn side=left"));
}

TEST(BedSupervisor, ManualHeightsKeepTheOtherCellsTargetsAsACustomPlan) {
  Bed bed;
  ASSERT_TRUE(bed.posture("flat", {"height_m"}, {"0.08"}).ok);
  bed.run(0.5);
  const nb::RequestResult r = bed.setHeights({2, 4}, {0.12, 0.05});
  ASSERT_TRUE(r.ok) << r.message;
  EXPECT_EQ(r.message, "set 2 cells as a custom plan, reached at 0.020000 m/s at most");
  ASSERT_TRUE(bed.out.resume_record);
  EXPECT_EQ(bed.out.resume_record->running.request.plan, "custom");
  EXPECT_EQ(bed.out.resume_record->running.request.heights_m,
            (std::vector<double>{0.08, 0.08, 0.12, 0.08, 0.05, 0.08}));
  const nb::BedStatus status = bed.run(0.1);
  EXPECT_EQ(status.plan, nb::PlanKind::kCustom);
  EXPECT_EQ(status.target_heights_m[2], 0.12);
  EXPECT_EQ(bed.setHeights({0}, {0.1}).message, "set 1 cell as a custom plan, reached at 0.020000 m/s at most");
}

// ---- what is sent -----------------------------------------------------------------------------

TEST(BedSupervisor, TargetsAreRateLimitedFromWhereTheCellsAre) {
  Bed bed;
  std::fill(bed.heights.begin(), bed.heights.end(), 0.05);
  ASSERT_TRUE(bed.posture("flat", {"height_m"}, {"0.15"}).ok);
  bed.step();  // the first step has no elapsed time: the ramp starts at the measured 0.05 m
  bed.sent = bed.out.commands;
  ASSERT_EQ(bed.setpoints().size(), 6u);
  EXPECT_NEAR(bed.setpoints().at(0), 0.05, 1e-12);
  double previous = 0.05;
  for (int i = 0; i < 40; ++i) {
    bed.run(0.1);
    const auto sent = bed.setpoints();
    ASSERT_TRUE(sent.count(0)) << i;
    EXPECT_LE(sent.at(0) - previous, 0.02 * 0.1 + 1e-9) << i;  // max_height_rate_m_s
    EXPECT_GT(sent.at(0), previous) << i;
    previous = sent.at(0);
  }
  EXPECT_NEAR(previous, 0.05 + 0.02 * 4.0, 1e-6);
  EXPECT_EQ(bed.run(0.1).target_heights_m[0], 0.15);  // ~state shows the plan's target
}

TEST(BedSupervisor, ASteadySetpointIsResentEveryResendPeriodAndANewPlanAtOnce) {
  nb::BedSupervisorParams params;
  params.resend_s = 0.95;
  Bed bed(params);
  ASSERT_TRUE(bed.posture("flat").ok);
  bed.step();
  EXPECT_EQ(bed.out.commands.size(), 6u);
  bed.run(0.9);
  EXPECT_TRUE(bed.sent.empty());  // nothing new, nothing due
  bed.run(0.1);
  EXPECT_EQ(bed.sent.size(), 6u);  // due: every cell once
  bed.run(0.1);
  EXPECT_TRUE(bed.sent.empty());
  // A new plan (same targets) sends everything at the next step.
  ASSERT_TRUE(bed.posture("flat").ok);
  bed.run(0.1);
  EXPECT_EQ(bed.setpoints().size(), 6u);
}

TEST(BedSupervisor, ARampSendsThePlansExactTargetAsSoonAsItArrivesNotAtTheResend) {
  nb::BedSupervisorParams params;
  params.resend_s = 5.0;
  Bed bed(params);
  std::fill(bed.heights.begin(), bed.heights.end(), 0.05);
  ASSERT_TRUE(bed.posture("flat", {"height_m"}, {"0.0501"}).ok);
  bed.step();  // the ramp starts at the measured 0.05 m
  // The last step of the ramp (0.1 mm) is below the change that is news, yet it is the target.
  bed.run(0.1);
  ASSERT_EQ(bed.setpoints().size(), 6u);
  for (const auto& [id, h] : bed.setpoints()) EXPECT_EQ(h, 0.0501) << "cell " << id;
  bed.run(1.0);
  EXPECT_TRUE(bed.sent.empty());  // arrived and sent: nothing new until the resend
}

TEST(BedSupervisor, VentAllVentsEveryCellThenOnlyEveryResendPeriod) {
  Bed bed;
  ASSERT_TRUE(bed.posture("flat").ok);
  bed.run(0.3);
  ASSERT_TRUE(bed.posture("cpr").ok);
  bed.run(0.1);
  EXPECT_EQ(bed.vents(), 6u);
  EXPECT_TRUE(bed.setpoints().empty());
  bed.run(0.8);
  EXPECT_EQ(bed.vents(), 0u);
  bed.run(0.3);
  EXPECT_EQ(bed.vents(), 6u);  // once per cell per resend period
  // After CPR the ramp starts again where the cells are, not where it was before.
  std::fill(bed.heights.begin(), bed.heights.end(), 0.01);
  ASSERT_TRUE(bed.posture("flat").ok);
  bed.run(0.1);
  ASSERT_EQ(bed.setpoints().size(), 6u);
  EXPECT_LE(bed.setpoints().at(0), 0.01 + 0.02 * 0.1 + 1e-9);
}

TEST(BedSupervisor, TheHeartbeatIsFedOnlyWhileAPlanRuns) {
  Bed bed;
  bed.run(0.1);
  EXPECT_FALSE(bed.out.heartbeat);
  ASSERT_TRUE(bed.posture("flat").ok);
  bed.run(0.1);
  EXPECT_TRUE(bed.out.heartbeat);
}

TEST(BedSupervisor, TheLargestStateGapIsMeasuredSinceThePlanStarted) {
  Bed bed;
  ASSERT_TRUE(bed.posture("flat").ok);
  bed.run(0.2);
  bed.silent[0] = true;
  bed.run(0.3);
  bed.silent[0] = false;
  EXPECT_NEAR(bed.run(0.1).largest_state_gap_s, 0.4, 1e-6);
  ASSERT_TRUE(bed.posture("flat").ok);
  EXPECT_NEAR(bed.run(0.1).largest_state_gap_s, 0.1, 1e-6);
}

// ---- tunables on a running bed (dynamic reconfigure) --------------------------------------------

TEST(BedSupervisor, NewAlarmThresholdsAndCellTimeoutActOnTheRunningBed) {
  Bed bed;
  ASSERT_TRUE(bed.posture("flat").ok);
  bed.run(1.0);
  nb::BedSupervisorParams tuned = bed.sup.params();
  tuned.leak_alarm_s = 5.0;
  tuned.leak_alarm_error_m = 0.012;
  tuned.cell_timeout_s = 0.25;
  ASSERT_EQ(bed.sup.setTunables(tuned), "");
  EXPECT_DOUBLE_EQ(bed.sup.params().leak_alarm_s, 5.0);
  bed.heights[1] = 0.089;  // 11 mm below: under the new error, no alarm however long
  EXPECT_TRUE(bed.run(6.0).alarms.empty());
  bed.heights[1] = 0.085;  // 15 mm below: the alarm after the new 5 s, not the old 15 s
  EXPECT_TRUE(bed.run(5.0).alarms.empty());
  nb::BedStatus status = bed.run(0.2);
  ASSERT_EQ(status.alarms.size(), 1u);
  EXPECT_TRUE(contains(status.alarms[0], "cell 1 (airbag_0_1) low pressure or leak")) << status.alarms[0];
  // Silent for 0.3 s: dead under the new timeout (the old 0.5 s would keep it alive).
  bed.silent[4] = true;
  status = bed.run(0.3);
  EXPECT_EQ(status.dead_cells, std::vector<std::uint32_t>{4});
}

TEST(BedSupervisor, NewPlanDefaultsApplyToPlansStartedAfterwards) {
  Bed bed;
  ASSERT_TRUE(bed.posture("flat").ok);
  EXPECT_EQ(bed.run(0.1).parameters, "height_m=0.1");
  nb::BedSupervisorParams tuned = bed.sup.params();
  tuned.plans.nominal_height_m = 0.08;
  tuned.plans.max_inflate_timeout_s = 300.0;
  ASSERT_EQ(bed.sup.setTunables(tuned), "");
  EXPECT_EQ(bed.run(0.1).parameters, "height_m=0.1") << "the running plan keeps its parameters";
  const nb::RequestResult r = bed.posture("flat");
  ASSERT_TRUE(r.ok) << r.message;
  EXPECT_EQ(bed.run(0.1).parameters, "height_m=0.08");
  EXPECT_DOUBLE_EQ(bed.sup.params().plans.max_inflate_timeout_s, 300.0);
}

TEST(BedSupervisor, InvalidTunablesAreRefusedNamingTheKeyAndChangeNothing) {
  nb::BedSupervisorParams params;
  params.plans.max_height_m = 0.14;
  Bed bed(params);
  const nb::BedSupervisorParams before = bed.sup.params();
  nb::BedSupervisorParams bad = before;
  bad.leak_alarm_s = 0.0;
  bad.cell_timeout_s = 2.0;  // valid, but refused with the rest
  EXPECT_TRUE(contains(bed.sup.setTunables(bad), "leak_alarm_s must be positive"));
  bad = before;
  bad.plans.nominal_height_m = 0.145;  // above the running plan limit
  bad.plans.max_height_m = 0.15;       // a limit: not taken, so it does not make room
  EXPECT_TRUE(contains(bed.sup.setTunables(bad), "plans:")) << bed.sup.setTunables(bad);
  bad = before;
  bad.plans.alternating_transition_s = 200.0;  // too long for the cycle
  EXPECT_TRUE(contains(bed.sup.setTunables(bad), "alternating")) << bed.sup.setTunables(bad);
  EXPECT_DOUBLE_EQ(bed.sup.params().leak_alarm_s, before.leak_alarm_s);
  EXPECT_DOUBLE_EQ(bed.sup.params().cell_timeout_s, before.cell_timeout_s);
  EXPECT_DOUBLE_EQ(bed.sup.params().plans.nominal_height_m, before.plans.nominal_height_m);
  EXPECT_DOUBLE_EQ(bed.sup.params().plans.alternating_transition_s, before.plans.alternating_transition_s);
  // Nothing changed in what the bed does: a flat plan at the old nominal height; a cell silent
  // for 1 s is dead under the old 0.5 s timeout, not alive under the refused 2 s.
  ASSERT_TRUE(bed.posture("flat").ok);
  EXPECT_EQ(bed.run(2.1).parameters, "height_m=0.1");
  bed.silent[0] = true;
  EXPECT_EQ(bed.run(1.0).dead_cells, std::vector<std::uint32_t>{0});
}

TEST(BedSupervisor, TunablesLeaveThePlanLimitsAndTheOtherSettingsAsTheyRun) {
  Bed bed;
  nb::BedSupervisorParams tuned = bed.sup.params();
  tuned.plans.max_height_m = 0.12;
  tuned.plans.max_tilt_deg = 10.0;
  tuned.resend_s = 5.0;
  tuned.leak_alarm_s = 20.0;
  ASSERT_EQ(bed.sup.setTunables(tuned), "");
  EXPECT_DOUBLE_EQ(bed.sup.params().leak_alarm_s, 20.0);
  EXPECT_DOUBLE_EQ(bed.sup.params().plans.max_height_m, 0.15);
  EXPECT_DOUBLE_EQ(bed.sup.params().plans.max_tilt_deg, nb::PlanConfig{}.max_tilt_deg);
  EXPECT_DOUBLE_EQ(bed.sup.params().resend_s, nb::BedSupervisorParams{}.resend_s);
  EXPECT_TRUE(bed.posture("lateral_turn", {"side", "angle_deg"}, {"left", "20"}).ok) << "the old tilt limit holds";
}

TEST(BedSupervisor, InvalidParametersAreRefusedNamingTheKey) {
  nb::BedSupervisorParams p;
  p.cell_timeout_s = 0.0;
  p.leak_alarm_s = -1.0;
  EXPECT_EQ(p.validate("~"),
            "~cell_timeout_s must be positive; ~leak_alarm_error_m and ~leak_alarm_s must be positive");
  try {
    Bed bed(p);
    FAIL() << "accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_TRUE(contains(e.what(), "cell_timeout_s must be positive")) << e.what();
  }
  nb::BedSupervisorParams plans;
  plans.plans.max_tilt_deg = 50.0;
  EXPECT_TRUE(contains(plans.validate(), "plans: max_tilt_deg")) << plans.validate();
}

}  // namespace
