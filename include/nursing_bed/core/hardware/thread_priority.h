// Real-time scheduling for the bus threads (ROS-free). A fieldbus master's I/O thread runs at a
// real-time priority, as EtherCAT and CAN masters do: on a loaded machine a thread at the normal
// scheduler wakes up to milliseconds late, and each write's moment (the driven record's edges,
// doc/real_bed.md) is only known within its request's round trip.
#pragma once

#include <string>
#include <thread>

#include "nursing_bed/core/io/status.h"

namespace nursing_bed {

/// How a thread runs after scheduleRealtime.
struct ThreadScheduling {
  bool refused = false;  ///< a real-time priority was asked for and the system refused it
  std::string text;      ///< "SCHED_FIFO <priority>", "normal" or "normal (SCHED_FIFO <priority> refused: <reason>)"
};

/// Success when `priority` is one scheduleRealtime takes (0..99), else what is wrong with it.
Status checkRealtimePriority(int priority);

/// Puts `thread` under SCHED_FIFO at `priority` (1-99; 0: leaves it on the normal scheduler).
/// When the system refuses (no CAP_SYS_NICE, an RT limit of 0) the thread runs on normally and
/// the answer says so.
ThreadScheduling scheduleRealtime(std::thread& thread, int priority);

}  // namespace nursing_bed
