#include "nursing_bed/core/hardware/thread_priority.h"

#include <pthread.h>
#include <sched.h>

#include <cstring>

namespace nursing_bed {

std::string scheduleRealtime(std::thread& thread, int priority) {
  if (priority <= 0) return "normal";
  sched_param param{};
  param.sched_priority = priority;
  const int error = pthread_setschedparam(thread.native_handle(), SCHED_FIFO, &param);
  const std::string fifo = "SCHED_FIFO " + std::to_string(priority);
  return error == 0 ? fifo : "normal (" + fifo + " refused: " + std::strerror(error) + ")";
}

bool realtimeRefused(const std::string& scheduling) { return scheduling.find("refused") != std::string::npos; }

}  // namespace nursing_bed
