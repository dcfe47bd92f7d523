// The real-time setup of ladderd's threads: the SCHED_FIFO scheduler and the timer slack. Linux only.
#pragma once

namespace ladder::daemon {

// Puts the calling thread under SCHED_FIFO at `priority`, so that no thread of the normal scheduler (other programs:
// viewers on the same cores) delays it; says which. Returns whether it could.
bool run_realtime(const char* thread, int priority);

// The calling thread's timed waits end within microseconds of their deadline, not the default 50 us late.
void wake_on_time();

}  // namespace ladder::daemon
