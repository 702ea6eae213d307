// The bed supervisor (ROS-free): the bed's policy between a nurse's intent and the cells. It
// runs posture plans and manual heights (requests checked, refusals with the reason), sends the
// cells rate-limited setpoints or vents, levels the bed at the healthy cells' mean height when
// a cell dies or reports a fault, raises the leak alarm, reverts a timed-out max_inflate,
// follows CPR started from outside, and resumes a saved plan after a restart. The caller (the
// bed manager node, or a test) feeds it cell states and requests, calls step() at the plan
// rate, and carries out what takeOutput() returns. Times are seconds on the caller's clock,
// simulated or wall. Not thread-safe: the caller serialises calls. doc/bed_manager.md.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "nursing_bed/core/bed/bed_grid.h"
#include "nursing_bed/core/bed/cell_commander.h"
#include "nursing_bed/core/bed/cell_health.h"
#include "nursing_bed/core/bed/leak_watch.h"
#include "nursing_bed/core/bed/plan_runner.h"
#include "nursing_bed/core/bed/posture_plans.h"

namespace nursing_bed {

struct BedSupervisorParams {
  double cell_timeout_s = 0.45;  ///< a cell silent this long is dead [s] (watched at ~50 Hz: dead within 0.5 s)
  /// Cells are judged once every cell reports, or this long after the start: a cell that never
  /// reported is dead only then (a loaded machine takes seconds to load a whole bed) [s].
  double startup_grace_s = 60.0;
  double resend_s = 1.0;             ///< setpoints and vents are repeated this often [s]
  double leak_alarm_error_m = 0.01;  ///< a cell this far below its target ... [m]
  double leak_alarm_s = 15.0;        ///< ... for this long raises the leak alarm [s]
  /// Fastest change of a cell's target outside CPR (the cells' safety/max_height_rate_m_s) [m/s].
  double max_height_rate_m_s = 0.02;
  PlanConfig plans;
  BodyFootprint body;
  /// Empty when valid, else every problem; keys are named with `key_prefix` before them (a string,
  /// not a Status, while BedManagerParams::validate() appends it to its own string).
  std::string validate(const std::string& key_prefix = "") const;
};

/// Something the supervisor did or saw, for the log.
struct BedEvent {
  enum class Kind { kPlanStarted, kPlanReverted, kPlanResumed, kResumeRefused, kCellFailed, kCprFollowed };
  Kind kind;
  Severity severity;
  std::string text;
};

/// What the supervisor is doing (the bed manager's ~state).
struct BedStatus {
  std::optional<PlanKind> plan;          ///< nullopt: no plan runs
  std::string phase;                     ///< the last targets' phase
  std::string parameters;                ///< the plan's parameters after defaults
  double elapsed_s = 0.0;                ///< since the plan started [s]
  double tilt_deg = 0.0;                 ///< lateral turn commanded now [deg]
  std::vector<double> target_heights_m;  ///< by cell id; NaN where none (venting)
  std::vector<std::uint32_t> dead_cells, faulty_cells;
  std::vector<std::uint32_t> unverified_cells;  ///< reporting cells whose estimated height is not proven
  double largest_state_gap_s = 0.0;  ///< longest wait between two states of one cell since the plan started [s]
  std::vector<std::string> alarms;
};

/// The bed on diagnostics: a summary and one report per cell (by id).
struct BedReport {
  Severity severity = Severity::kOk;  ///< error when a cell is not reporting, warn on faults or alarms
  std::string message;                ///< "N cells, D not reporting, F with faults, U unverified[; first alarm]"
  std::vector<std::string> alarms;
  std::string plan;  ///< "plan (phase)[, resumed ...]"; "" when no plan runs
  std::vector<CellReport> cells;
};

/// What the caller must carry out after a call: publish, log, store.
struct SupervisorOutput {
  bool heartbeat = false;                     ///< feed the cells' command watchdog
  std::vector<CellCommand> commands;          ///< setpoints and vents, in order
  std::vector<BedEvent> events;               ///< for the log
  std::optional<ResumeRecord> resume_record;  ///< store it (replacing the stored one)
  std::optional<bool> cpr;                    ///< announce bed-wide CPR on or off
};

/// The answer to a request.
struct RequestResult {
  bool ok = false;
  std::string message;  ///< what was done, or why nothing was
};

class BedSupervisor {
 public:
  /// `cells` by id, on `grid`; `now_s` starts the start-up grace. The plan height limits are
  /// narrowed to the cells' and the body rows to the grid. Throws std::invalid_argument when
  /// the parameters are not valid.
  BedSupervisor(BedSupervisorParams params, const BedGrid& grid, std::vector<BedCell> cells, double now_s);

