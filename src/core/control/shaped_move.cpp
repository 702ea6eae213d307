#include "nursing_bed/core/control/shaped_move.h"

#include <algorithm>
#include <cmath>

namespace nursing_bed {

void ShapedMove::start(double predicted_error_m) {
  direction_ = predicted_error_m > 0.0 ? 1 : -1;
  phase_ = MovePhase::kLead;
  time_s_ = 0.0;
  initial_remaining_m_ = std::fabs(predicted_error_m);
}

void ShapedMove::stop() {
  direction_ = 0;
  phase_ = MovePhase::kNone;
}

std::optional<double> ShapedMove::step(double dt_s, double remaining_m, double half_period_s, double rest_rate_m_s) {
  time_s_ += dt_s;
  if (phase_ == MovePhase::kLead) {
    if (const auto opening = lead(dt_s, remaining_m, half_period_s)) return opening;
  }
  if (phase_ == MovePhase::kFullFlow) {
    if (const auto opening = fullFlow(dt_s, remaining_m, half_period_s, rest_rate_m_s)) return opening;
  }
  if (const auto opening = tail(dt_s, remaining_m, half_period_s, rest_rate_m_s)) return opening;
  stop();  // move done; fine corrections from here
  return std::nullopt;
}

std::optional<double> ShapedMove::lead(double dt_s, double remaining_m, double half_period_s) {
  if (time_s_ <= half_period_s + 0.5 * dt_s && remaining_m > 0.5 * initial_remaining_m_) return 0.5;
  lead_duration_s_ = time_s_ - dt_s;
  phase_ = MovePhase::kFullFlow;
  return std::nullopt;
}

std::optional<double> ShapedMove::fullFlow(double dt_s, double remaining_m, double half_period_s,
                                           double rest_rate_m_s) {
  const bool small = lead_duration_s_ < half_period_s;
  const double tail_duration = small ? lead_duration_s_ : half_period_s;
  const bool tail_due = small ? time_s_ >= half_period_s : remaining_m <= 0.5 * rest_rate_m_s * tail_duration;
  if (!tail_due) return small ? 0.0 : 1.0;
  tail_start_s_ = time_s_ - dt_s;
  phase_ = MovePhase::kTail;
  return std::nullopt;
}

std::optional<double> ShapedMove::tail(double dt_s, double remaining_m, double half_period_s, double rest_rate_m_s) {
  const double tail_duration = std::min(lead_duration_s_, half_period_s);
  const double time_left = tail_start_s_ + tail_duration - (time_s_ - dt_s);
  if (remaining_m > 0.0 && time_left > 0.5 * dt_s && rest_rate_m_s > 0.0)
    return std::clamp(remaining_m / (rest_rate_m_s * std::max(time_left, dt_s)), 0.0, 1.0);
  return std::nullopt;
}

}  // namespace nursing_bed
