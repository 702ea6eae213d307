#include "nursing_bed/core/bed/cell_commander.h"

#include <algorithm>
#include <cmath>

namespace nursing_bed {

CellCommander::CellCommander(std::vector<BedCell> cells, RateLimits limits, double resend_s)
    : cells_(std::move(cells)),
      limiter_(std::move(limits), cells_.size()),
      limited_m_(cells_.size(), CellSnapshot::kNone),
      sent_height_m_(cells_.size(), CellSnapshot::kNone),
      sent_at_s_(cells_.size(), CellSnapshot::kNone),
      resend_s_(resend_s) {}

void CellCommander::resendAll() { std::fill(sent_at_s_.begin(), sent_at_s_.end(), CellSnapshot::kNone); }

std::vector<CellCommand> CellCommander::command(const PlanTargets& targets, const std::vector<double>& measured_m,
                                                double dt_s, double now_s) {
  if (targets.vent_all) {
    std::fill(limited_m_.begin(), limited_m_.end(), CellSnapshot::kNone);
    return send(targets, targets.heights_m, now_s);
  }
  PlanTargets limited = targets;
  limited.heights_m = limit(targets.heights_m, measured_m, dt_s);
  return send(limited, targets.heights_m, now_s);
}

std::vector<double> CellCommander::limit(const std::vector<double>& wanted, const std::vector<double>& measured_m,
                                         double dt_s) {
  if (wanted.size() != limited_m_.size()) return wanted;
  for (const BedCell& c : cells_) {
    const double h = c.id < measured_m.size() ? measured_m[c.id] : CellSnapshot::kNone;
    // Nothing sent yet (start, after CPR): the ramp starts where the cell is.
    if (!std::isfinite(limited_m_[c.id]) && std::isfinite(h))
      limited_m_[c.id] = std::clamp(h, c.min_height_m, c.max_height_m);
  }
  limited_m_ = limiter_.step(limited_m_, wanted, dt_s);
  return limited_m_;
}

std::vector<CellCommand> CellCommander::send(const PlanTargets& targets, const std::vector<double>& wanted_m,
                                             double now_s) {
  std::vector<CellCommand> out;
  for (const BedCell& c : cells_) {
    const bool due = !std::isfinite(sent_at_s_[c.id]) || now_s - sent_at_s_[c.id] >= resend_s_;
    if (targets.vent_all) {
      if (due || std::isfinite(sent_height_m_[c.id])) {
        out.push_back({c.id, true, CellSnapshot::kNone});
        sent_height_m_[c.id] = CellSnapshot::kNone;
        sent_at_s_[c.id] = now_s;
      }
      continue;
    }
    if (c.id >= targets.heights_m.size() || !std::isfinite(targets.heights_m[c.id])) continue;
    const double h = targets.heights_m[c.id];
    // A setpoint that moved by less than this is not news: it waits for the resend, unless the
    // ramp has just arrived at the plan's target (the cell then holds exactly what was asked).
    constexpr double kChangedM = 2e-4;
    const bool arrived = c.id < wanted_m.size() && h == wanted_m[c.id] && h != sent_height_m_[c.id];
    if (due || arrived || !(std::fabs(h - sent_height_m_[c.id]) < kChangedM)) {
      out.push_back({c.id, false, h});
      sent_height_m_[c.id] = h;
      sent_at_s_[c.id] = now_s;
    }
  }
  return out;
}

}  // namespace nursing_bed
