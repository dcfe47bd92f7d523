#include "daemon/io.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cstdio>
#include <mutex>
#include <utility>

namespace ladder::daemon {

namespace {

using transport::copy_text;
using transport::text_of;

std::string number(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

}  // namespace

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
// A client that reads acks but no events waits kEventGrace after its ack reader is found, not commands.reader_wait:
// a participant's readers are discovered together, milliseconds apart.
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
    admit(sender(info.publication_handle, c, now), c, now, ready);
  });
  sh_.received.fetch_add(arrived);
  // Clients that have left are forgotten within a second (their memory of answers, about 0.6 MB each, is kept no
  // longer than they are there), and at once when many writers have come (forget_above_).
  if (now >= next_forget_) {
    forget_departed_senders();
    next_forget_ = now + std::chrono::seconds(1);
  }
  if (!waiting_.empty()) release_answerable(ready);
  if (!ready.empty()) queue_for_physics(ready);
  for (auto& [key, s] : senders_)
    if (s.rate_limited + s.unanswered > 0 && now >= s.next_report) report(s, now);
}

// One command of sender s: a repeat is answered again (or waits for the answer it shares), a command over the
// sender's rate is refused (within the refusals' own rate) or dropped, and the rest go on, held while the sender
// cannot hear answers yet.
void Io::admit(Sender& s, const ladder_msg_Command& c, Clock::time_point now, std::vector<Incoming>& ready) {
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
    refuse_for_rate({c, s.key},
                    "rate limit: more than " + number(sh_.config.rate) + " commands a second (commands.rate, " +
                        number(sh_.config.burst) + " at once: commands.burst) from this client; send fewer");
    return;
  }
  if (!s.ready) {
    if (s.held.size() < sh_.config.queue && held_ < kHeldQueues * sh_.config.queue) {
      s.held.push_back({c, s.key});
      ++held_;
      return;
    }
    refuse_for_rate({c, s.key}, s.held.size() >= sh_.config.queue
                                    ? "rate limit: " + std::to_string(sh_.config.queue) +
                                          " commands of this client are already waiting (commands.queue); send fewer"
                                    : "rate limit: this server already holds " + std::to_string(held_) +
                                          " commands of clients whose answer readers it has not found; send them "
                                          "again once your client hears answers");
    return;
  }
  ready.push_back({c, s.key});
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

// The sender of a command from `writer`: the client of the writer's participant, known or new (a writer that had
// left before its first command was read is a client of its own). A new one is checked at once: usually it is ready.
Io::Sender& Io::sender(dds_instance_handle_t writer, const ladder_msg_Command& c, Clock::time_point now) {
  if (const auto known = writer_sender_.find(writer); known != writer_sender_.end())
    return senders_.at(known->second);
  if (writer_sender_.size() >= forget_above_) forget_departed_senders();
  const std::optional<dds_guid_t> participant = transport::writer_participant(command_r_.entity(), writer);
  SenderKey key = next_sender_;
  if (participant) {
    std::array<std::uint8_t, 16> guid;
    std::copy(std::begin(participant->v), std::end(participant->v), guid.begin());
    key = participant_sender_.try_emplace(guid, next_sender_).first->second;
  }
  if (key == next_sender_) ++next_sender_;
  writer_sender_.emplace(writer, key);
  const auto [it, fresh] = senders_.try_emplace(key, key, sh_.config, now);
  Sender& s = it->second;
  if (!fresh) return s;  // another writer of a client already known
  s.client = transport::printable(text_of(c.client_id));  // (for the log lines)
  s.participant = participant;
  check(s, now);
  if (!s.ready) {
    waiting_.push_back(key);
    spdlog::debug("client '{}': its commands wait until its ack and event readers are found", s.client);
  }
  return s;
}