  /// A cell's state as it arrived (snapshot.seen_s); false for an id that is not a cell.
  bool onCellState(const CellSnapshot& snapshot);
  /// Runs the plan of a saved record, if there is one that can be resumed at `now_s`.
  RequestResult resume(const std::optional<ResumeRecord>& record, double now_s);
  /// Starts a plan: `keys`/`values` its arguments, `heights_m` a custom plan's heights.
  RequestResult setPosture(const std::string& plan, const std::vector<std::string>& keys,
                           const std::vector<std::string>& values, const std::vector<double>& heights_m, double now_s);
  /// Sets cells' heights, all or nothing, as a custom plan (the other cells keep their
  /// targets). `connected` by cell id: something listens to the cell's setpoints.
  RequestResult setHeights(const std::vector<std::uint32_t>& ids, const std::vector<double>& heights_m,
                           const std::vector<bool>& connected, double now_s);
  /// Bed-wide CPR announced by anyone: on, the supervisor follows it.
  void onCpr(bool on, double now_s);
  /// One plan step at `now_s`: watches the cells, evaluates the plan, queues the commands.
  BedStatus step(double now_s);
  /// Watches the cells at `now_s` between plan steps (a dead cell is acted on sooner than the
  /// plan rate allows): levels the bed if a cell failed. Returns how many newly failed, plus one
  /// when the set of cells with a lost hardware link changed.
  std::size_t watch(double now_s);
  /// What the calls since the last takeOutput() want done.
  SupervisorOutput takeOutput();
  /// Diagnostics at `now_s`.
  BedReport report(double now_s) const;

  /// What an operator may change on a running bed (dynamic reconfigure): takes `params`'
  /// cell_timeout_s, leak alarm thresholds and plan defaults (for plans started afterwards) and
  /// returns "", or returns why not and changes nothing. The rest keeps its running values:
  /// the plan limits (heights, tilt, tilt rates: the envelope the rate limiter was built with),
  /// resend_s, startup_grace_s, max_height_rate_m_s and the body.
  std::string setTunables(const BedSupervisorParams& params);

  const CellHealthWatcher& health() const { return health_; }
  const BedSupervisorParams& params() const { return params_; }

 private:
  /// Runs `next` from its start_s.
  void start(RunningPlan next);
  /// After a plan starts or resumes: every target sent again, CPR announced, the record saved.
  void started();
  void announceCpr(bool on);
  /// After a requested plan: CPR announced off when no announcement was ever made.
  void endUnknownCpr();
  void saveResume();
  /// Height the bed levels at when a cell fails: the healthy cells' mean within the plan limits
  /// (the nominal height when none is known).
  double safeLevel() const;
  std::size_t watchCells(double now_s);
  /// The cells' last gauge pressures and load estimates (NaN for dead or faulty cells).
  SensedCells sensed() const;
  /// The current targets with `ids` set to `heights_m` (the others: the plan's target, else
  /// what was sent, else the measured height, within the plan limits).
  std::vector<double> customTargets(const std::vector<std::uint32_t>& ids, const std::vector<double>& heights_m) const;
  void log(BedEvent::Kind kind, Severity severity, std::string text);

  BedSupervisorParams params_;
  CellHealthWatcher health_;
  LeakWatch leaks_;
  CellCommander commander_;
  PlanRunner runner_;
  std::vector<std::string> alarms_;
  std::string link_lost_;  ///< the cells whose hardware link was lost at the last watch
  PlanTargets last_targets_;
  double last_step_s_ = CellSnapshot::kNone;
  int cpr_announced_ = -1;  ///< last CPR announcement (-1: none)
  bool resumed_ = false;    ///< the plan was resumed from a record
  SupervisorOutput out_;
};

}  // namespace nursing_bed
