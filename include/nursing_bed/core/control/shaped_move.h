// A height move as a zero-vibration shaped full-flow pulse (ROS-free): the phases and timers of
// one move, with the valve opening each period; HeightController decides when a move starts and
// which valve it drives.
#pragma once

#include <cstdint>
#include <optional>

namespace nursing_bed {

/// Where a shaped move is: none, the half-open lead, full flow (or a small move's pause), the
/// half-open tail, or the tail under feedback (PlateLanding, where the loop is fast enough).
enum class MovePhase : std::uint8_t { kNone = 0, kLead = 1, kFullFlow = 2, kTail = 3, kLanding = 4 };

/**
 * The ideal flow-limited command is a full-flow pulse that ends when the plate's rest height
 * reaches the target. The loaded plate rings on its gas spring (half period T/2), so the pulse
 * passes a zero-vibration input shaper: half of it now, half T/2 later. As phases: half open
 * for T/2 (or until half the move is done), fully open until the gas in the cell plus half a
 * flow for T/2 carries the plate to the target, half open for the last T/2, re-aimed every
 * period. A move too small for that is two half-open pulses T/2 apart (the full-flow phase is a
 * pause).
 */
class ShapedMove {
 public:
  /// Starts a move in `direction` (+1 fill, -1 vent) with `remaining` still to go (in the unit
  /// step() is given it and the rate in).
  void start(int direction, double remaining);
  /// Ends the move (done, or no target).
  void stop();
  bool active() const { return direction_ != 0; }
  /// +1 fill, -1 vent, 0 no move.
  int direction() const { return direction_; }
  MovePhase phase() const { return phase_; }

  /// One period of `dt_s`: the opening of the move's valve over it, or nothing once the move is
  /// done (it has then stopped). `remaining`: what is still to go in the move's direction (a
  /// rest height, or the gas's invariant: any measure of the gas); `half_period_s`: the loaded
  /// plate's; `rate`: the rate of that measure with the valve fully open (same unit per second).
  std::optional<double> step(double dt_s, double remaining, double half_period_s, double rate);

 private:
  /// Half-open lead: T/2, or until half the move is done; nothing when it has ended.
  std::optional<double> lead(double dt_s, double remaining, double half_period_s);
  /// Full flow until the tail can finish the move; a small move pauses instead.
  std::optional<double> fullFlow(double dt_s, double remaining, double half_period_s, double rate);
  /// Tail: the remaining gas spread over what is left of it (half flow when the prediction is
  /// exact; re-aimed every period so that the rest height lands on the target).
  std::optional<double> tail(double dt_s, double remaining, double half_period_s, double rate);

  int direction_ = 0;
  MovePhase phase_ = MovePhase::kNone;
  double time_s_ = 0.0;             ///< since the move started [s]
  double lead_duration_s_ = 0.0;    ///< how long the lead lasted [s]
  bool small_ = false;              ///< the lead ended halfway through the move, before T/2
  double tail_start_s_ = 0.0;       ///< when the tail began [s]
  double initial_remaining_ = 0.0;  ///< what was to go at the start (step()'s unit)
};

}  // namespace nursing_bed
