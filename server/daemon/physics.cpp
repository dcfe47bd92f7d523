#include "daemon/physics.hpp"

#include "daemon/frames.hpp"
#include "daemon/realtime.hpp"
#include "daemon/wire.hpp"
#include "transport/dds.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <mutex>
#include <thread>
#include <tuple>

namespace ladder::daemon {

using transport::copy_text;
using transport::printable;
using transport::text_of;

// Where the run stands, and the hash of its complete state.
CheckpointOut Physics::place() const {
  const scene::Simulation& sim = session_.sim();
  return {session_.generation(), sim.steps(), accepted_ + refused_, session_.state_hash(), sim.time()};
}

void Physics::checkpoint() {
  const CheckpointOut c = place();
  with_outbox([&](Outbox& o) { o.checkpoints.push_back(c); });
  next_checkpoint_ = c.t + sh_.config.checkpoint_every;
}

// A failed step (or a state found non-finite) paused the session: the log says where and which, so that a re-run
// fails there too and goes on as the session did (a reset then restores the scene's own settings;
// docs/recording.md).
void Physics::record_failure(bool step_failed) {
  if (!recording_) return;
  const CheckpointOut c = place();
  with_outbox([&](Outbox& o) { (step_failed ? o.failures : o.non_finite).push_back(c); });
}

void Physics::push_scene() {
  if (recording_ && session_.generation() != scene_generation_) next_checkpoint_ = 0;  // one at each start
  scene_generation_ = session_.generation();
  scene_rates_ = session_.rates();
  SceneOut out = scene_out(session_);
  std::string bad;
  std::uint64_t zeroed = 0;
  for (auto [v, name] : {std::pair{&out.length, "length"}, {&out.thickness, "thickness"}, {&out.inset, "hinge_inset"},
                         {&out.dt, "dt"}, {&out.rates.physics, "physics_rate"}, {&out.rates.publish, "publish_rate"},
                         {&out.rates.real_time_factor, "real_time_factor"}})
    finite_or_zero(*v, name, bad, zeroed);
  for (double& m : out.masses) finite_or_zero(m, "a mass", bad, zeroed);
  if (zeroed) spdlog::warn("SceneInfo: non-finite {} sent as 0", bad);  // the scene checks should leave none
  scene_options_ = out.options;
  with_outbox([&](Outbox& o) { o.scenes.push_back(std::move(out)); });
}

void Physics::take_commands() {
  std::vector<Incoming> batch;
  {
    std::lock_guard lock(sh_.inbox_mutex);
    sh_.inbox.take(sh_.config.per_tick - taken_, batch);
  }
  if (batch.empty()) return;
  taken_ += batch.size();
  dirty_ = true;  // even a refused command gets a fresh state, so a client can see that nothing changed
  // One deterministic order for the commands taken together (those that arrived during a step, or queued while
  // spinning): client, then id. A command that arrives while the thread waits is taken on its own, as it comes.
  std::stable_sort(batch.begin(), batch.end(), [](const Incoming& x, const Incoming& y) {
    const ladder_msg_Command &a = x.command, &b = y.command;
    const int c = std::strncmp(a.client_id, b.client_id, sizeof a.client_id);
    return c < 0 || (c == 0 && a.command_id < b.command_id);
  });
  std::vector<AckOut> acks(batch.size());
  std::vector<CommandOut> commands;
  for (std::size_t i = 0; i < batch.size(); ++i) {
    const ladder_msg_Command& c = batch[i].command;
    const double t = session_.sim().time();
    const std::uint64_t step = session_.sim().steps();
    const CommandFields fields = fields_of(c);
    const char* kind = kind_name(fields.kind);
    const Outcome r = session_.apply(fields);
    const bool restarted = session_.generation() != scene_generation_;
    acks[i] = {ack_for(c, r), batch[i].sender};
    ladder_msg_CommandAck& a = acks[i].ack;
    // A command that restarted the scene took effect at the new scene's start.
    a.sim_time = restarted ? session_.sim().time() : t;
    a.step = restarted ? session_.sim().steps() : step;
    (r.accepted ? accepted_ : refused_)++;
    a.command_seq = accepted_ + refused_;
    if (recording_) commands.push_back({c, scene_generation_, step, a.command_seq, r.accepted, r.reason});
    if (r.accepted && !r.reason.empty())  // accepted with a note (a reset that dropped the live settings)
      spdlog::info("{} (command {}) from {}: accepted: {}", kind, c.command_id, printable(text_of(c.client_id)),
                   printable(r.reason));
    else if (r.accepted)
      spdlog::debug("{} (command {}) from {}: accepted at t = {:.6f} s{}", kind, c.command_id,
                    printable(text_of(c.client_id)), t, taking_);
    else if (std::uint64_t held_back = 0; refusal_log_.allow(Clock::now(), held_back))
      spdlog::info("{} (command {}) from {}: refused: {}{}", kind, c.command_id, printable(text_of(c.client_id)),
                   printable(r.reason),
                   held_back == 0 ? std::string()
                                  : " (" + std::to_string(held_back) +
                                        " refusals before it not logged: more than 20 a second; the Stats count all)");
    // SceneInfo carries the live settings and the rates: published (and logged) again when they change. A setting
    // that leaves them as they were (a value they already had) sends none: at N = 10 000 a SceneInfo is 80 kB of
    // masses to every reader.
    if (restarted ||
        (r.accepted && fields.kind == kind::kSet &&
         scene::live_settings(session_.sim().scene()) != scene_options_) ||
        std::tie(session_.rates().publish, session_.rates().real_time_factor) !=
            std::tie(scene_rates_.publish, scene_rates_.real_time_factor)) {
      if (restarted) {
        debt_ = 0;
        spdlog::info("scene '{}' started ({} blocks)", printable(session_.sim().scene().name),
                     session_.sim().ladder().blocks());
      }
      push_scene();
    }
  }
  with_outbox([&](Outbox& o) {
    o.acks.insert(o.acks.end(), acks.begin(), acks.end());
    o.commands.insert(o.commands.end(), commands.begin(), commands.end());
  });
  // The acks go out now, not after this tick's step (0.6 to 0.9 ms at N = 10 000): each command took effect at the
  // tick's start, before the step.
  sh_.waiter->wake();
}

// How long before a tick the step's second thread, asleep since the last one (World::rest_threads), is woken: a
// sleeping thread takes tens of microseconds to run on this kind of virtual machine, and more after a longer sleep.
constexpr auto kHelperLead = std::chrono::microseconds(200);

// Waits for the next tick's deadline. A command that arrives meanwhile is applied at once: the simulation already
// stands where the next tick starts, so it takes effect at the same sim time as it would then, and its ack goes
// out without waiting for the deadline. The last server.spin_us before the deadline are busy-waited. The step's second
// thread is woken kHelperLead before the deadline when a step is coming (and `wake_helper`).
void Physics::idle_until(Clock::time_point deadline, const std::atomic<bool>& stop, bool wake_helper) {
  const auto halted = [&] { return stop.load(std::memory_order_relaxed) || sh_.abort.load(std::memory_order_relaxed); };
  const auto ready = [&] { return (!sh_.inbox.empty() && taken_ < sh_.config.per_tick) || halted(); };
  const auto wake = deadline - std::chrono::microseconds(sh_.config.spin_us);
  const auto helper_wake = deadline - kHelperLead;
  bool helper_woken = !wake_helper || (session_.paused() && session_.pending_steps() == 0);  // (no step is coming)
  std::unique_lock lock(sh_.inbox_mutex);
  while (true) {
    const auto now = Clock::now();
    if (!helper_woken && now >= helper_wake) {
      session_.sim().ladder().world().wake_threads();
      helper_woken = true;
    }
    const bool sleeping = now < wake;  // else spinning
    if (sleeping) {
      if (!sh_.inbox_cv.wait_until(lock, helper_woken ? wake : std::min(wake, helper_wake), ready)) continue;
    } else if (now >= deadline) {
      return;
    } else if (!ready()) {
      lock.unlock();
      std::this_thread::yield();  // lets a thread of the same priority run; costs no sleep
      lock.lock();
      continue;
    }
    if (halted()) return;
    lock.unlock();
    taking_ = sleeping ? ", between ticks" : ", while spinning before the tick";
    take_commands();
    taking_ = "";
    lock.lock();
  }
}

void Physics::run_step() {
  if (interrupted_) return;  // (the stop cut the last step short: no more, and the loop ends at once)
  // Checked before every step, not only at a tick's start: one tick may take thousands of steps (a real-time factor
  // of 1000, or 0), and a log's reader allows a step at most two intervals past a checkpoint.
  if (recording_ && session_.sim().time() >= next_checkpoint_) checkpoint();
  dirty_ = true;
  const auto t0 = Clock::now();
  try {
    session_.step();
  } catch (const scene::Interrupted& e) {
    interrupted_ = true;
    if (e.substeps > 0)
      spdlog::info("stopping: the step at t = {:.6f} s interrupted after {} of its {} sub-steps", finite_time(),
                   e.substeps_taken, e.substeps);
    else
      spdlog::info("stopping: the step at t = {:.6f} s interrupted after {} adaptive sub-steps", finite_time(),
                   e.substeps_taken);
    return;
  } catch (const std::runtime_error& e) {
    spdlog::error("step failed, simulation paused: {}", e.what());
    record_failure(true);
    with_outbox([&](Outbox& o) { o.events.push_back({finite_time(), "solver_failure", e.what(), 0, 0}); });
    debt_ = 0;
  }
  const Clock::duration took = Clock::now() - t0;
  step_us_.push_back(1e6 * seconds(took));
  tick_.step_ns += std::chrono::nanoseconds(took).count();
  ++tick_.steps;
}

// The tick log: the I/O thread writes it, from batches handed over a few times a second (and at the end), so the
// physics thread neither writes files nor takes the outbox's lock every tick.
void Physics::log_tick(Clock::time_point start, Clock::duration late) {
  tick_.start_ns = std::chrono::nanoseconds(start.time_since_epoch()).count();
  tick_.late_ns = std::chrono::nanoseconds(late).count();
  ticks_.push_back(tick_);
  tick_ = TickRecord{tick_.tick + 1};
  if (ticks_.size() >= 250) hand_over_ticks();
}

void Physics::hand_over_ticks() {
  if (ticks_.empty()) return;
  with_outbox([&](Outbox& o) { o.ticks.insert(o.ticks.end(), ticks_.begin(), ticks_.end()); });
  ticks_.clear();
}

// Runs the steps this tick owes: real time times the real-time factor, or pending single steps while paused.
// With a real-time factor of 0 it steps for one tick period of wall time. A backlog beyond two ticks' worth (or one
// step, when a step is longer) is dropped rather than caught up, so an overloaded server runs slow instead of freezing.
void Physics::advance(double period, Clock::time_point tick_start) {
  const double dt = session_.sim().dt();
  const auto budget = tick_start + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(period));
  if (session_.paused()) {
    debt_ = 0;
    while (session_.pending_steps() > 0 && session_.paused()) {
      session_.take_pending_step();
      run_step();
      if (Clock::now() >= budget) break;
    }
    return;
  }
  const double rtf = session_.rates().real_time_factor;
  if (rtf == 0) {
    do run_step();
    while (!session_.paused() && Clock::now() < budget);
    return;
  }
  debt_ += rtf * period;
  while (debt_ >= 0.5 * dt && !session_.paused()) {
    run_step();
    debt_ -= dt;
    if (Clock::now() >= budget + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(period)))
      break;
  }
  // At most two ticks' worth, or one step: a sim.dt longer than two ticks of sim time (4 ms at 1 kHz and a real-time
  // factor of 1) must still come due, or the simulation would never step again.
  debt_ = std::min(debt_, std::max(2 * rtf * period, dt));
}

