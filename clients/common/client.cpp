#include "client.hpp"

#include "ladder/limits.hpp"
#include "transport/default_config.hpp"

#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <mutex>
#include <stdexcept>

namespace ladder::client {

using transport::copy_text;
using transport::printable;
using transport::text_of;
using Clock = std::chrono::steady_clock;

namespace cmd {

ladder_msg_Command make(ladder_msg_CommandKind kind) {
  ladder_msg_Command c{};
  c.kind = kind;
  c.block = -1;
  c.hinge = -1;
  return c;
}
ladder_msg_Command tip() { return make(ladder_msg_TIP); }
ladder_msg_Command poke(int block, double jx, double jy) {
  ladder_msg_Command c = make(ladder_msg_POKE);
  c.block = block;
  c.a = jx;
  c.b = jy;
  return c;
}
ladder_msg_Command poke_at(int block, double jx, double jy, double px, double py) {
  ladder_msg_Command c = poke(block, jx, jy);
  c.has_point = true;
  c.c = px;
  c.d = py;
  return c;
}
ladder_msg_Command push(int block, double fx, double fy, double duration) {
  ladder_msg_Command c = make(ladder_msg_PUSH);
  c.block = block;
  c.a = fx;
  c.b = fy;
  c.e = duration;
  return c;
}
ladder_msg_Command push_at(int block, double fx, double fy, double duration, double lx, double ly) {
  ladder_msg_Command c = push(block, fx, fy, duration);
  c.has_point = true;
  c.c = lx;
  c.d = ly;
  return c;
}
ladder_msg_Command grab(int block) {
  ladder_msg_Command c = make(ladder_msg_GRAB);
  c.block = block;
  return c;
}
ladder_msg_Command grab_to(int block, double tx, double ty) {
  ladder_msg_Command c = grab(block);
  c.has_target = true;
  c.a = tx;
  c.b = ty;
  return c;
}
ladder_msg_Command drag(int block, double tx, double ty) {
  ladder_msg_Command c = make(ladder_msg_DRAG);
  c.block = block;
  c.has_target = true;
  c.a = tx;
  c.b = ty;
  return c;
}
ladder_msg_Command drag_pose(int block, double tx, double ty, double angle) {
  ladder_msg_Command c = drag(block, tx, ty);
  c.has_angle = true;
  c.f = angle;
  return c;
}
ladder_msg_Command release(int block) {
  ladder_msg_Command c = make(ladder_msg_RELEASE);
  c.block = block;
  return c;
}
ladder_msg_Command break_hinge(int hinge) {
  ladder_msg_Command c = make(ladder_msg_BREAK_HINGE);
  c.hinge = hinge;
  return c;
}
ladder_msg_Command join_hinge(int hinge) {
  ladder_msg_Command c = make(ladder_msg_JOIN_HINGE);
  c.hinge = hinge;
  return c;
}
ladder_msg_Command pause() { return make(ladder_msg_PAUSE); }
ladder_msg_Command resume() { return make(ladder_msg_RESUME); }
ladder_msg_Command step(std::uint32_t count) {
  ladder_msg_Command c = make(ladder_msg_STEP);
  c.count = count;
  return c;
}
ladder_msg_Command reset() { return make(ladder_msg_RESET); }
ladder_msg_Command set(const std::string& key_value) {
  ladder_msg_Command c = make(ladder_msg_SET_PARAM);
  copy_text(c.text, key_value);
  return c;
}
ladder_msg_Command load(const std::string& scene) {
  ladder_msg_Command c = make(ladder_msg_LOAD_SCENE);
  copy_text(c.text, scene);
  return c;
}

}  // namespace cmd

namespace {
std::string default_client_id() {
  char host[64] = {};
  gethostname(host, sizeof host - 1);
  return std::string(host) + "-" + std::to_string(getpid());
}

// The topics of a participant; when DDS Security does not let it publish commands (a viewer: its permissions grant
// neither ladder/Command nor ladder/CommandAck, and Cyclone refuses even to create those topics), the topics
// without those two, and `denied` says so.
transport::Topics topics_for(const transport::Entity& participant, std::string& denied) {
  try {
    return transport::Topics(participant);
  } catch (const transport::DdsError& e) {
    if (e.code() != DDS_RETCODE_NOT_ALLOWED_BY_SECURITY) throw;
    denied = "permission denied: this identity's DDS Security permissions do not allow publishing ladder/Command "
             "(a viewer's; commands need a controller identity)";
    return transport::Topics(participant, false);
  }
}

template <class T>
T if_topic(const transport::Entity& participant, const transport::Entity& topic, transport::Profile p) {
  return topic ? T(participant, topic, p) : T();
}

constexpr std::size_t kMaxScenes = 16, kMaxEarlyEvents = 1024, kMaxOwners = 4096, kMaxCandidates = 8;

}  // namespace

namespace {
// Cyclone's own warnings and errors, on standard error: three in ten seconds at most, then how many were not shown,
// each made printable. (A sample Cyclone cannot decode, from a publisher built from another ladder.idl, is a line
// each: 33 a second reached a viewer's terminal from one such peer.)
void cyclone_line(const char* message) {
  static std::mutex mutex;
  static transport::LineLimiter limiter(3, std::chrono::seconds(10));
  std::lock_guard lock(mutex);
  bool shown = false;
  if (const std::uint64_t hidden = limiter.admit(Clock::now(), shown))
    std::fprintf(stderr, "cyclone: %llu more lines not shown\n", static_cast<unsigned long long>(hidden));
  if (shown) std::fprintf(stderr, "cyclone: %s\n", printable(message).c_str());
}
}  // namespace

void route_cyclone_log() { transport::route_cyclone_log(cyclone_line, "ladder/State"); }

std::string unwritable(const std::string& path) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (fs::is_directory(path, ec)) return "it is a folder";
  const fs::path parent = fs::path(path).parent_path();
  const std::string dir = parent.empty() ? "." : parent.string();
  if (!fs::is_directory(dir, ec)) return "no folder '" + dir + "'";
  if (access(dir.c_str(), W_OK) != 0) return std::string(std::strerror(errno)) + " (folder '" + dir + "')";
  return {};
}

