// The shaped full-flow move's phases (ShapedMove) and the commands in flight (CommandsInFlight).
#include <gtest/gtest.h>

#include <stdexcept>
#include <vector>

#include "nursing_bed/core/control/commands_in_flight.h"
#include "nursing_bed/core/control/shaped_move.h"

namespace nb = nursing_bed;

TEST(ShapedMove, ALargeMoveLeadsHalfOpenRunsFullFlowAndEndsWithATail) {
  nb::ShapedMove move;
  EXPECT_FALSE(move.active());
  move.start(-1, 0.05);
  EXPECT_EQ(move.direction(), -1);
  EXPECT_EQ(move.phase(), nb::MovePhase::kLead);
  // The rest height moves 0.1 m/s at full flow; the lead lasts whole periods past T/2.
  const double dt = 0.005, half_period = 0.0499, rate = 0.1;
  double remaining = 0.05;
  std::vector<nb::MovePhase> phases;
  for (int i = 0; i < 1000 && move.active(); ++i) {
    const auto opening = move.step(dt, remaining, half_period, rate);
    if (!opening) break;
    if (phases.empty() || phases.back() != move.phase()) phases.push_back(move.phase());
    if (move.phase() == nb::MovePhase::kLead) {
      EXPECT_EQ(*opening, 0.5);
    } else if (move.phase() == nb::MovePhase::kFullFlow) {
      EXPECT_EQ(*opening, 1.0);
    }
    EXPECT_GE(*opening, 0.0);
    EXPECT_LE(*opening, 1.0);
    remaining -= *opening * rate * dt;
  }
  EXPECT_EQ(phases, (std::vector<nb::MovePhase>{nb::MovePhase::kLead, nb::MovePhase::kFullFlow, nb::MovePhase::kTail}));
  EXPECT_FALSE(move.active());
  EXPECT_EQ(move.phase(), nb::MovePhase::kNone);
  EXPECT_NEAR(remaining, 0.0, 0.002) << "the tail lands the rest height on the target";
}

// A lead cut by its time is not a small move, even where T/2 is a whole number of periods
// (the lead's measured duration then rounds either side of T/2).
TEST(ShapedMove, ALeadEndingAtExactlyHalfAPeriodIsFollowedByFullFlow) {
  nb::ShapedMove move;
  move.start(1, 0.05);
  const double dt = 0.005, half_period = 0.05, rate = 0.1;
  double remaining = 0.05;
  bool full = false;
  for (int i = 0; i < 1000 && move.active(); ++i) {
    const auto opening = move.step(dt, remaining, half_period, rate);
    if (!opening) break;
    full = full || (move.phase() == nb::MovePhase::kFullFlow && *opening == 1.0);
    remaining -= *opening * rate * dt;
  }
  EXPECT_TRUE(full);
  EXPECT_NEAR(remaining, 0.0, 0.002);
}

TEST(ShapedMove, ASmallMoveIsTwoHalfOpenPulsesAPauseApart) {
  nb::ShapedMove move;
  move.start(1, 0.004);
  const double dt = 0.005, half_period = 0.05, rate = 0.1;
  double remaining = 0.004;
  std::vector<double> openings;
  while (move.active()) {
    const auto opening = move.step(dt, remaining, half_period, rate);
    if (!opening) break;
    openings.push_back(*opening);
    remaining -= *opening * rate * dt;
  }
  ASSERT_GE(openings.size(), 4u);
  EXPECT_EQ(openings.front(), 0.5);
  int paused = 0;
  for (const double o : openings) paused += o == 0.0;
  EXPECT_GT(paused, 0) << "the full-flow phase of a small move is a pause";
  EXPECT_LT(remaining, 0.001);
}

TEST(CommandsInFlight, KeepsOnlyTheLastDeadTimesCommands) {
  nb::CommandsInFlight in_flight;
  in_flight.note({1.0, 0.0, false}, 0.01);
  EXPECT_TRUE(in_flight.empty()) << "without a dead time nothing is in flight";
  in_flight.setDeadTime(0.015);
  in_flight.note({1.0, 0.0, false}, 0.01);
  in_flight.note({0.0, 0.5, false}, 0.01);
  in_flight.note({0.5, 0.0, false}, 0.01);
  double inlet_s = 0.0, vent_s = 0.0;
  in_flight.openSeconds(&inlet_s, &vent_s);
  // The last 15 ms: half of the vent's 10 ms command, all of the last inlet one.
  EXPECT_NEAR(inlet_s, 0.005, 1e-12);
  EXPECT_NEAR(vent_s, 0.0025, 1e-12);
  EXPECT_THROW(in_flight.setDeadTime(-0.1), std::invalid_argument);
  EXPECT_THROW(in_flight.setDeadTime(2.0), std::invalid_argument);
  EXPECT_EQ(in_flight.deadTime(), 0.015) << "a refused dead time changes nothing";
  in_flight.openSeconds(&inlet_s, &vent_s);
  EXPECT_NEAR(inlet_s, 0.005, 1e-12);
}