void Physics::collect_events() {
  std::vector<EventOut> out;
  for (const model::Event& e : session_.sim().take_events())
    out.push_back({e.t, model::to_string(e.kind), e.detail, e.hinge, e.energy_removed});
  for (const scene::Refusal& r : session_.sim().take_refusals())
    out.push_back({r.t, "command_refused", r.where + ": " + r.reason, 0, 0});
  if (out.empty()) return;
  for (EventOut& e : out) {
    std::string bad;
    finite_or_zero(e.t, "t", bad, events_zeroed_);
    finite_or_zero(e.energy_removed, "energy_removed", bad, events_zeroed_);
    if (!bad.empty()) e.detail += (e.detail.empty() ? "" : "; ") + ("non-finite " + bad + " sent as 0");
  }
  for (const EventOut& e : out)
    spdlog::info("t = {:.6f} s: {} at hinge {}{}{}", e.t, e.kind, e.hinge, e.detail.empty() ? "" : ": ",
                 printable(e.detail));
  with_outbox([&](Outbox& o) { o.events.insert(o.events.end(), out.begin(), out.end()); });
}

void Physics::publish_state() {
  dirty_ = false;
  StateFrame& f = sh_.state.back();
  fill_frame(session_, accepted_ + refused_, f);
  const std::string bad = non_finite_in(f);
  if (!bad.empty()) {
    // Treated as a failed step: the frame is not handed over (clients keep the last good state) and the session
    // pauses, so that a reset restores the scene's own settings. Reported once, not at every command while paused.
    if (session_.failed()) return;
    session_.fail();
    record_failure(false);
    const std::string why = "the state holds a non-finite number (" + bad + "): not published; paused";
    spdlog::error("step failed, simulation paused: {}", why);
    with_outbox([&](Outbox& o) { o.events.push_back({finite_time(), "solver_failure", why, 0, 0}); });
    debt_ = 0;
    return;
  }
  if (sh_.state.publish()) sh_.states_dropped.fetch_add(1, std::memory_order_relaxed);
}

