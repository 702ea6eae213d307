#include "nursing_bed/core/hardware/thread_priority.h"

#include <pthread.h>
#include <sched.h>

#include <cstring>

namespace nursing_bed {

Status checkRealtimePriority(int priority) {
  if (priority < 0 || priority > 99) return Status::error("not in 0..99 (0: the normal scheduler)");
  return Status::success();
}

ThreadScheduling scheduleRealtime(std::thread& thread, int priority) {
  if (priority <= 0) return {false, "normal"};
  sched_param param{};
  param.sched_priority = priority;
  const int error = pthread_setschedparam(thread.native_handle(), SCHED_FIFO, &param);
  const std::string fifo = "SCHED_FIFO " + std::to_string(priority);
  if (error == 0) return {false, fifo};
  return {true, "normal (" + fifo + " refused: " + std::strerror(error) + ")"};
}

}  // namespace nursing_bed
