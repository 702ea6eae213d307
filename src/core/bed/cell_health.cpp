#include "nursing_bed/core/bed/cell_health.h"

#include <cmath>
#include <stdexcept>

namespace nursing_bed {
namespace {
constexpr double kStartUpSettleS = 2.0;  ///< see CellHealthWatcher::watch
}  // namespace

CellHealthWatcher::CellHealthWatcher(std::vector<BedCell> cells, double timeout_s, double startup_grace_s,
                                     double started_s)
    : cells_(std::move(cells)),
      states_(cells_.size()),
      dead_(cells_.size(), false),
      faulty_(cells_.size(), false),
      timeout_s_(timeout_s),
      startup_grace_s_(startup_grace_s),
      started_s_(started_s) {
  for (std::size_t i = 0; i < cells_.size(); ++i) {
    if (cells_[i].id != i) throw std::invalid_argument("CellHealthWatcher: cells must be given by id");
    states_[i].id = cells_[i].id;
  }
}

bool CellHealthWatcher::record(const CellSnapshot& state) {
  if (state.id >= states_.size()) return false;
  const double previous = states_[state.id].seen_s;
  // What the dead-cell timeout has as margin: the longest silence of a live cell.
  if (std::isfinite(previous) && std::isfinite(state.seen_s))
    largest_gap_s_ = std::max(largest_gap_s_, state.seen_s - previous);
  states_[state.id] = state;
  return true;
}

bool CellHealthWatcher::reported(std::uint32_t id) const { return std::isfinite(states_.at(id).seen_s); }

bool CellHealthWatcher::reporting(std::uint32_t id, double now_s) const {
  return reported(id) && now_s - states_.at(id).seen_s <= timeout_s_;
}

std::vector<std::string> CellHealthWatcher::watch(double now_s) {
  if (!judging()) {
    bool all_reporting = true;
    for (const BedCell& c : cells_) all_reporting = all_reporting && reporting(c.id, now_s);
    // The cells loaded last still stall for a moment after their first state: silences count
    // from kStartUpSettleS after every cell first reported at once.
    if (all_reporting) judged_from_s_ = now_s + kStartUpSettleS;
    else if (now_s - started_s_ > startup_grace_s_) judged_from_s_ = now_s;
  }
  std::vector<std::string> failed;
  for (const BedCell& c : cells_) {
    const CellSnapshot& s = states_[c.id];
    const bool never = !reported(c.id);
    // A silence counts from the end of the start-up at the earliest.
    const bool dead = judging() && (never || now_s - std::max(s.seen_s, judged_from_s_) > timeout_s_);
    const bool faulty = !dead && !never && (s.faults & kFaultsThatFailACell);
    if ((dead && !dead_[c.id]) || (faulty && !faulty_[c.id])) {
      failed.push_back("cell " + std::to_string(c.id) + " (" + c.name + ") " +
                       (dead ? "stopped reporting"
                             : "reports a sensor or model fault (faults " + std::to_string(s.faults) + ", " +
                                   std::to_string(s.gauge_pressure_pa) + " Pa, " + std::to_string(s.height_m) +
                                   " m, load " + std::to_string(s.external_load_n) + " N)"));
    }
    dead_[c.id] = dead;
    faulty_[c.id] = faulty;
  }
  return failed;
}

std::vector<std::uint32_t> CellHealthWatcher::deadCells() const {
  std::vector<std::uint32_t> ids;
  for (const BedCell& c : cells_)
    if (dead_[c.id]) ids.push_back(c.id);
  return ids;
}

std::vector<std::uint32_t> CellHealthWatcher::faultyCells() const {
  std::vector<std::uint32_t> ids;
  for (const BedCell& c : cells_)
    if (faulty_[c.id]) ids.push_back(c.id);
  return ids;
}

std::vector<std::uint32_t> CellHealthWatcher::unverifiedCells() const {
  std::vector<std::uint32_t> ids;
  for (const BedCell& c : cells_)
    if (!dead_[c.id] && states_[c.id].unverified) ids.push_back(c.id);
  return ids;
}

std::vector<double> CellHealthWatcher::heights() const {
  std::vector<double> h(cells_.size(), CellSnapshot::kNone);
  for (const BedCell& c : cells_)
    if (reported(c.id)) h[c.id] = states_[c.id].height_m;
  return h;
}

std::optional<double> CellHealthWatcher::healthyMeanHeight(const std::vector<double>& held_m) const {
  double sum = 0.0;
  int n = 0;
  for (const BedCell& c : cells_) {
    const double held = c.id < held_m.size() ? held_m[c.id] : CellSnapshot::kNone;
    const double h = std::isfinite(held) ? held : states_[c.id].height_m;
    if (dead_[c.id] || faulty_[c.id] || !reported(c.id) || !std::isfinite(h)) continue;
    sum += h;
    ++n;
  }
  if (n == 0) return std::nullopt;
  return sum / n;
}

CellReport CellHealthWatcher::report(std::uint32_t id, double now_s) const {
  const CellSnapshot& s = states_.at(id);
  const double age_s = reported(id) ? now_s - s.seen_s : INFINITY;
  if (age_s > timeout_s_)
    return {Severity::kError, std::isinf(age_s) ? "no state received" : "no state for " + std::to_string(age_s) + " s"};
  // A lost hardware link leaves the cell unattended: an error like a silent cell.
  if (s.faults & kFaultCommunication)
    return {Severity::kError,
            "hardware link lost, faults:" + faultNames(s.faults) + (s.unverified ? "; height unverified" : "")};
  if (s.faults != kFaultNone)
    return {Severity::kWarn, "faults:" + faultNames(s.faults) + (s.unverified ? "; height unverified" : "")};
  if (s.unverified) return {Severity::kWarn, "height unverified (its gas unproven or its vent count doubtful)"};
  return {Severity::kOk, "ok"};
}

std::string faultNames(std::uint32_t faults) {
  std::string names;
  if (faults & kFaultSensor) names += " sensor";
  if (faults & kFaultOverpressure) names += " overpressure";
  if (faults & kFaultCommandTimeout) names += " command-timeout";
  if (faults & kFaultLowPressure) names += " low-pressure";
  if (faults & kFaultModel) names += " model-reset";
  if (faults & kFaultCommunication) names += " communication";
  if (faults & kFaultInconsistent) names += " inconsistent";
  return names;
}

}  // namespace nursing_bed