std::string fixed(double v, int decimals) {
  char buf[40];
  if (std::abs(v) < 1e9) std::snprintf(buf, sizeof buf, "%.*f", std::clamp(decimals, 0, 9), v);
  else std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

Client::Client(int domain, std::string sim_id, std::string client_id, const transport::Identity* identity)
    : sim_id_(std::move(sim_id)),
      client_id_(client_id.empty() ? default_client_id() : std::move(client_id)),
      participant_((transport::use_default_config(transport::kDefaultCycloneConfig), route_cyclone_log(),
                    transport::make_participant(static_cast<dds_domainid_t>(domain), identity))),
      topics_(topics_for(participant_, denied_)),
      command_w_(if_topic<transport::Writer<ladder_msg_Command>>(participant_, topics_.command,
                                                                  transport::Profile::Command)),
      ack_r_(if_topic<transport::Reader<ladder_msg_CommandAck>>(participant_, topics_.ack,
                                                                 transport::Profile::CommandAck)),
      state_r_(participant_, topics_.state, transport::Profile::State),
      scene_r_(participant_, topics_.scene_info, transport::Profile::SceneInfo),
      event_r_(participant_, topics_.event, transport::Profile::Event),
      stats_r_(participant_, topics_.stats, transport::Profile::Stats),
      waiter_(participant_) {
  for (const transport::Entity* r : {&ack_r_.entity(), &state_r_.entity(), &scene_r_.entity(), &event_r_.entity(),
                                     &stats_r_.entity()})
    if (*r) waiter_.attach(*r);
  domain_ = domain;
}

std::string Client::no_server(double timeout_s) const {
  char t[32];
  std::snprintf(t, sizeof t, "%g", timeout_s);
  std::string text = "no ladderd with sim id '" + sim_id_ + "' on DDS domain " + std::to_string(domain_) + " after " +
                     t + " s; ";
  if (other_sim_ids_.empty()) return text + "is it running, and is CYCLONEDDS_URI the same on both sides?";
  text += other_sim_ids_.size() == 1 ? "the ladder there is" : "the ladders there are";
  const char* sep = " ";
  for (const std::string& id : other_sim_ids_) text += std::exchange(sep, ", ") + ("'" + id + "'");
  return text + " (choose one with --sim-id)";
}

std::optional<Client::Key> Client::owner(const transport::Entity& reader, dds_instance_handle_t writer) {
  if (const auto it = owners_.find(writer); it != owners_.end()) return it->second;
  const auto p = transport::writer_participant(reader, writer);
  if (!p) return std::nullopt;
  if (owners_.size() >= kMaxOwners) owners_.clear();  // many short-lived writers: start again
  return owners_.emplace(writer, key_of(*p)).first->second;
}

bool Client::from_server(const transport::Entity& reader, dds_instance_handle_t writer) {
  if (!server_) return false;
  const auto o = owner(reader, writer);
  return o && *o == key_of(*server_);
}

// The server is the participant of a State's writer that connected() has confirmed: it also reads our commands and
// writes acks and events to us. Until then the latest State's writer is the candidate (so that a participant that
// only publishes States cannot keep us from finding the server). Once confirmed, another participant's States are
// taken only when the server's writer is gone (a restarted server has a new participant); else they are forgeries.
void Client::take_states() {
  state_r_.take([&](const ladder_msg_State& s, const dds_sample_info_t& info) {
    if (text_of(s.sim_id) != sim_id_) return;
    // One pose (three numbers) and one hinge per block, every number finite, the sim time not negative, at most one
    // grip a block: a state that is not so was not written by a ladderd (which never publishes a non-finite number)
    // and is not drawable.
    const std::size_t n = s.hinge_corner._length;
    const auto finite = [](double v) { return std::isfinite(v); };
    if (s.poses._length != 3 * n || s.hinge_status._length != n || s.hinge_flips._length != n ||
        s.grips._length > n || !(s.sim_time >= 0 && finite(s.sim_time) && finite(s.energy)) ||
        !std::all_of(s.poses._buffer, s.poses._buffer + s.poses._length, finite) ||
        !std::all_of(s.grips._buffer, s.grips._buffer + s.grips._length, [&](const ladder_msg_Grip& g) {
          return finite(g.target_x) && finite(g.target_y) && finite(g.angle);
        })) {
      ++states_malformed_;
      return;
    }
    if (info.publication_handle != server_writer_) {  // the first state, a restarted server's, or a forger's
      if (from_server(state_r_.entity(), info.publication_handle)) {
        server_writer_ = info.publication_handle;  // the same server, another writer
      } else if (confirmed_ && transport::writer_participant(state_r_.entity(), server_writer_)) {
        ++forged_;  // our server's writer is still there: this is someone else's
        return;
      } else if (const auto p = transport::writer_participant(state_r_.entity(), info.publication_handle)) {
        if (server_ && state_ && key_of(*server_) != key_of(*p)) {
          candidate_states_[key_of(*server_)] = std::move(*state_);  // kept for connected()
          state_.reset();
          if (const auto back = candidate_states_.find(key_of(*p)); back != candidate_states_.end()) {
            state_ = std::move(back->second);  // its storage is reused below
            candidate_states_.erase(back);
          }
        }
        server_ = p;
        server_writer_ = info.publication_handle;
        confirmed_ = false;
        const Key k = key_of(*p);
        const auto seen = std::find_if(candidates_.begin(), candidates_.end(),
                                       [&](const auto& c) { return key_of(c.first) == k; });
        if (seen != candidates_.end()) candidates_.erase(seen);
        if (candidates_.size() >= kMaxCandidates) {
          candidate_states_.erase(key_of(candidates_.front().first));
          candidates_.erase(candidates_.begin());
        }
        candidates_.emplace_back(*p, info.publication_handle);
        if (const auto it = scenes_.find(k); it != scenes_.end()) scene_ = it->second;
        else scene_.reset();  // the previous server's does not describe this one
        for (auto& [who, e] : early_events_)
          if (who == k) events_.push_back(std::move(e));
        early_events_.clear();
      } else {
        return;  // its writer is gone already
      }
    }
    State& st = state_ ? *state_ : state_.emplace();  // reuses the vectors' storage
    st.latency = 1e-9 * static_cast<double>(dds_time() - info.source_timestamp);
    st.generation = s.generation;
    st.seq = s.seq;
    st.step = s.step;
    st.commands_applied = s.commands_applied;
    st.sim_time = s.sim_time;
    st.energy = s.energy;
    st.paused = s.paused;
    st.blocks.resize(n);
    st.hinges.resize(n);
    const double* p = s.poses._buffer;
    for (std::size_t k = 0; k < n; ++k) {
      st.blocks[k] = {p[3 * k], p[3 * k + 1], p[3 * k + 2]};
      st.hinges[k] = {s.hinge_corner._buffer[k], s.hinge_status._buffer[k], s.hinge_flips._buffer[k]};
    }
    st.grips.assign(s.grips._buffer, s.grips._buffer + s.grips._length);
    ++state_count_;
  });
}

// Only the server's samples count (from_server); the others are counted in forged_ and dropped, so that another
// participant on the domain cannot answer our commands or be drawn as our ladder.
void Client::poll() {
  take_states();  // first: they say which participant is the server
  if (ack_r_.entity()) {
    ack_r_.take([&](const ladder_msg_CommandAck& a, const dds_sample_info_t& info) {
      if (text_of(a.sim_id) != sim_id_ || text_of(a.client_id) != client_id_) return;
      if (!from_server(ack_r_.entity(), info.publication_handle)) {
        ++forged_;
        return;
      }
      acks_[a.command_id] = {a.command_id, a.accepted, printable(text_of(a.reason), false), a.sim_time, a.step,
                             a.command_seq};
      ++acks_received_;
    });
  }
  scene_r_.take([&](const ladder_msg_SceneInfo& s, const dds_sample_info_t& info) {
    if (text_of(s.sim_id) != sim_id_) {
      if (other_sim_ids_.size() < kMaxOtherSimIds) other_sim_ids_.insert(printable(text_of(s.sim_id)));
      return;
    }
    const auto who = owner(scene_r_.entity(), info.publication_handle);
    if (!who) return;
    const bool ours = server_ && *who == key_of(*server_);
    if (server_ && !ours) ++forged_;  // kept aside all the same: it may be a restarted server's, before its State
    if (!scenes_.count(*who) && scenes_.size() >= kMaxScenes) scenes_.erase(scenes_.begin());
    SceneInfo& si = scenes_[*who];
    si.generation = s.generation;
    si.scene_name = printable(text_of(s.scene_name));
    si.description = printable(text_of(s.description));
    si.server_version = printable(text_of(s.server_version));
    si.replay = s.replay;
    si.top = printable(text_of(s.top));
    si.options = printable_lines(text_of(s.options));
    // The masses only as a ladderd sends them, one a block and no more blocks than a scene may have: a peer's
    // sequence is as long as it likes, and a copy of it is kept for each of kMaxScenes participants.
    if (s.masses._length == s.blocks && s.blocks <= static_cast<std::uint32_t>(kMaxBlocks))
      si.masses.assign(s.masses._buffer, s.masses._buffer + s.masses._length);
    else
      si.masses.clear();
    si.blocks = s.blocks;
    si.length = s.length;
    si.thickness = s.thickness;
    si.hinge_inset = s.hinge_inset;
    si.dt = s.dt;
    si.physics_rate = s.physics_rate;
    si.publish_rate = s.publish_rate;
    si.real_time_factor = s.real_time_factor;
    if (ours) scene_ = si;
  });
  event_r_.take([&](const ladder_msg_Event& e, const dds_sample_info_t& info) {
    if (text_of(e.sim_id) != sim_id_) return;
    Event ev{e.seq, e.t, printable(text_of(e.kind)), e.hinge, e.energy_removed, printable(text_of(e.detail))};
    if (!server_) {  // the event reader can match the server before its first State comes: kept for then
      const auto who = owner(event_r_.entity(), info.publication_handle);
      if (who && early_events_.size() < kMaxEarlyEvents) early_events_.emplace_back(*who, std::move(ev));
      return;
    }
    if (!from_server(event_r_.entity(), info.publication_handle)) {
      ++forged_;
      return;
    }
    events_.push_back(std::move(ev));
  });
  stats_r_.take([&](const ladder_msg_Stats& s, const dds_sample_info_t& info) {
    if (text_of(s.sim_id) != sim_id_) return;
    if (!from_server(stats_r_.entity(), info.publication_handle)) {
      if (server_) ++forged_;
      return;
    }
    stats_ = s;
    ++stats_count_;
  });
}

bool Client::wait(Millis timeout, const std::function<bool()>& done) {
  const auto deadline = Clock::now() + timeout;
  while (true) {
    poll();
    if (done()) return true;
    const auto left = deadline - Clock::now();
    if (left <= Clock::duration::zero()) return false;
    waiter_.wait(std::min<Clock::duration>(left, Millis(50)));
  }
}

bool Client::serves_us(const dds_guid_t& p) {
  const auto scene = scenes_.find(key_of(p));
  if (scene == scenes_.end()) return false;
  if (scene->second.replay) return true;  // a replay (ladderctl replay) publishes but takes no commands
  if (!may_command()) return event_r_.matched_in(p);  // a viewer: it only reads
  return command_w_.matched_in(p) && ack_r_.matched_in(p) && event_r_.matched_in(p);
}

bool Client::connected() {
  if (!confirmed_) {
    // Every participant that sent States since the last confirmation, the latest first: the first that serves us
    // is the server. (Only the latest State's writer would do, but a participant publishing States faster than the
    // server would then hide it most of the time.)
    for (auto c = candidates_.rbegin(); c != candidates_.rend() && !confirmed_; ++c) {
      if (!serves_us(c->first)) continue;
      if (!server_ || key_of(*server_) != key_of(c->first)) {
        server_ = c->first;
        server_writer_ = c->second;
        // Its latest State, if kept; else wait for its next (state_ is another participant's).
        const auto kept = candidate_states_.find(key_of(c->first));
        if (kept != candidate_states_.end()) state_ = std::move(kept->second);
        else state_.reset();
        scene_ = scenes_.at(key_of(c->first));
      }
      confirmed_ = true;
    }
    if (!confirmed_) return false;
    candidates_.clear();
    candidate_states_.clear();
  }
  if (!state_ || !scene_) return false;
  if (scene_->replay || !may_command()) return true;
  // The lookups copy every matched endpoint's data: the answer is kept while the server and the count stay.
  const std::uint32_t readers = command_w_.matched();
  if (connected_writer_ == server_writer_ && connected_readers_ == readers) return true;
  if (!(command_w_.matched_in(*server_) && ack_r_.matched_in(*server_) && event_r_.matched_in(*server_)))
    return false;
  connected_writer_ = server_writer_;
  connected_readers_ = readers;
  return true;
}

bool Client::wait_for_server(Millis timeout) {
  return wait(timeout, [&] { return connected(); });
}

std::uint64_t Client::send(ladder_msg_Command c) {
  if (!may_command()) throw PermissionDenied(denied_);
  const std::uint64_t id = next_id_++;
  // An answer to this id that came before the command went out is not its answer: another participant sent a
  // command under this client's id (anyone on the domain may, without DDS Security), and the server answered it.
  acks_.erase(id);
  resend(c, id);
  return id;
}

void Client::resend(ladder_msg_Command c, std::uint64_t id) {
  copy_text(c.sim_id, sim_id_);
  copy_text(c.client_id, client_id_);
  c.command_id = id;
  // A write waits up to 1 s for room (commands are keep-all, so that none is lost); a server held up for longer (a
  // loaded machine) is given four more tries before the failure is the caller's.
  for (int tries = 1;; ++tries) {
    const dds_return_t rc = command_w_.try_write(c);
    if (rc >= 0) break;
    if (rc != DDS_RETCODE_TIMEOUT || tries == 5) transport::check(rc, "write a command");
  }
}

std::optional<Ack> Client::wait_ack(std::uint64_t id, Millis timeout) {
  if (!wait(timeout, [&] { return acks_.count(id) > 0; })) return std::nullopt;
  const Ack a = acks_.at(id);
  acks_.erase(id);
  return a;
}

Ack Client::call(const ladder_msg_Command& c, Millis timeout) {
  const std::uint64_t id = send(c);
  if (auto a = wait_ack(id, timeout)) return *a;
  throw std::runtime_error("no answer from ladderd '" + sim_id_ + "' to command " + std::to_string(id) + " within " +
                           std::to_string(timeout.count()) + " ms");
}

std::optional<State> Client::wait_state(const std::function<bool(const State&)>& pred, Millis timeout) {
  if (wait(timeout, [&] { return state_.has_value() && pred(*state_); })) return state_;
  return std::nullopt;
}

std::optional<SceneInfo> Client::wait_scene_info(Millis timeout, const std::function<bool(const SceneInfo&)>& pred) {
  if (wait(timeout, [&] { return scene_.has_value() && (!pred || pred(*scene_)); })) return scene_;
  return std::nullopt;
}

std::optional<ladder_msg_Stats> Client::wait_stats(const std::function<bool(const ladder_msg_Stats&)>& pred,
                                                   Millis timeout) {
  const std::uint64_t seen = stats_count_;
  if (wait(timeout, [&] { return stats_count_ > seen && pred(*stats_); })) return stats_;
  return std::nullopt;
}

std::vector<Event> Client::take_events() { return std::exchange(events_, {}); }

}  // namespace ladder::client