void Physics::publish_stats(Clock::time_point now) {
  ladder_msg_Stats s{};
  const scene::Simulation& sim = session_.sim();
  copy_text(s.sim_id, sh_.config.sim_id);
  s.sim_time = sim.time();
  s.steps = sim.steps();
  s.window = seconds(now - last_stats_);
  const Percentiles step = percentiles(step_us_), late = percentiles(late_us_);
  s.step_p50_us = step.p50;
  s.step_p99_us = step.p99;
  s.step_max_us = step.max;
  s.late_p50_us = late.p50;
  s.late_p99_us = late.p99;
  s.late_max_us = late.max;
  // The sim time run over the window: a reset or a load since the last Stats began the scene again at t = 0 (the
  // factor read 0 for the second after each).
  const double from = session_.generation() == stats_generation_ ? sim_at_last_stats_ : 0.0;
  s.real_time_factor = s.window > 0 ? std::max(0.0, sim.time() - from) / s.window : 0;
  s.missed_deadlines = missed_;
  s.solver_iterations = static_cast<std::uint32_t>(sim.ladder().world().last_step().iterations);
  s.solver_residual = sim.ladder().world().last_step().residual;
  s.energy = sim.ladder().energy();
  s.max_hinge_error = sim.max_step_residual();
  s.commands_received = sh_.received.load();
  s.commands_accepted = accepted_;
  s.commands_refused = refused_;
  s.commands_rate_limited = sh_.rate_limited.load();
  s.commands_duplicate = sh_.duplicates.load();
  s.commands_unanswered = sh_.unanswered.load();
  s.commands_undecodable = transport::undecodable_samples();
  s.write_failures = sh_.write_failures.load();
  s.states_published = sh_.states_published.load();
  s.states_dropped = sh_.states_dropped.load();
  s.events_published = sh_.events_published.load();
  std::string bad;
  const std::uint64_t before = stats_zeroed_;
  for (auto [v, name] : {std::pair{&s.sim_time, "sim_time"}, {&s.window, "window"}, {&s.step_p50_us, "step_p50_us"},
                         {&s.step_p99_us, "step_p99_us"}, {&s.step_max_us, "step_max_us"},
                         {&s.late_p50_us, "late_p50_us"}, {&s.late_p99_us, "late_p99_us"},
                         {&s.late_max_us, "late_max_us"}, {&s.real_time_factor, "real_time_factor"},
                         {&s.solver_residual, "solver_residual"}, {&s.energy, "energy"},
                         {&s.max_hinge_error, "max_hinge_error"}})
    finite_or_zero(*v, name, bad, stats_zeroed_);
  if (stats_zeroed_ != before)
    spdlog::warn("Stats: non-finite {} sent as 0 ({} such fields so far)", bad, stats_zeroed_);
  with_outbox([&](Outbox& o) { o.stats.push_back(s); });
  last_stats_ = now;
  sim_at_last_stats_ = sim.time();
  stats_generation_ = session_.generation();
}

