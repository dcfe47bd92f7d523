#include "daemon/server.hpp"

#include "daemon/handoff.hpp"
#include "daemon/intake.hpp"
#include "daemon/notify.hpp"
#include "daemon/resimulate.hpp"
#include "ladderlcm/checkpoint_t.hpp"
#include "ladderlcm/command_t.hpp"
#include "ladderlcm/event_t.hpp"
#include "ladderlcm/scene_t.hpp"
#include "ladderlcm/state_t.hpp"
#include "transport/dds.hpp"
#include "transport/lcm_log.hpp"
#include "transport/topics.hpp"
#include "transport/version.hpp"

#include <spdlog/spdlog.h>

#include <pthread.h>
#include <sched.h>
#include <sys/prctl.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <deque>
#include <exception>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>
#include <tuple>
#include <unordered_map>
#include <utility>
#include <vector>

namespace ladder::daemon {

namespace {

using Clock = std::chrono::steady_clock;
using transport::copy_text;
using transport::text_of;

const std::string kServerVersion = std::string("ladderd ") + ladder::kVersion;

double seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

std::string number(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

// Cyclone's own warnings and errors, in ladderd's log. A hostile writer can make Cyclone warn once per sample (one
// it cannot deserialize), so at most 10 lines a second go through; the rest are counted in the next line.
void cyclone_line(const char* message) {
  static std::mutex mutex;
  static Clock::time_point window{};
  static int lines = 0;
  static std::uint64_t suppressed = 0;
  std::lock_guard lock(mutex);
  const Clock::time_point now = Clock::now();
  if (now - window >= std::chrono::seconds(1)) window = now, lines = 0;
  if (++lines > 10) {
    ++suppressed;
    return;
  }
  if (suppressed > 0)
    spdlog::warn("cyclone: {} (and {} more lines not shown)", message, std::exchange(suppressed, 0));
  else
    spdlog::warn("cyclone: {}", message);
}

// What the physics thread hands the I/O thread (besides the latest state, which goes through a Latest buffer).
struct EventOut {
  double t = 0;
  std::string kind, detail;
  int hinge = 0;
  double energy_removed = 0;
};
struct SceneOut {
  std::uint32_t generation = 0;
  std::string name, description, top, options;
  std::string text, source;              // what the scene was made from, for the log
  std::vector<std::string> overrides;
  bool timeline_dropped = false;
  int blocks = 0;
  double length = 0, thickness = 0, inset = 0, dt = 0;
  std::vector<double> masses;
  Rates rates;
};
// A command as the simulation took it, for the log.
struct CommandOut {
  ladder_msg_Command command;
  std::uint32_t generation = 0;
  std::uint64_t step = 0, seq = 0;
  bool accepted = false;
  std::string reason;
};
struct CheckpointOut {
  std::uint32_t generation = 0;
  std::uint64_t step = 0, commands_applied = 0, hash = 0;
  double t = 0;
};
// One tick of the real-time loop, for the tick log (ladderd --tick-log). Times on the steady clock, in ns.
struct TickRecord {
  std::uint64_t tick = 0;
  std::int64_t start_ns = 0, late_ns = 0, step_ns = 0;
  std::uint32_t steps = 0, commands = 0;
  bool published = false;
};
// An answer of the physics thread, for the sender whose record keeps it (to answer a repeated command again).
struct AckOut {
  ladder_msg_CommandAck ack;
  SenderKey sender = 0;
};
struct Outbox {
  std::vector<AckOut> acks;
  std::vector<CommandOut> commands;       // only when recording
  std::vector<CheckpointOut> checkpoints;  // only when recording
  std::vector<EventOut> events;
  std::vector<ladder_msg_Stats> stats;
  std::vector<SceneOut> scenes;
  std::vector<TickRecord> ticks;  // only with a tick log
};

// Shared between the two threads. The physics thread only ever holds the locks for a swap or a push.
struct Shared {
  explicit Shared(const ServerConfig& c) : config(c) {}
  const ServerConfig& config;
  std::mutex inbox_mutex;
  std::condition_variable inbox_cv;  // a command came: wakes the physics thread between ticks
  Inbox inbox;
  std::mutex outbox_mutex;
  Outbox outbox;
  Latest<StateFrame> state;
  std::atomic<std::uint64_t> received{0}, rate_limited{0}, duplicates{0}, unanswered{0}, states_published{0},
      states_dropped{0}, events_published{0}, write_failures{0};
  std::atomic<bool> physics_done{false};
  std::atomic<bool> abort{false};  // the I/O thread failed: the physics thread stops too
  const transport::Waiter* waiter = nullptr;  // to wake the I/O thread
  const Notifier* notifier = nullptr;          // systemd's, when it started us
  std::atomic<Clock::rep> io_alive{0};         // when the I/O thread last went round its loop
};

// The answer to command c: addressed to its client, with the outcome; the caller adds when it took effect.
ladder_msg_CommandAck ack_for(const ladder_msg_Command& c, const Outcome& r) {
  ladder_msg_CommandAck a{};
  std::memcpy(a.sim_id, c.sim_id, sizeof a.sim_id);
  std::memcpy(a.client_id, c.client_id, sizeof a.client_id);
  a.command_id = c.command_id;
  a.accepted = r.accepted;
  copy_text(a.reason, r.reason);
  return a;
}

// Percentiles of a window of samples [us]; the window is cleared.
struct Percentiles {
  double p50 = 0, p99 = 0, max = 0;
};
Percentiles percentiles(std::vector<double>& v) {
  Percentiles p;
  if (v.empty()) return p;
  const auto at = [&](double q) {
    const auto k = static_cast<std::ptrdiff_t>(q * static_cast<double>(v.size() - 1));
    std::nth_element(v.begin(), v.begin() + k, v.end());
    return v[static_cast<std::size_t>(k)];
  };
  p.p50 = at(0.5);
  p.p99 = at(0.99);
  p.max = *std::max_element(v.begin(), v.end());
  v.clear();
  return p;
}

void fill_frame(const Session& s, std::uint64_t commands_applied, StateFrame& f) {
  const model::Ladder& l = s.sim().ladder();
  f.generation = s.generation();
  f.step = s.sim().steps();
  f.t = s.sim().time();
  f.paused = s.paused();
  f.commands_applied = commands_applied;
  f.energy = l.energy();
  const auto n = static_cast<std::size_t>(l.blocks());
  f.poses.resize(3 * n);
  f.hinge_corner.resize(n);
  f.hinge_status.resize(n);
  f.hinge_flips.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    core::Vec2 c;
    l.block_pose(static_cast<int>(i), c, f.poses[3 * i + 2]);
    f.poses[3 * i] = c.x();
    f.poses[3 * i + 1] = c.y();
    const model::HingeInfo& h = l.hinges()[i];
    f.hinge_corner[i] = static_cast<std::uint8_t>(h.corner);
    f.hinge_status[i] = h.status == model::HingeStatus::Hinged   ? ladder_msg_HINGED
                        : h.status == model::HingeStatus::Locked ? ladder_msg_LOCKED
                                                                 : ladder_msg_BROKEN;
    f.hinge_flips[i] = static_cast<std::uint32_t>(h.flips);
  }
  f.grips.clear();
  for (const model::Ladder::Grip& g : l.grips())
    f.grips.push_back({g.block, g.target.x(), g.target.y(), g.hold_angle, g.angle});
}

// The final guard before a State is handed over: the name of its first non-finite number, or "" when all are
// finite. The commands' checks and the step's watchdog should leave none; one that slips through must not reach
// a client (a viewer that divides by it, or a controller that feeds it back, fails far from the cause).
std::string non_finite_in(const StateFrame& f) {
  if (!std::isfinite(f.t)) return "sim_time";
  if (!std::isfinite(f.energy)) return "energy";
  static constexpr const char* kPose[] = {"x", "y", "theta"};
  for (std::size_t i = 0; i < f.poses.size(); ++i)
    if (!std::isfinite(f.poses[i])) return "block " + std::to_string(i / 3) + "'s " + kPose[i % 3];
  for (const ladder_msg_Grip& g : f.grips)
    if (!std::isfinite(g.target_x) || !std::isfinite(g.target_y) || !std::isfinite(g.angle))
      return "the grip on block " + std::to_string(g.block);
  return {};
}

// Replaces a non-finite number by 0 and counts it, naming the field in `fields` (Stats and events are figures for
// people and plots: a 0 there with a log line is better than a NaN that breaks every reader).
void finite_or_zero(double& v, const char* name, std::string& fields, std::uint64_t& count) {
  if (std::isfinite(v)) return;
  v = 0;
  ++count;
  fields += fields.empty() ? name : std::string(", ") + name;
}

SceneOut scene_out(const Session& s) {
  const scene::Scene& sc = s.sim().scene();
  const model::LadderSpec& l = sc.ladder;
  SceneOut o;
  o.generation = s.generation();
  o.name = sc.name;
  o.description = sc.description;
  o.top = l.top == model::Top::Held ? "held" : l.top == model::Top::Pinned ? "pinned" : "free";
  o.options = scene::live_settings(sc);
  o.blocks = l.blocks;
  o.length = l.length;
  o.thickness = l.thickness;
  o.inset = l.hinge_inset;
  o.dt = sc.dt;
  o.masses = l.masses.empty() ? std::vector<double>(static_cast<std::size_t>(l.blocks), l.mass) : l.masses;
  o.rates = s.rates();
  o.text = sc.text;
  o.source = sc.source;
  o.overrides = sc.overrides;
  o.timeline_dropped = sc.timeline_dropped;
  return o;
}

// ---------------------------------------------------------------------------------------------------------------
// The physics thread

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

