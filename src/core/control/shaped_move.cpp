#include "nursing_bed/core/control/shaped_move.h"

#include <algorithm>
#include <cmath>

namespace nursing_bed {

void ShapedMove::start(int direction, double remaining) {
  direction_ = direction > 0 ? 1 : -1;
  phase_ = MovePhase::kLead;
  time_s_ = 0.0;
  initial_remaining_ = std::max(remaining, 0.0);
}

void ShapedMove::stop() {
  direction_ = 0;
  phase_ = MovePhase::kNone;
}

std::optional<double> ShapedMove::step(double dt_s, double remaining, double half_period_s, double rate) {
  time_s_ += dt_s;
  if (phase_ == MovePhase::kLead) {
    if (const auto opening = lead(dt_s, remaining, half_period_s)) return opening;
  }
  if (phase_ == MovePhase::kFullFlow) {
    if (const auto opening = fullFlow(dt_s, remaining, half_period_s, rate)) return opening;
  }
  if (const auto opening = tail(dt_s, remaining, half_period_s, rate)) return opening;
  stop();  // move done; fine corrections from here
  return std::nullopt;
}

std::optional<double> ShapedMove::lead(double dt_s, double remaining, double half_period_s) {
  const bool in_time = time_s_ <= half_period_s + 0.5 * dt_s;
  if (in_time && remaining > 0.5 * initial_remaining_) return 0.5;
  lead_duration_s_ = time_s_ - dt_s;
  small_ = in_time;  // half the move done before T/2
  phase_ = MovePhase::kFullFlow;
  return std::nullopt;
}

std::optional<double> ShapedMove::fullFlow(double dt_s, double remaining, double half_period_s, double rate) {
  const double tail_duration = small_ ? lead_duration_s_ : half_period_s;
  const bool tail_due = small_ ? time_s_ >= half_period_s : remaining <= 0.5 * rate * tail_duration;
  if (!tail_due) return small_ ? 0.0 : 1.0;
  tail_start_s_ = time_s_ - dt_s;
  phase_ = MovePhase::kTail;
  return std::nullopt;
}

std::optional<double> ShapedMove::tail(double dt_s, double remaining, double half_period_s, double rate) {
  const double tail_duration = std::min(lead_duration_s_, half_period_s);
  const double time_left = tail_start_s_ + tail_duration - (time_s_ - dt_s);
  if (remaining > 0.0 && time_left > 0.5 * dt_s && rate > 0.0)
    return std::clamp(remaining / (rate * std::max(time_left, dt_s)), 0.0, 1.0);
  return std::nullopt;
}

}  // namespace nursing_bed