void Physics::run(const std::atomic<bool>& stop, bool realtime) {
  realtime_ = realtime;
  wake_on_time();
  last_stats_ = last_publish_ = Clock::now();
  sim_at_last_stats_ = session_.sim().time();  // (a resumed session starts where its log ended)
  stats_generation_ = session_.generation();
  tick_.tick = 1;
  ticks_.reserve(250);
  push_scene();
  publish_state();
  session_.set_interrupt([&stop, this] {
    return stop.load(std::memory_order_relaxed) || sh_.abort.load(std::memory_order_relaxed);
  });
  try {
    tick_loop(stop);
  } catch (...) {
    session_.set_interrupt({});
    hand_over_ticks();  // the ticks before a failure are the ones worth reading
    throw;
  }
  session_.set_interrupt({});
  sh_.notifier->send("STOPPING=1");
  if (!interrupted_) publish_state();  // (a step cut short is no state of the simulation's clock)
  hand_over_ticks();
  sh_.physics_done = true;
  sh_.waiter->wake();
}

// systemd's watchdog (WatchdogSec=) hears from the physics loop, twice per interval, only while both threads go
// round: a loop wedged in a step, or an I/O thread wedged in DDS, goes silent and systemd restarts the server.
void Physics::keep_watchdog(Clock::time_point now) {
  const auto interval = *sh_.notifier->watchdog();
  next_watchdog_ = now + interval / 2;
  const Clock::time_point io{Clock::duration(sh_.io_alive.load(std::memory_order_relaxed))};
  if (now - io < interval / 2) sh_.notifier->send("WATCHDOG=1");
}

