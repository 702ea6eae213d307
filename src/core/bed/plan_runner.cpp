#include "nursing_bed/core/bed/plan_runner.h"

namespace nursing_bed {

PlanRunner::PlanRunner(PlanConfig config, BedGrid grid, BodyFootprint body)
    : config_(std::move(config)), grid_(grid), body_(body) {}

std::unique_ptr<PosturePlan> PlanRunner::make(const PlanRequest& request, std::string* error) const {
  return makePlan(request, config_, grid_, body_, error);
}

RunningPlan PlanRunner::safeLevel(double height_m, double start_s) const {
  return RunningPlan{makeSafeLevelPlan(grid_, height_m), start_s,
                     PlanRequest{planKindName(PlanKind::kSafeLevel), {}, {height_m}}};
}

void PlanRunner::start(RunningPlan next) {
  const bool inflate = next.plan->kind() == PlanKind::kMaxInflate;
  if (inflate && running_.plan && !runs(PlanKind::kMaxInflate)) interrupted_ = running_;
  else if (!inflate) interrupted_ = RunningPlan{};
  running_ = std::move(next);
}

std::optional<RunningPlan> PlanRunner::restore(const SavedPlan& saved, double now_s, std::string* why) const {
  const PlanRequest& request = saved.request;
  std::unique_ptr<PosturePlan> plan;
  // safe_level is the supervisor's own plan: not a request makePlan takes.
  if (planKindFromName(request.plan) == PlanKind::kSafeLevel && request.heights_m.size() == 1)
    plan = makeSafeLevelPlan(grid_, request.heights_m[0]);
  else plan = make(request, why);
  if (plan && (!(saved.start_s > 0.0) || saved.start_s > now_s)) {
    *why = "bad start time " + std::to_string(saved.start_s);
    plan.reset();
  }
  if (!plan) return std::nullopt;
  return RunningPlan{std::move(plan), saved.start_s, request};
}

bool PlanRunner::resume(const ResumeRecord& record, double now_s, std::vector<std::string>* refused) {
  auto refuse = [&](const SavedPlan& saved, const std::string& why) {
    refused->push_back("the saved plan '" + saved.request.plan + "' cannot be resumed (" + why + ")");
  };
  std::string why;
  std::optional<RunningPlan> saved = restore(record.running, now_s, &why);
  if (!saved) {
    refuse(record.running, why);
    return false;
  }
  std::optional<RunningPlan> before;
  if (record.interrupted) {
    before = restore(*record.interrupted, now_s, &why);
    if (!before) refuse(*record.interrupted, why);
  }
  interrupted_ = before && saved->plan->kind() == PlanKind::kMaxInflate ? *before : RunningPlan{};
  running_ = std::move(*saved);
  return true;
}

PlanTargets PlanRunner::targets(double now_s, bool* reverted, const SensedCells& sensed) {
  *reverted = false;
  if (!running_.plan) return PlanTargets{};
  const double elapsed_s = now_s - running_.start_s;
  PlanTargets t = running_.plan->sensedTargets(elapsed_s, sensed);
  if (!(t.finished && runs(PlanKind::kMaxInflate))) return t;
  // Back to what max_inflate interrupted, where it left off: its clock stood still meanwhile.
  if (interrupted_.plan)
    running_ = RunningPlan{interrupted_.plan, interrupted_.start_s + elapsed_s, interrupted_.request};
  else running_ = safeLevel(config_.nominal_height_m, now_s);
  interrupted_ = RunningPlan{};
  *reverted = true;
  return running_.plan->sensedTargets(now_s - running_.start_s, sensed);
}

ResumeRecord PlanRunner::record() const {
  ResumeRecord r{SavedPlan{running_.request, running_.start_s}, std::nullopt};
  if (interrupted_.plan) r.interrupted = SavedPlan{interrupted_.request, interrupted_.start_s};
  return r;
}

}  // namespace nursing_bed
