// Real-time scheduling for the bus threads (ROS-free). A fieldbus master's I/O thread runs at a
// real-time priority, as EtherCAT and CAN masters do: on a loaded machine a thread at the normal
// scheduler wakes up to milliseconds late, and each write's moment (the driven record's edges,
// doc/real_bed.md) is only known within its request's round trip.
#pragma once

#include <string>
#include <thread>

namespace nursing_bed {

/// Puts `thread` under SCHED_FIFO at `priority` (1-99; 0: leaves it on the normal scheduler).
/// Returns how it is scheduled: "SCHED_FIFO <priority>", "normal", or, when the system refuses
/// (no CAP_SYS_NICE, an RT limit of 0), "normal (SCHED_FIFO <priority> refused: <reason>)".
std::string scheduleRealtime(std::thread& thread, int priority);

/// True when scheduleRealtime's answer is a refusal.
bool realtimeRefused(const std::string& scheduling);

}  // namespace nursing_bed
