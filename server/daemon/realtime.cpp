#include "daemon/realtime.hpp"

#include <spdlog/spdlog.h>

#include <pthread.h>
#include <sched.h>
#include <sys/prctl.h>

#include <cstring>

namespace ladder::daemon {

bool run_realtime(const char* thread, int priority) {
  sched_param param{};
  param.sched_priority = priority;
  const int rc = pthread_setschedparam(pthread_self(), SCHED_FIFO, &param);
  if (rc == 0) {
    spdlog::info("{} thread at SCHED_FIFO priority {}", thread, priority);
    return true;
  }
  spdlog::warn("could not run the {} thread at SCHED_FIFO priority {}: {} (it needs CAP_SYS_NICE or root); running "
               "with normal scheduling",
               thread, priority, std::strerror(rc));
  return false;
}

void wake_on_time() { prctl(PR_SET_TIMERSLACK, 1UL); }

}  // namespace ladder::daemon