// The real-time loop, until `stop` or an I/O failure.
void Physics::tick_loop(const std::atomic<bool>& stop) {
  const Rates& rates = session_.rates();
  const double period = 1.0 / rates.physics;
  const auto period_d = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(period));
  auto deadline = Clock::now();
  while (!stop.load(std::memory_order_relaxed) && !sh_.abort.load(std::memory_order_relaxed)) {
    const auto start = Clock::now();
    Clock::duration late{};
    if (rates.real_time_factor > 0 || session_.paused()) {
      late = start - deadline;
      late_us_.push_back(1e6 * seconds(late));
      if (late > period_d) {  // more than a whole tick late: count it and start afresh
        ++missed_;
        deadline = start;
      }
    } else {
      deadline = start;
    }
    take_commands();
    // Not at the place of a failed step: its time may have moved on inside the step, and a checkpoint there would
    // hash the state the failure left, while a state published before the failure at the same place holds the one
    // before (the re-run could not tell which). The next step's own check takes one.
    if (recording_ && !session_.failed() && session_.sim().time() >= next_checkpoint_) checkpoint();
    advance(period, start);
    if (interrupted_) return;  // nothing of a step cut short is published
    tick_.commands = static_cast<std::uint32_t>(taken_);  // those of the wait before this tick and of its start
    taken_ = 0;  // commands applied between ticks and at the next tick's start share one commands.per_tick
    collect_events();
    const auto now = Clock::now();
    if (dirty_ && seconds(now - last_publish_) >= 1.0 / rates.publish - 0.5 * period) {
      publish_state();
      last_publish_ = now;
      tick_.published = true;
    }
    if (seconds(now - last_stats_) >= 1.0 / sh_.config.stats_rate) publish_stats(now);
    if (tick_log_) log_tick(start, late);
    if (sh_.notifier->watchdog() && now >= next_watchdog_) keep_watchdog(now);
    sh_.waiter->wake();
    deadline += period_d;
    const bool timed = rates.real_time_factor > 0 || session_.paused();
    if (timed || realtime_) {
      // Under SCHED_FIFO a loop that never waits (a step longer than the tick, or a real-time factor of 0) leaves the
      // I/O thread, DDS's threads and every other program no processor but what the kernel's real-time throttling
      // gives them: commands went unanswered. When the deadline has passed, it waits all the same, a tenth of the
      // tick or of the time this one took, whichever is longer (the next tick is late by that, and says so).
      // And under SCHED_FIFO the step's second thread sleeps until idle_until wakes it for the next tick (not at all
      // after an overrun: the next step wakes it), instead of spinning through the wait at real-time priority: a
      // real-time thread that never sleeps is stopped by the throttling for the rest of each second (Lanes::rest).
      // Under the normal scheduler it spins on (docs/benchmarks.md, the twelfth round: commands are acknowledged
      // sooner then).
      const auto now_idle = Clock::now();
      const auto yield = std::max(period_d, now_idle - start) / 10;
      auto until = timed ? deadline : now_idle;
      const bool overran = realtime_ && until <= now_idle;
      if (overran) until = now_idle + yield;
      if (realtime_ && (overran || now_idle < until - kHelperLead)) session_.sim().ladder().world().rest_threads();
      idle_until(until, stop, !overran);
    }
  }
}

}  // namespace ladder::daemon
