// Real-time scheduling of the bus threads: what scheduleRealtime says is how the thread runs.
#include <gtest/gtest.h>

#include <pthread.h>
#include <sched.h>

#include <atomic>
#include <chrono>
#include <thread>

#include "nursing_bed/core/hardware/thread_priority.h"

namespace nb = nursing_bed;

namespace {

/// A thread that waits until released, and the policy it runs under.
struct Waiting {
  std::atomic<bool> release{false};
  std::thread thread{[this] {
    while (!release) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }};
  int policy() {
    int policy = -1;
    sched_param param{};
    pthread_getschedparam(thread.native_handle(), &policy, &param);
    return policy;
  }
  ~Waiting() {
    release = true;
    thread.join();
  }
};

}  // namespace

TEST(ScheduleRealtime, PriorityZeroLeavesTheThreadOnTheNormalScheduler) {
  Waiting w;
  const nb::ThreadScheduling answer = nb::scheduleRealtime(w.thread, 0);
  EXPECT_EQ(answer.text, "normal");
  EXPECT_FALSE(answer.refused);
  EXPECT_EQ(w.policy(), SCHED_OTHER);
}

TEST(ScheduleRealtime, SaysWhetherTheSystemGrantedIt) {
  // Granted (root, or CAP_SYS_NICE): the thread runs under SCHED_FIFO. Refused (an ordinary
  // user without an RT limit): it runs on, normally, and the answer names the refusal.
  Waiting w;
  const nb::ThreadScheduling answer = nb::scheduleRealtime(w.thread, 20);
  if (answer.refused) {
    EXPECT_EQ(w.policy(), SCHED_OTHER) << answer.text;
    EXPECT_EQ(answer.text.rfind("normal (SCHED_FIFO 20 refused: ", 0), 0u) << answer.text;
  } else {
    EXPECT_EQ(answer.text, "SCHED_FIFO 20");
    EXPECT_EQ(w.policy(), SCHED_FIFO);
  }
}
