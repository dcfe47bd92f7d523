// ladderd's physics thread: it owns the session, keeps real time, applies the commands the I/O thread queues and
// hands over states, events, acks and Stats (outbox.hpp). It never touches DDS or a file, so that a slow subscriber
// or a burst of commands cannot delay a step.
#pragma once

#include "daemon/outbox.hpp"
#include "daemon/session.hpp"

#include <atomic>
#include <cmath>
#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace ladder::daemon {

class Physics {
 public:
  Physics(Shared& shared, std::unique_ptr<Session> session)
      : sh_(shared),
        owned_(std::move(session)),
        session_(*owned_),
        recording_(!shared.config.record.empty()),
        tick_log_(!shared.config.tick_log.empty()) {
    session_.configure(sh_.config.scenes_dir, sh_.config.limits, sh_.config.rates);
    scene_generation_ = session_.generation();
    accepted_ = session_.taken_before().accepted;  // a resumed session numbers on from its log
    refused_ = session_.taken_before().refused;
  }

  // `realtime`: this thread runs under SCHED_FIFO (the step's second thread then sleeps between ticks: tick_loop).
  void run(const std::atomic<bool>& stop, bool realtime = false);

 private:
  void tick_loop(const std::atomic<bool>& stop);
  void take_commands();
  void idle_until(Clock::time_point deadline, const std::atomic<bool>& stop, bool wake_helper = true);
  void advance(double period, Clock::time_point tick_start);
  void collect_events();
  void publish_state();
  void publish_stats(Clock::time_point now);
  void run_step();
  void push_scene();
  void checkpoint();
  void record_failure(bool step_failed);
  CheckpointOut place() const;
  void log_tick(Clock::time_point start, Clock::duration late);
  void hand_over_ticks();
  void keep_watchdog(Clock::time_point now);
  template <class F>
  void with_outbox(F&& f) {
    std::lock_guard lock(sh_.outbox_mutex);
    f(sh_.outbox);
  }

  Shared& sh_;
  std::unique_ptr<Session> owned_;
  Session& session_;
  bool interrupted_ = false;  // a step was cut short by the stop (run_step): the loop ends
  double debt_ = 0;  // sim time owed to the real-time clock [s]
  std::vector<double> step_us_, late_us_;
  std::uint64_t missed_ = 0, accepted_ = 0, refused_ = 0;
  std::size_t taken_ = 0;  // commands taken since the last tick's step (at most commands.per_tick)
  const char* taking_ = "";  // where take_commands() is called from, for the debug log
  LogBudget refusal_log_{20, Clock::now()};  // the refusals' info lines: 20 a second (a client may send 1000)
  double sim_at_last_stats_ = 0;
  std::uint32_t stats_generation_ = 0;  // the scene's generation at the last Stats
  Clock::time_point last_stats_{}, last_publish_{};
  std::uint32_t scene_generation_ = 0;
  Rates scene_rates_{};
  std::string scene_options_;  // the live settings the last SceneInfo carried
  bool recording_;
  bool tick_log_;
  bool realtime_ = false;
  TickRecord tick_;                // the tick under way, for the tick log
  std::vector<TickRecord> ticks_;  // ticks not yet handed to the I/O thread
  double next_checkpoint_ = 0;  // [s of sim time]
  bool dirty_ = true;  // the state changed (or a command came) since the last publish; paused states publish only then
  std::uint64_t stats_zeroed_ = 0, events_zeroed_ = 0;  // non-finite fields sent as 0 (the final guard)
  // The sim time for an event, 0 if it is not finite.
  double finite_time() const { return std::isfinite(session_.sim().time()) ? session_.sim().time() : 0; }
  Clock::time_point next_watchdog_{};  // when systemd's watchdog is next told that all is well
};

}  // namespace ladder::daemon
