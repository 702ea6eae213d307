// The running posture plan of the bed supervisor (ROS-free): which plan runs since when, what a
// max_inflate interrupted (it goes back to that plan where it left off when it times out), and
// the resume record that lets a restarted supervisor carry on. Times are seconds on the
// caller's clock.
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "nursing_bed/core/bed/posture_plans.h"

namespace nursing_bed {

/// A plan as the resume record keeps it: the request that made it and when it started.
struct SavedPlan {
  PlanRequest request;
  double start_s = 0.0;  ///< [s]
};

/// What a restarted supervisor needs to carry on: the running plan, and what a running
/// max_inflate interrupted.
struct ResumeRecord {
  SavedPlan running;
  std::optional<SavedPlan> interrupted;
};

/// A plan with its start and the request that made it.
struct RunningPlan {
  std::shared_ptr<PosturePlan> plan;  ///< null: none (shared: a max_inflate keeps what it interrupted)
  double start_s = 0.0;               ///< [s]
  PlanRequest request;
};

class PlanRunner {
 public:
  PlanRunner(PlanConfig config, BedGrid grid, BodyFootprint body);

  /// makePlan on this bed (nullptr and why when the request is refused).
  std::unique_ptr<PosturePlan> make(const PlanRequest& request, std::string* error) const;
  /// The supervisor's own plan after a cell failed: every cell at `height_m`.
  RunningPlan safeLevel(double height_m, double start_s) const;

  /// Runs `next`. A max_inflate keeps the plan it interrupts (another max_inflate keeps the one
  /// it had); any other plan forgets it.
  void start(RunningPlan next);
  /// Runs a saved record's plan (and, under a max_inflate, what it interrupted). Refuses, and
  /// nothing changes, when the plan cannot be rebuilt or its start is not in (0, now_s]; a bad
  /// interrupted plan is only dropped. Each refusal is added to *refused as "the saved plan
  /// 'P' cannot be resumed (why)".
  bool resume(const ResumeRecord& record, double now_s, std::vector<std::string>* refused);
  /// The targets at `now_s`. A max_inflate that has run its course first reverts (*reverted):
  /// to the plan it interrupted, shifted so that it carries on where it left off, else to
  /// safe_level at the nominal height. `sensed`: what the cells sense now, for plans that act
  /// on it (PosturePlan::sensedTargets).
  PlanTargets targets(double now_s, bool* reverted, const SensedCells& sensed = SensedCells{});

  bool running() const { return static_cast<bool>(running_.plan); }
  /// A plan of this kind runs.
  bool runs(PlanKind kind) const { return running_.plan && running_.plan->kind() == kind; }
  const RunningPlan& current() const { return running_; }
  const RunningPlan& interrupted() const { return interrupted_; }
  /// The running plan's record (call only while running()).
  ResumeRecord record() const;
  const PlanConfig& config() const { return config_; }
  /// A new configuration (valid, checked by the caller) for the plans made from now on; the
  /// running plan keeps the one it was made with.
  void setConfig(PlanConfig config) { config_ = std::move(config); }

 private:
  std::optional<RunningPlan> restore(const SavedPlan& saved, double now_s, std::string* why) const;

  PlanConfig config_;
  BedGrid grid_;
  BodyFootprint body_;
  RunningPlan running_, interrupted_;
};

}  // namespace nursing_bed