void Io::check(Sender& s, Clock::time_point now) {
  constexpr double kEventGrace = 0.1;  // [s]
  s.next_check = now + std::chrono::milliseconds(2);  // the lookups cost a copy per matched reader
  const bool ack = !s.participant || ack_w_.matched_in(*s.participant);
  if (ack && !s.ack_reader_found) s.ack_reader_found = now;
  const bool events = ack && (!s.participant || event_w_.matched_in(*s.participant));  // (looked up once ack is)
  s.ready = ack && (events || seconds(now - *s.ack_reader_found) >= std::min(kEventGrace, sh_.config.reader_wait));
  const double waited = seconds(now - s.first_seen);
  if (s.ready) {
    if (!events)
      spdlog::debug("client '{}': no event reader {:.0f} ms after its ack reader was found; its commands go on (it "
                    "hears their answers, not the events)",
                    s.client, 1e3 * seconds(now - *s.ack_reader_found));
    else if (waited > 0)
      spdlog::debug("client '{}': its readers found after {:.0f} ms", s.client, 1e3 * waited);
  } else if (waited >= sh_.config.reader_wait) {
    s.ready = true;
    if (std::uint64_t held_back = 0; slow_readers_log_.allow(now, held_back))
      spdlog::warn("client '{}': its ack reader not found in {:g} s; its commands go on, and it may miss their "
                   "answers{}",
                   s.client, sh_.config.reader_wait,
                   held_back == 0 ? std::string()
                                  : " (and " + std::to_string(held_back) + " more clients since the last such line)");
  }
}

// Moves the commands of the senders that have become ready to `ready`, in their order.
void Io::release_answerable(std::vector<Incoming>& ready) {
  const Clock::time_point now = Clock::now();
  std::erase_if(waiting_, [&](SenderKey key) {
    Sender& s = senders_.at(key);
    if (now < s.next_check) return false;
    check(s, now);
    if (!s.ready) return false;
    ready.insert(ready.end(), s.held.begin(), s.held.end());
    held_ -= s.held.size();
    s.held.clear();
    return true;
  });
}

// Forgets the command writers that have left (each ladderctl run is one), and the clients that have none left,
// keeping those still waiting.
void Io::forget_departed_senders() {
  std::vector<dds_instance_handle_t> matched = transport::matched_writers(command_r_.entity());
  std::sort(matched.begin(), matched.end());
  std::erase_if(writer_sender_,
                [&](const auto& w) { return !std::binary_search(matched.begin(), matched.end(), w.first); });
  std::vector<SenderKey> keep(waiting_);
  for (const auto& [writer, key] : writer_sender_) keep.push_back(key);
  std::sort(keep.begin(), keep.end());
  const auto kept = [&](SenderKey key) { return std::binary_search(keep.begin(), keep.end(), key); };
  std::erase_if(senders_, [&](const auto& s) { return !kept(s.first); });
  std::erase_if(participant_sender_, [&](const auto& p) { return !kept(p.second); });
  forget_above_ = std::max<std::size_t>(256, 2 * writer_sender_.size());
  // (A waiting sender is kept with its held commands whether its writers are there or not: they go on at its wait's
  // end, and held_ counts them.)
}

// At the stop: the commands the physics thread did not take, and those still held, are refused. (A sender still
// held may not hear it.)
void Io::refuse_leftovers() {
  std::vector<Incoming> left;
  {
    std::lock_guard lock(sh_.inbox_mutex);
    left = sh_.inbox.drain();
  }
  for (SenderKey key : waiting_) {
    std::deque<Incoming>& held = senders_.at(key).held;
    left.insert(left.end(), held.begin(), held.end());
    held.clear();
  }
  held_ = 0;
  for (const Incoming& in : left) refuse(in.command, "ladderd stopped before it could take this command");
}

void Io::write_scene(const SceneOut& s) {
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
  scene_written_ = Clock::now();
}

void Io::write_outbox() {
  {
    std::lock_guard lock(sh_.outbox_mutex);
    std::swap(out_, sh_.outbox);
  }
  for (const SceneOut& s : out_.scenes) write_scene(s);
  if (!out_.scenes.empty()) {
    scene_ = out_.scenes.back();
  } else if (scene_ && Clock::now() - scene_written_ >= kSceneRepeat) {
    write_scene(*scene_);  // the same again (see io.hpp)
  }
  // A command is in the log, flushed to the file, before its ack goes out: an acknowledged command survives a
  // kill -9 (--resume replays it).
  if (recorder_) recorder_->record(out_);
  if (log_ && !out_.commands.empty() && !log_->sync(std::chrono::seconds(5)) && log_->failed_syncs() == 1)
    spdlog::error("session log {}: writing it failed or took over 5 s; until it catches up, commands are "
                  "acknowledged before they are in it (said once)", transport::printable(log_->path()));
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
  tick_log_.write(out_.ticks);
  out_.clear();
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
  if (recorder_) recorder_->record_state(*f, m.seq);
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

}  // namespace ladder::daemon