  void run(const std::atomic<bool>& stop);

 private:
  void tick_loop(const std::atomic<bool>& stop);
  void take_commands();
  void idle_until(Clock::time_point deadline, const std::atomic<bool>& stop);
  void advance(double period, Clock::time_point tick_start);
  void collect_events();
  void publish_state();
  void publish_stats(Clock::time_point now);
  void run_step();
  void push_scene();
  void checkpoint();
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
  double debt_ = 0;  // sim time owed to the real-time clock [s]
  std::vector<double> step_us_, late_us_;
  std::uint64_t missed_ = 0, accepted_ = 0, refused_ = 0;
  std::size_t taken_ = 0;  // commands taken since the last tick's step (at most commands.per_tick)
  const char* taking_ = "";  // where take_commands() is called from, for the debug log
  double sim_at_last_stats_ = 0;
  Clock::time_point last_stats_{}, last_publish_{};
  std::uint32_t scene_generation_ = 0;
  Rates scene_rates_{};
  std::string scene_options_;  // the live settings the last SceneInfo carried
  bool recording_;
  bool tick_log_;
  TickRecord tick_;                // the tick under way, for the tick log
  std::vector<TickRecord> ticks_;  // ticks not yet handed to the I/O thread
  double next_checkpoint_ = 0;  // [s of sim time]
  bool dirty_ = true;  // the state changed (or a command came) since the last publish; paused states publish only then
  std::uint64_t stats_zeroed_ = 0, events_zeroed_ = 0;  // non-finite fields sent as 0 (the final guard)
  // The sim time for an event, 0 if it is not finite.
  double finite_time() const { return std::isfinite(session_.sim().time()) ? session_.sim().time() : 0; }
  Clock::time_point next_watchdog_{};  // when systemd's watchdog is next told that all is well
};

void Physics::checkpoint() {
  const scene::Simulation& sim = session_.sim();
  const CheckpointOut c{session_.generation(), sim.steps(), accepted_ + refused_, session_.state_hash(), sim.time()};
  with_outbox([&](Outbox& o) { o.checkpoints.push_back(c); });
  next_checkpoint_ = sim.time() + sh_.config.checkpoint_every;
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
    const Outcome r = session_.apply(c);
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
      spdlog::info("{} {} from {}: accepted: {}", to_string(c.kind), c.command_id, text_of(c.client_id), r.reason);
    else if (r.accepted)
      spdlog::debug("{} {} from {}: accepted at t = {:.6f} s{}", to_string(c.kind), c.command_id, text_of(c.client_id), t,
                    taking_);
    else
      spdlog::info("{} {} from {}: refused: {}", to_string(c.kind), c.command_id, text_of(c.client_id), r.reason);
    // SceneInfo carries the live settings and the rates: published (and logged) again when they change. A setting
    // that leaves them as they were (a value they already had) sends none: at N = 10 000 a SceneInfo is 80 kB of
    // masses to every reader.
    if (restarted ||
        (r.accepted && c.kind == ladder_msg_SET_PARAM &&
         scene::live_settings(session_.sim().scene()) != scene_options_) ||
        std::tie(session_.rates().publish, session_.rates().real_time_factor) !=
            std::tie(scene_rates_.publish, scene_rates_.real_time_factor)) {
      if (restarted) {
        debt_ = 0;
        spdlog::info("scene '{}' started ({} blocks)", session_.sim().scene().name, session_.sim().ladder().blocks());
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

// Waits for the next tick's deadline. A command that arrives meanwhile is applied at once: the simulation already
// stands where the next tick starts, so it takes effect at the same sim time as it would then, and its ack goes
// out without waiting for the deadline. The last server.spin_us before the deadline are busy-waited.
void Physics::idle_until(Clock::time_point deadline, const std::atomic<bool>& stop) {
  const auto halted = [&] { return stop.load(std::memory_order_relaxed) || sh_.abort.load(std::memory_order_relaxed); };
  const auto ready = [&] { return (!sh_.inbox.empty() && taken_ < sh_.config.per_tick) || halted(); };
  const auto wake = deadline - std::chrono::microseconds(sh_.config.spin_us);
  std::unique_lock lock(sh_.inbox_mutex);
  while (true) {
    const auto now = Clock::now();
    const bool sleeping = now < wake;  // else spinning
    if (sleeping) {
      if (!sh_.inbox_cv.wait_until(lock, wake, ready)) continue;
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
  dirty_ = true;
  const auto t0 = Clock::now();
  try {
    session_.step();
  } catch (const std::runtime_error& e) {
    spdlog::error("step failed, simulation paused: {}", e.what());
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
    spdlog::info("t = {:.6f} s: {} at hinge {}{}{}", e.t, e.kind, e.hinge, e.detail.empty() ? "" : ": ", e.detail);
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
  s.real_time_factor = s.window > 0 ? std::max(0.0, sim.time() - sim_at_last_stats_) / s.window : 0;
  s.missed_deadlines = missed_;
  s.solver_iterations = static_cast<std::uint32_t>(sim.ladder().world().last_step().iterations);
  s.solver_residual = sim.ladder().world().last_step().residual;
  s.energy = sim.ladder().energy();
  s.max_hinge_error = sim.max_hinge_error();
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
}

void Physics::run(const std::atomic<bool>& stop) {
  prctl(PR_SET_TIMERSLACK, 1UL);  // wake within microseconds of the deadline, not the default 50 us
  last_stats_ = last_publish_ = Clock::now();
  tick_.tick = 1;
  ticks_.reserve(250);
  push_scene();
  publish_state();
  try {
    tick_loop(stop);
  } catch (...) {
    hand_over_ticks();  // the ticks before a failure are the ones worth reading
    throw;
  }
  sh_.notifier->send("STOPPING=1");
  publish_state();
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
    if (recording_ && session_.sim().time() >= next_checkpoint_) checkpoint();
    advance(period, start);
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
    if (rates.real_time_factor > 0 || session_.paused()) idle_until(deadline, stop);
  }
}

// ---------------------------------------------------------------------------------------------------------------
// The I/O thread: DDS in and out.

class Io {
 public:
  Io(Shared& shared, transport::LogWriter* log, std::FILE* tick_log)
      : sh_(shared),
        log_(log),
        tick_log_(tick_log),
        participant_(transport::make_participant(static_cast<dds_domainid_t>(shared.config.domain))),
        topics_(participant_),
        scene_w_(participant_, topics_.scene_info, transport::Profile::SceneInfo),
        state_w_(participant_, topics_.state, transport::Profile::State),
        ack_w_(participant_, topics_.ack, transport::Profile::CommandAck),
        event_w_(participant_, topics_.event, transport::Profile::Event),
        stats_w_(participant_, topics_.stats, transport::Profile::Stats),
        command_r_(participant_, topics_.command, transport::Profile::Command),
        waiter_(participant_) {
    waiter_.attach(command_r_.entity());
    sh_.waiter = &waiter_;
  }

  // Until the physics thread has finished and everything it handed over is written.
  void run();

 private:
  // A client's command writer: whether this server can answer it yet (its ack and event writers have found a
  // reader in the writer's participant), and its commands meanwhile.
  // Also what it may send (its rate), what it sent lately (repeats are answered, not applied) and what this server
  // could not answer it, for the log.
  struct Sender {
    Sender(const ServerConfig& c, Clock::time_point now)
        : first_seen(now), commands(c.rate, c.burst, now), refusals(c.rate, c.burst, now), next_report(now) {}
    std::string client;                     // the client id of its first command, for the log
    std::optional<dds_guid_t> participant;  // none: the writer had left when its first command was read
    Clock::time_point first_seen, next_check;
    bool ready = false;
    std::deque<Incoming> held;  // in the order they came
    Bucket commands, refusals;  // commands.rate and commands.burst, each
    RecentCommands recent;
    std::uint64_t rate_limited = 0, unanswered = 0;  // since the last report
    Clock::time_point next_report;
  };

  void take_commands();
  void admit(Sender& s, const ladder_msg_Command& c, dds_instance_handle_t writer, Clock::time_point now,
             std::vector<Incoming>& ready);
  Sender& sender(dds_instance_handle_t writer, const ladder_msg_Command& c, Clock::time_point now);
  void check(Sender& s, Clock::time_point now);
  void release_answerable(std::vector<Incoming>& ready);
  void queue_for_physics(std::vector<Incoming>& ready);
  void refuse_for_rate(const Incoming& in, const std::string& reason);
  void report(Sender& s, Clock::time_point now);
  void forget_departed_senders();
  void refuse_leftovers();
  void write_outbox();
  void write_state();
  void refuse(const ladder_msg_Command& c, const std::string& reason);
  void answer(const ladder_msg_Command& c, const Answer& a);
  void remember(const AckOut& a);
  // Counts a failed write (a write that Cyclone could not take: it does not end the server) and logs it, once a
  // topic at first and then at most every 10 s.
  void written(dds_return_t rc, const char* topic);

  void record_outbox();
  void record_state(const StateFrame& f, std::uint64_t seq);
  void write_ticks();

  Shared& sh_;
  transport::LogWriter* log_;  // null when not recording
  std::FILE* tick_log_;        // null without --tick-log
  transport::Entity participant_;  // first: destroyed last
  transport::Topics topics_;
  transport::Writer<ladder_msg_SceneInfo> scene_w_;
  transport::Writer<ladder_msg_State> state_w_;
  transport::Writer<ladder_msg_CommandAck> ack_w_;
  transport::Writer<ladder_msg_Event> event_w_;
  transport::Writer<ladder_msg_Stats> stats_w_;
  transport::Reader<ladder_msg_Command> command_r_;
  transport::Waiter waiter_;
  std::uint64_t state_seq_ = 0, event_seq_ = 0, logged_events_ = 0;
  std::uint32_t generation_ = 0;
  Outbox out_;
  std::unordered_map<dds_instance_handle_t, Sender> senders_;
  std::vector<dds_instance_handle_t> waiting_;  // the senders not ready yet
  std::size_t forget_above_ = 256;              // senders known before those that have left are forgotten
  std::unordered_map<std::string, Clock::time_point> write_failure_logged_;  // by topic
};

void Io::written(dds_return_t rc, const char* topic) {
  if (rc >= 0) return;
  sh_.write_failures.fetch_add(1, std::memory_order_relaxed);
  const Clock::time_point now = Clock::now();
  const auto last = write_failure_logged_.find(topic);
  if (last != write_failure_logged_.end() && now - last->second < std::chrono::seconds(10)) return;
  write_failure_logged_[topic] = now;
  spdlog::warn("a write on {} failed: {} (the sample is lost to its readers; the server goes on; {} writes have "
               "failed so far)",
               topic, dds_strretcode(rc), sh_.write_failures.load());
}

void Io::refuse(const ladder_msg_Command& c, const std::string& reason) {
  ladder_msg_CommandAck a = ack_for(c, {false, reason});
  a.sim_time = -1;  // never reached the simulation
  written(ack_w_.try_write(a), "ladder/CommandAck");
}

// A repeated command's answer: the first one's, again.
void Io::answer(const ladder_msg_Command& c, const Answer& r) {
  ladder_msg_CommandAck a = ack_for(c, {r.accepted, r.reason});
  a.sim_time = r.sim_time;
  a.step = r.step;
  a.command_seq = r.command_seq;
  written(ack_w_.try_write(a), "ladder/CommandAck");
}

void Io::remember(const AckOut& out) {
  const auto s = senders_.find(out.sender);
  if (s == senders_.end()) return;  // forgotten meanwhile (it had left)
  const ladder_msg_CommandAck& a = out.ack;
  s->second.recent.answered(a.client_id, a.command_id,
                            {a.accepted, text_of(a.reason), a.sim_time, a.step, a.command_seq});
}

// Commands go to the physics thread in the order they arrived, with one exception: a sender's commands wait until
// this server's ack and event writers have found a reader in the sender's participant (commands.reader_wait at
// most). Discovery can bring a client's command writer before its readers, and an ack written then reaches no one.
// The commands of one sender keep their order. This thread takes every sample as it comes, whatever the senders
// do: what a sender may not send is refused or dropped here, in constant time, so that a flood neither grows this
// server's memory nor delays another sender's commands (docs/server.md, "Intake").
void Io::take_commands() {
  const std::string& id = sh_.config.sim_id;
  const Clock::time_point now = Clock::now();
  std::vector<Incoming> ready;
  std::size_t arrived = 0;
  command_r_.take([&](const ladder_msg_Command& c, const dds_sample_info_t& info) {
    if (text_of(c.sim_id) != id) return;  // commands for other ladders on this domain are not ours
    ++arrived;
    admit(sender(info.publication_handle, c, now), c, info.publication_handle, now, ready);
  });
  sh_.received.fetch_add(arrived);
  if (!waiting_.empty()) release_answerable(ready);
  if (!ready.empty()) queue_for_physics(ready);
  for (auto& [writer, s] : senders_)
    if (s.rate_limited + s.unanswered > 0 && now >= s.next_report) report(s, now);
}

// One command of sender s: a repeat is answered again (or waits for the answer it shares), a command over the
// sender's rate is refused (within the refusals' own rate) or dropped, and the rest go on, held while the sender
// cannot hear answers yet.
void Io::admit(Sender& s, const ladder_msg_Command& c, dds_instance_handle_t writer, Clock::time_point now,
               std::vector<Incoming>& ready) {
  switch (s.recent.note(c)) {
    case RecentCommands::Seen::Answered:
      sh_.duplicates.fetch_add(1, std::memory_order_relaxed);
      if (s.refusals.take(now)) answer(c, *s.recent.answer(c));
      return;
    case RecentCommands::Seen::Pending:  // its answer, when it comes, is theirs too
      sh_.duplicates.fetch_add(1, std::memory_order_relaxed);
      return;
    case RecentCommands::Seen::New:
      break;
  }
  if (!s.commands.take(now)) {
    refuse_for_rate({c, writer},
                    "rate limit: more than " + number(sh_.config.rate) + " commands a second (commands.rate, " +
                        number(sh_.config.burst) + " at once: commands.burst) from this client; send fewer");
    return;
  }
  if (!s.ready) {
    if (s.held.size() < sh_.config.queue) {
      s.held.push_back({c, writer});
      return;
    }
    refuse_for_rate({c, writer}, "rate limit: " + std::to_string(sh_.config.queue) +
                                     " commands of this client are already waiting (commands.queue); send fewer");
    return;
  }
  ready.push_back({c, writer});
}

// Commands refused before they reach the simulation: answered while the sender's refusals last, else dropped
// unanswered. Either way counted, and reported in the log once a second per sender.
void Io::refuse_for_rate(const Incoming& in, const std::string& reason) {
  const auto it = senders_.find(in.sender);
  if (it == senders_.end()) return;
  Sender& s = it->second;
  s.recent.forget(in.command);  // sent again later, it is a new command
  if (s.refusals.take(Clock::now())) {
    sh_.rate_limited.fetch_add(1, std::memory_order_relaxed);
    ++s.rate_limited;
    refuse(in.command, reason);
  } else {
    sh_.unanswered.fetch_add(1, std::memory_order_relaxed);
    ++s.unanswered;
  }
}

void Io::report(Sender& s, Clock::time_point now) {
  if (s.unanswered > 0)
    spdlog::warn("client '{}' sends faster than commands.rate ({}/s): {} of its commands refused and {} dropped "
                 "unanswered (its refusals are limited to the same rate) since the last report",
                 s.client, number(sh_.config.rate), s.rate_limited, s.unanswered);
  else
    spdlog::warn("client '{}': {} of its commands refused for rate since the last report", s.client, s.rate_limited);
  s.rate_limited = s.unanswered = 0;
  s.next_report = now + std::chrono::seconds(1);
}

// Each sender's commands join its own queue of the inbox (commands.queue at most); the physics thread takes the
// queues in turn.
void Io::queue_for_physics(std::vector<Incoming>& ready) {
  std::vector<Incoming> over;
  {
    std::lock_guard lock(sh_.inbox_mutex);
    for (Incoming& in : ready)
      if (!sh_.inbox.push(in, sh_.config.queue)) over.push_back(std::move(in));
  }
  sh_.inbox_cv.notify_one();
  for (const Incoming& in : over)
    refuse_for_rate(in, "rate limit: " + std::to_string(sh_.config.queue) +
                            " commands of this client are already waiting (commands.queue); send fewer");
}

// The sender of a command from `writer`, known or new. A new one is checked at once: usually it is ready.
Io::Sender& Io::sender(dds_instance_handle_t writer, const ladder_msg_Command& c, Clock::time_point now) {
  if (const auto known = senders_.find(writer); known != senders_.end()) return known->second;
  if (senders_.size() >= forget_above_) forget_departed_senders();
  Sender& s = senders_.try_emplace(writer, sh_.config, now).first->second;
  s.client = text_of(c.client_id);
  s.participant = transport::writer_participant(command_r_.entity(), writer);
  check(s, now);
  if (!s.ready) {
    waiting_.push_back(writer);
    spdlog::debug("client '{}': its commands wait until its ack and event readers are found", s.client);
  }
  return s;
}

void Io::check(Sender& s, Clock::time_point now) {
  s.next_check = now + std::chrono::milliseconds(2);  // the lookups cost a copy per matched reader
  s.ready = !s.participant || (ack_w_.matched_in(*s.participant) && event_w_.matched_in(*s.participant));
  const double waited = seconds(now - s.first_seen);
  if (s.ready) {
    if (waited > 0) spdlog::debug("client '{}': its readers found after {:.0f} ms", s.client, 1e3 * waited);
  } else if (waited >= sh_.config.reader_wait) {
    s.ready = true;
    spdlog::warn("client '{}': its ack or event reader not found in {:g} s; its commands go on, and it may miss "
                 "their answers",
                 s.client, sh_.config.reader_wait);
  }
}

// Moves the commands of the senders that have become ready to `ready`, in their order.
void Io::release_answerable(std::vector<Incoming>& ready) {
  const Clock::time_point now = Clock::now();
  std::erase_if(waiting_, [&](dds_instance_handle_t writer) {
    Sender& s = senders_.at(writer);
    if (now < s.next_check) return false;
    check(s, now);
    if (!s.ready) return false;
    ready.insert(ready.end(), s.held.begin(), s.held.end());
    s.held.clear();
    return true;
  });
}

// Forgets the command writers that have left (each ladderctl run is one), keeping those still waiting.
void Io::forget_departed_senders() {
  std::vector<dds_instance_handle_t> keep = transport::matched_writers(command_r_.entity());
  keep.insert(keep.end(), waiting_.begin(), waiting_.end());
  std::sort(keep.begin(), keep.end());
  std::erase_if(senders_, [&](const auto& s) { return !std::binary_search(keep.begin(), keep.end(), s.first); });
  forget_above_ = std::max<std::size_t>(256, 2 * senders_.size());
}

// At the stop: the commands the physics thread did not take, and those still held, are refused. (A sender still
// held may not hear it.)
void Io::refuse_leftovers() {
  std::vector<Incoming> left;
  {
    std::lock_guard lock(sh_.inbox_mutex);
    left = sh_.inbox.drain();
  }
  for (dds_instance_handle_t writer : waiting_) {
    std::deque<Incoming>& held = senders_.at(writer).held;
    left.insert(left.end(), held.begin(), held.end());
    held.clear();
  }
  for (const Incoming& in : left) refuse(in.command, "ladderd stopped before it could take this command");
}

void Io::write_outbox() {
  {
    std::lock_guard lock(sh_.outbox_mutex);
    std::swap(out_, sh_.outbox);
  }
  for (const SceneOut& s : out_.scenes) {
    ladder_msg_SceneInfo m{};
    copy_text(m.sim_id, sh_.config.sim_id);
    m.generation = generation_ = s.generation;
    copy_text(m.scene_name, s.name);
    copy_text(m.description, s.description);
    copy_text(m.server_version, kServerVersion);
    m.blocks = static_cast<std::uint32_t>(s.blocks);
    m.length = s.length;
    m.thickness = s.thickness;
    m.hinge_inset = s.inset;
    transport::lend(m.masses, s.masses);
    copy_text(m.top, s.top);
    m.dt = s.dt;
    m.physics_rate = s.rates.physics;
    m.publish_rate = s.rates.publish;
    m.real_time_factor = s.rates.real_time_factor;
    copy_text(m.options, s.options);
    written(scene_w_.try_write(m), "ladder/SceneInfo");
  }
  // A command is in the log, flushed to the file, before its ack goes out: an acknowledged command survives a
  // kill -9 (--resume replays it).
  if (log_) record_outbox();
  if (log_ && !out_.commands.empty() && !log_->sync(std::chrono::seconds(5)) && log_->failed_syncs() == 1)
    spdlog::error("session log {}: writing it failed or took over 5 s; until it catches up, commands are "
                  "acknowledged before they are in it (said once)", log_->path());
  for (const AckOut& a : out_.acks) {
    written(ack_w_.try_write(a.ack), "ladder/CommandAck");
    remember(a);
  }
  for (const EventOut& e : out_.events) {
    ladder_msg_Event m{};
    copy_text(m.sim_id, sh_.config.sim_id);
    m.seq = ++event_seq_;
    m.t = e.t;
    copy_text(m.kind, e.kind);
    m.hinge = e.hinge;
    m.energy_removed = e.energy_removed;
    copy_text(m.detail, e.detail);
    written(event_w_.try_write(m), "ladder/Event");
  }
  sh_.events_published.fetch_add(out_.events.size());
  for (const ladder_msg_Stats& s : out_.stats) written(stats_w_.try_write(s), "ladder/Stats");
  if (tick_log_) write_ticks();
  out_.ticks.clear();
  out_.commands.clear();
  out_.checkpoints.clear();
  out_.scenes.clear();
  out_.acks.clear();
  out_.events.clear();
  out_.stats.clear();
}

void Io::write_state() {
  const StateFrame* f = sh_.state.take();
  if (!f) return;
  ladder_msg_State m{};
  copy_text(m.sim_id, sh_.config.sim_id);
  m.generation = f->generation;
  m.seq = ++state_seq_;
  m.step = f->step;
  m.sim_time = f->t;
  m.paused = f->paused;
  m.commands_applied = f->commands_applied;
  m.energy = f->energy;
  // Borrowed buffers: DDS serialises them in write() and must not free them.
  transport::lend_blocks(m, f->poses, f->hinge_corner, f->hinge_status, f->hinge_flips);
  transport::lend(m.grips, f->grips);
  written(state_w_.try_write(m), "ladder/State");
  if (sh_.states_published.fetch_add(1, std::memory_order_relaxed) == 0)  // the first is on the wire: ready
    sh_.notifier->send("READY=1\nSTATUS=serving sim id '" + sh_.config.sim_id + "' on DDS domain " +
                       std::to_string(sh_.config.domain));
  if (log_) record_state(*f, m.seq);
}

void Io::write_ticks() {
  if (out_.ticks.empty()) return;
  for (const TickRecord& t : out_.ticks)
    std::fprintf(tick_log_, "%llu %lld %lld %lld %u %u %d\n", static_cast<unsigned long long>(t.tick),
                 static_cast<long long>(t.start_ns), static_cast<long long>(t.late_ns),
                 static_cast<long long>(t.step_ns), t.steps, t.commands, t.published ? 1 : 0);
  std::fflush(tick_log_);  // a few times a second: `tail -f` follows it
}

// The session log (ladderd --record): what was published, and the commands as the simulation took them. The
// encoding happens here, on the I/O thread; the writer's own thread does the file I/O.
void Io::record_outbox() {
  const std::int64_t now = transport::now_us();
  for (const SceneOut& s : out_.scenes) {
    ladderlcm::scene_t m;
    m.utime = now;
    m.sim_id = sh_.config.sim_id;
    m.generation = static_cast<std::int32_t>(s.generation);
    m.name = s.name;
    m.source = s.source;
    m.toml = s.text;
    m.overrides = s.overrides;
    m.num_overrides = static_cast<std::int32_t>(s.overrides.size());
    m.clear_timeline = s.timeline_dropped;
    m.blocks = s.blocks;
    m.length = s.length;
    m.thickness = s.thickness;
    m.hinge_inset = s.inset;
    m.dt = s.dt;
    m.top = s.top;
    m.masses = s.masses;
    m.server_version = kServerVersion;
    log_->write(transport::kSceneChannel, now, m, false);
  }
  for (const CommandOut& c : out_.commands) {
    ladderlcm::command_t m = command_record(c.command);
    m.utime = now;
    m.generation = static_cast<std::int32_t>(c.generation);
    m.step = static_cast<std::int64_t>(c.step);
    m.command_seq = static_cast<std::int64_t>(c.seq);
    m.accepted = c.accepted;
    m.reason = c.reason;
    log_->write(transport::kCommandChannel, now, m, false);
  }
  for (const EventOut& e : out_.events) {
    ladderlcm::event_t m;
    m.utime = now;
    m.seq = static_cast<std::int64_t>(++logged_events_);
    m.t = e.t;
    m.kind = e.kind;
    m.hinge = e.hinge;
    m.energy_removed = e.energy_removed;
    m.detail = e.detail;
    log_->write(transport::kEventChannel, now, m, false);
  }
  for (const CheckpointOut& c : out_.checkpoints) {
    ladderlcm::checkpoint_t m;
    m.utime = now;
    m.generation = static_cast<std::int32_t>(c.generation);
    m.step = static_cast<std::int64_t>(c.step);
    m.sim_time = c.t;
    m.commands_applied = static_cast<std::int64_t>(c.commands_applied);
    m.state_hash = static_cast<std::int64_t>(c.hash);
    log_->write(transport::kCheckpointChannel, now, m, false);
  }
}

void Io::record_state(const StateFrame& f, std::uint64_t seq) {
  ladderlcm::state_t m;
  m.utime = transport::now_us();
  m.generation = static_cast<std::int32_t>(f.generation);
  m.seq = static_cast<std::int64_t>(seq);
  m.step = static_cast<std::int64_t>(f.step);
  m.sim_time = f.t;
  m.paused = f.paused;
  m.commands_applied = static_cast<std::int64_t>(f.commands_applied);
  m.energy = f.energy;
  const std::size_t n = f.hinge_corner.size();
  m.num_blocks = static_cast<std::int32_t>(n);
  m.x.resize(n), m.y.resize(n), m.theta.resize(n), m.corner.resize(n), m.status.resize(n), m.flips.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    m.x[i] = f.poses[3 * i], m.y[i] = f.poses[3 * i + 1], m.theta[i] = f.poses[3 * i + 2];
    m.corner[i] = static_cast<std::int8_t>(f.hinge_corner[i]);
    m.status[i] = static_cast<std::int8_t>(f.hinge_status[i]);
    m.flips[i] = static_cast<std::int32_t>(f.hinge_flips[i]);
  }
  log_->write(transport::kStateChannel, m.utime, m, true);
}

void Io::run() {
  while (true) {
    sh_.io_alive.store(Clock::now().time_since_epoch().count(), std::memory_order_relaxed);
    const bool done = sh_.physics_done.load();
    waiter_.wait(std::chrono::milliseconds(5));
    take_commands();
    write_outbox();  // scene info before the states of its generation
    write_state();
    if (done) break;
  }
  refuse_leftovers();
}

using File = std::unique_ptr<std::FILE, int (*)(std::FILE*)>;

// The tick log's file with its header (docs/server.md, "The tick log").
File open_tick_log(const ServerConfig& config) {
  File f(nullptr, &std::fclose);
  if (config.tick_log.empty()) return f;
  f.reset(std::fopen(config.tick_log.c_str(), "w"));
  if (!f) throw OutputError("cannot create the tick log '" + config.tick_log + "': " + std::strerror(errno));
  std::fprintf(f.get(),
               "# %s tick log, sim id '%s', physics rate %g Hz: one line per tick of the real-time loop.\n"
               "# start_ns: when the tick started, on CLOCK_MONOTONIC [ns]; late_ns: how late that was against its "
               "deadline [ns]\n"
               "# (0 while running at real-time factor 0); step_ns, steps: time in and number of physics steps in the "
               "tick;\n"
               "# commands: commands applied since the previous tick's end; published: 1 if the tick handed a state "
               "over.\n"
               "# tick start_ns late_ns step_ns steps commands published\n",
               kServerVersion.c_str(), config.sim_id.c_str(), config.rates.physics);
  return f;
}

// Puts the calling thread under SCHED_FIFO at `priority`, so that no thread of the normal scheduler (other programs:
// viewers on the same cores) delays it; says which. Returns whether it could.
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

}  // namespace

int run_server(const ServerConfig& config, const scene::Scene& scene, const std::atomic<bool>& stop) {
  return run_server(config, std::make_unique<Session>(scene, config.scenes_dir, config.limits, config.rates), stop);
}

int run_server(const ServerConfig& config, std::unique_ptr<Session> session, const std::atomic<bool>& stop) {
  const scene::Scene& scene = session->sim().scene();
  Shared shared(config);
  const Notifier notifier;
  shared.notifier = &notifier;
  if (notifier.enabled())
    spdlog::info("telling systemd when ready and stopping{}",
                 notifier.watchdog() ? ", and its watchdog every " +
                                           std::to_string(notifier.watchdog()->count() / 2000) + " ms"
                                     : std::string());
  std::unique_ptr<transport::LogWriter> log;
  if (!config.record.empty()) {
    try {
      log = std::make_unique<transport::LogWriter>(config.record);
    } catch (const std::runtime_error& e) {
      throw OutputError(e.what());
    }
    spdlog::info("recording the session to {}", config.record);
  }
  const File tick_log = open_tick_log(config);
  if (tick_log) spdlog::info("writing one line per tick to {}", config.tick_log);
  // With a real-time priority this (the I/O) thread runs just below the physics thread, and so do DDS's threads,
  // which inherit it when Io starts them: a thread of the normal scheduler could otherwise hold the I/O side up while
  // the physics thread waits for the hand-off's lock.
  const bool realtime =
      config.realtime_priority > 0 && run_realtime("I/O", std::max(1, config.realtime_priority - 1));
  transport::route_cyclone_log(cyclone_line, "ladder/Command");
  Io io(shared, log.get(), tick_log.get());
  Physics physics(shared, std::move(session));
  spdlog::info("serving '{}' as sim id '{}' on DDS domain {}: {} blocks, {} Hz physics, {} Hz states, real-time "
               "factor {}",
               scene.name, config.sim_id, config.domain, scene.ladder.blocks, config.rates.physics,
               config.rates.publish, config.rates.real_time_factor);
  if (config.spin_us > 0) spdlog::info("the physics thread busy-waits the last {} us before each tick", config.spin_us);
  std::exception_ptr physics_error;
  std::thread physics_thread([&] {
    if (realtime) run_realtime("physics", config.realtime_priority);
    try {
      physics.run(stop);
    } catch (...) {
      physics_error = std::current_exception();
      shared.physics_done = true;
    }
  });
  try {
    io.run();
  } catch (...) {
    {
      std::lock_guard lock(shared.inbox_mutex);  // a DDS failure on the I/O side: stop the physics thread (waking it)
      shared.abort = true;                       // before unwinding
    }
    shared.inbox_cv.notify_all();
    physics_thread.join();
    throw;
  }
  physics_thread.join();
  if (tick_log && (std::fflush(tick_log.get()) != 0 || std::ferror(tick_log.get())))
    spdlog::warn("the tick log {} is incomplete: writing to it failed", config.tick_log);
  if (log) {
    log.reset();  // writes what is queued, flushes, closes
    spdlog::info("session log {} closed", config.record);
  }
  if (physics_error) std::rethrow_exception(physics_error);
  return 0;
}

}  // namespace ladder::daemon
