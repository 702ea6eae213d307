#include "nursing_bed/core/bed/bed_supervisor.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include "nursing_bed/core/bed/request_validator.h"
#include "nursing_bed/core/io/errors.h"
#include "nursing_bed/core/physics/units.h"

namespace nursing_bed {
namespace {

std::string fixed(double v, int digits) {
  std::ostringstream s;
  s.setf(std::ios::fixed);
  s.precision(digits);
  s << v;
  return s.str();
}

// The parameters checked, with the plan limits narrowed to the cells' and the body to the grid.
BedSupervisorParams narrowed(BedSupervisorParams p, const BedGrid& grid) {
  const std::string error = p.validate();
  if (!error.empty()) throw std::invalid_argument("BedSupervisor: " + error);
  p.plans.max_height_m = std::min(p.plans.max_height_m, grid.max_height_m);
  p.body.last_row = std::min(p.body.last_row, grid.rows - 1);
  p.body.first_row = std::min(p.body.first_row, p.body.last_row);
  return p;
}

RateLimits rateLimits(const BedSupervisorParams& p, const BedGrid& grid) {
  RateLimits limits;
  limits.max_rate_per_s = p.max_height_rate_m_s;
  limits.slope_weights = rollSlopeWeights(grid, p.body);
  limits.max_angle_rate_rad_s = p.plans.bed_tilt_rate_fraction * p.plans.max_tilt_rate_deg_s * kPi / 180.0;
  return limits;
}

}  // namespace

std::string BedSupervisorParams::validate(const std::string& key_prefix) const {
  const std::string& k = key_prefix;
  ErrorList errors;
  errors.addIf(!(cell_timeout_s > 0.0), k, "cell_timeout_s must be positive");
  errors.addIf(!(startup_grace_s >= 0.0), k, "startup_grace_s must be >= 0");
  errors.addIf(!(resend_s > 0.0), k, "resend_s must be positive");
  errors.addIf(!(max_height_rate_m_s > 0.0 && std::isfinite(max_height_rate_m_s)),
               "the cells' safety/max_height_rate_m_s must be positive");
  errors.addIf(!(leak_alarm_error_m > 0.0 && leak_alarm_s > 0.0), k, "leak_alarm_error_m and ", k,
               "leak_alarm_s must be positive");
  errors.addIf(body.first_row < 0 || body.last_row < body.first_row, k,
               "body rows must satisfy 0 <= first_row <= last_row");
  errors.addNested(plans.validate(), k + "plans: ");
  return errors.text();
}

BedSupervisor::BedSupervisor(BedSupervisorParams params, const BedGrid& grid, std::vector<BedCell> cells, double now_s)
    : params_(narrowed(std::move(params), grid)),
      health_(cells, params_.cell_timeout_s, params_.startup_grace_s, now_s),
      leaks_(cells.size(), params_.leak_alarm_error_m, params_.leak_alarm_s),
      commander_(cells, rateLimits(params_, grid), params_.resend_s),
      runner_(params_.plans, grid, params_.body) {}

std::string BedSupervisor::setTunables(const BedSupervisorParams& params) {
  BedSupervisorParams next = params_;
  next.cell_timeout_s = params.cell_timeout_s;
  next.leak_alarm_error_m = params.leak_alarm_error_m;
  next.leak_alarm_s = params.leak_alarm_s;
  next.plans = params.plans;
  next.plans.min_height_m = params_.plans.min_height_m;
  next.plans.max_height_m = params_.plans.max_height_m;
  next.plans.max_tilt_deg = params_.plans.max_tilt_deg;
  next.plans.max_tilt_rate_deg_s = params_.plans.max_tilt_rate_deg_s;
  next.plans.bed_tilt_rate_fraction = params_.plans.bed_tilt_rate_fraction;
  const std::string error = next.validate();
  if (!error.empty()) return error;
  params_ = next;
  health_.setTimeout(params_.cell_timeout_s);
  leaks_.setThresholds(params_.leak_alarm_error_m, params_.leak_alarm_s);
  runner_.setConfig(params_.plans);
  return "";
}

bool BedSupervisor::onCellState(const CellSnapshot& snapshot) { return health_.record(snapshot); }

SupervisorOutput BedSupervisor::takeOutput() {
  SupervisorOutput out = std::move(out_);
  out_ = SupervisorOutput{};
  return out;
}

void BedSupervisor::log(BedEvent::Kind kind, Severity severity, std::string text) {
  out_.events.push_back(BedEvent{kind, severity, std::move(text)});
}

void BedSupervisor::announceCpr(bool on) {
  out_.cpr = on;
  cpr_announced_ = on ? 1 : 0;
}

void BedSupervisor::saveResume() {
  if (runner_.running()) out_.resume_record = runner_.record();
}

void BedSupervisor::started() {
  health_.resetLargestGap();
  commander_.resendAll();  // send every target at once
  if (runner_.runs(PlanKind::kCpr)) announceCpr(true);
  else if (cpr_announced_ == 1) announceCpr(false);
  saveResume();
}

void BedSupervisor::start(RunningPlan next) {
  runner_.start(std::move(next));
  started();
  const RunningPlan& p = runner_.current();
  log(BedEvent::Kind::kPlanStarted, Severity::kOk, "plan " + p.plan->name() + " " + p.plan->describe());
}

RequestResult BedSupervisor::resume(const std::optional<ResumeRecord>& record, double now_s) {
  if (!record) return {false, "no saved plan"};
  std::vector<std::string> refused;
  const bool ok = runner_.resume(*record, now_s, &refused);
  for (const std::string& r : refused) log(BedEvent::Kind::kResumeRefused, Severity::kError, "restarted, but " + r);
  if (!ok) return {false, refused.front()};
  resumed_ = true;
  started();
  const RunningPlan& p = runner_.current();
  const RunningPlan& before = runner_.interrupted();
  const std::string text = "restarted: resuming plan " + p.request.plan + " (" + p.plan->describe() + "), started " +
                           fixed(now_s - p.start_s, 1) + " s ago" +
                           (before.plan ? ", then back to " + before.request.plan : "");
  log(BedEvent::Kind::kPlanResumed, Severity::kWarn, text);
  return {true, text};
}

RequestResult BedSupervisor::setPosture(const std::string& plan, const std::vector<std::string>& keys,
                                        const std::vector<std::string>& values, const std::vector<double>& heights_m,
                                        double now_s) {
  PlanRequest request;
  std::string why;
  if (!postureRequest(plan, keys, values, heights_m, &request, &why)) return {false, why};
  std::unique_ptr<PosturePlan> made = runner_.make(request, &why);
  if (!made) return {false, why};
  const std::string description = made->name() + " " + made->describe();
  start(RunningPlan{std::move(made), now_s, request});
  endUnknownCpr();
  return {true, "started " + description};
}

std::vector<double> BedSupervisor::customTargets(const std::vector<std::uint32_t>& ids,
                                                 const std::vector<double>& heights_m) const {
  const std::size_t n = health_.cells().size();
  const PlanConfig& plans = params_.plans;
  std::vector<double> target(n, CellSnapshot::kNone);
  const bool planned = !last_targets_.vent_all && last_targets_.heights_m.size() == n;
  const std::vector<double> measured = health_.heights();
  for (std::uint32_t id = 0; id < n; ++id) {
    double h = planned ? last_targets_.heights_m[id] : CellSnapshot::kNone;
    if (!std::isfinite(h)) h = std::isfinite(commander_.sentHeight(id)) ? commander_.sentHeight(id) : measured[id];
    target[id] = std::isfinite(h) ? std::clamp(h, plans.min_height_m, plans.max_height_m) : CellSnapshot::kNone;
  }
  for (std::size_t i = 0; i < ids.size(); ++i) target[ids[i]] = heights_m[i];
  return target;
}

RequestResult BedSupervisor::setHeights(const std::vector<std::uint32_t>& ids, const std::vector<double>& heights_m,
                                        const std::vector<bool>& connected, double now_s) {
  if (runner_.runs(PlanKind::kCpr))
    return {false, "CPR is running: start a plan (e.g. flat) to end it before setting heights"};
  const std::string error = checkCellHeights(ids, heights_m, params_.plans, health_, connected, now_s);
  if (!error.empty()) return {false, error};
  std::vector<double> target = customTargets(ids, heights_m);
  PlanRequest request{planKindName(PlanKind::kCustom), {}, target};
  start(RunningPlan{makeCustomPlan(std::move(target)), now_s, std::move(request)});
  endUnknownCpr();
  return {true, "set " + std::to_string(ids.size()) + (ids.size() == 1 ? " cell" : " cells") +
                    " as a custom plan, reached at " + std::to_string(params_.max_height_rate_m_s) + " m/s at most"};
}

void BedSupervisor::onCpr(bool on, double now_s) {
  if (!on || runner_.runs(PlanKind::kCpr)) return;
  log(BedEvent::Kind::kCprFollowed, Severity::kWarn, "bed-wide CPR started from outside: following it");
  std::string why;
  const PlanRequest request{planKindName(PlanKind::kCpr), {}, {}};
  start(RunningPlan{runner_.make(request, &why), now_s, request});
}

void BedSupervisor::endUnknownCpr() {
  // A CPR begun while no supervisor listened (its latched announcement gone with its publisher)
  // leaves the cells venting: a plan a nurse asks for ends it. Never on a resume or a cell's
  // failure, which must not end a CPR that may be running.
  if (cpr_announced_ == -1 && !runner_.runs(PlanKind::kCpr)) announceCpr(false);
}

double BedSupervisor::safeLevel() const {
  // The healthy cells' targets, not their heights: a rig restarted empty leaves every cell near
  // flat while the plan the patient lay on still stands, and the bed refills to it.
  const PlanConfig& plans = params_.plans;
  const double level = health_.healthyMeanHeight(commander_.sentHeights()).value_or(plans.nominal_height_m);
  return std::clamp(level, plans.min_height_m, plans.max_height_m);
}

std::size_t BedSupervisor::watch(double now_s) { return watchCells(now_s); }

std::size_t BedSupervisor::watchCells(double now_s) {
  alarms_.clear();
  const std::vector<std::string> failed = health_.watch(now_s);
  std::string link_lost;
  for (const BedCell& c : health_.cells()) {
    const bool silent = health_.dead(c.id) || !health_.reported(c.id);
    const std::string alarm =
        leaks_.update(c, silent, health_.state(c.id).height_m, commander_.sentHeight(c.id), now_s);
    if (!alarm.empty()) alarms_.push_back(alarm);
    if (!silent && (health_.state(c.id).faults & kFaultCommunication))
      link_lost += (link_lost.empty() ? "" : ", ") + std::to_string(c.id) + " (" + c.name + ")";
  }
  // A lost terminal leaves its cells holding their gas, uncontrolled: the bed's first alarm.
  // They keep their targets and resume the plan when the link returns.
  if (!link_lost.empty())
    alarms_.insert(alarms_.begin(), "hardware link lost (cells holding their gas, mode SAFE): cells " + link_lost);
  const std::size_t link_changed = link_lost != link_lost_ ? 1 : 0;
  if (link_changed && !link_lost.empty()) log(BedEvent::Kind::kCellFailed, Severity::kError, alarms_.front());
  link_lost_ = link_lost;
  if (failed.empty()) return link_changed;
  // Keep the patient level, at the healthy cells' mean height, reached at the limited rates.
  const double h = safeLevel();
  for (const std::string& f : failed)
    log(BedEvent::Kind::kCellFailed, Severity::kError, f + "; levelling the bed at " + fixed(h, 3) + " m");
  if (!runner_.runs(PlanKind::kCpr)) start(runner_.safeLevel(h, now_s));
  return failed.size() + link_changed;
}

SensedCells BedSupervisor::sensed() const {
  SensedCells s;
  for (const BedCell& c : health_.cells()) {
    // A dead or faulty cell's last readings are not evidence of the load on it now.
    const bool trusted = !health_.dead(c.id) && !health_.faulty(c.id);
    s.gauge_pressure_pa.push_back(trusted ? health_.state(c.id).gauge_pressure_pa : CellSnapshot::kNone);
    s.load_n.push_back(trusted ? health_.state(c.id).external_load_n : CellSnapshot::kNone);
  }
  return s;
}

BedStatus BedSupervisor::step(double now_s) {
  // The cells' command watchdog: fed while the supervisor runs the bed (has a plan).
  out_.heartbeat = out_.heartbeat || runner_.running();
  const double dt_s = std::isfinite(last_step_s_) ? std::max(0.0, now_s - last_step_s_) : 0.0;
  last_step_s_ = now_s;
  watchCells(now_s);
  BedStatus status;
  status.largest_state_gap_s = health_.largestGapS();
  if (runner_.running()) {
    bool reverted = false;
    const PlanTargets t = runner_.targets(now_s, &reverted, sensed());
    if (reverted) {
      saveResume();
      commander_.resendAll();
      log(BedEvent::Kind::kPlanReverted, Severity::kOk,
          "max_inflate timed out, back to " + runner_.current().plan->name());
    }
    const std::vector<CellCommand> commands = commander_.command(t, health_.heights(), dt_s, now_s);
    out_.commands.insert(out_.commands.end(), commands.begin(), commands.end());
    last_targets_ = t;
    status.plan = runner_.current().plan->kind();
    status.parameters = runner_.current().plan->describe();
    status.elapsed_s = now_s - runner_.current().start_s;
  }
  status.phase = last_targets_.phase;
  status.tilt_deg = last_targets_.tilt_deg;
  status.target_heights_m = last_targets_.vent_all ? std::vector<double>(health_.cells().size(), CellSnapshot::kNone)
                                                   : last_targets_.heights_m;
  status.dead_cells = health_.deadCells();
  status.faulty_cells = health_.faultyCells();
  status.unverified_cells = health_.unverifiedCells();
  status.alarms = alarms_;
  return status;
}

BedReport BedSupervisor::report(double now_s) const {
  BedReport r;
  int dead = 0, faulty = 0, unlinked = 0;
  for (const BedCell& c : health_.cells()) {
    r.cells.push_back(health_.report(c.id, now_s));
    const bool error = r.cells.back().severity == Severity::kError;
    const bool link_lost = error && health_.reporting(c.id, now_s);  // reporting, but its link is down
    dead += error && !link_lost;
    unlinked += link_lost;
    faulty += r.cells.back().severity == Severity::kWarn && health_.state(c.id).faults != kFaultNone;
  }
  r.alarms = alarms_;
  const std::size_t unverified = health_.unverifiedCells().size();
  r.severity = (dead || unlinked)                           ? Severity::kError
               : (faulty || unverified || !alarms_.empty()) ? Severity::kWarn
                                                            : Severity::kOk;
  r.message = std::to_string(r.cells.size()) + " cells, " + std::to_string(dead) + " not reporting, " +
              (unlinked ? std::to_string(unlinked) + " with a lost hardware link, " : "") + std::to_string(faulty) +
              " with faults, " + std::to_string(unverified) + " unverified" +
              (alarms_.empty() ? "" : "; " + alarms_.front());
  if (runner_.running())
    r.plan = runner_.current().plan->name() + " (" + last_targets_.phase + ")" +
             (resumed_ ? ", resumed after a restart of the bed manager" : "");
  return r;
}

}  // namespace nursing_bed
