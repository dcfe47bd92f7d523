#include "client.hpp"

#include "transport/default_config.hpp"

#include <unistd.h>

#include <stdexcept>

namespace ladder::client {

using transport::copy_text;
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
}  // namespace

Client::Client(int domain, std::string sim_id, std::string client_id)
    : sim_id_(std::move(sim_id)),
      client_id_(client_id.empty() ? default_client_id() : std::move(client_id)),
      participant_((transport::use_default_config(transport::kDefaultCycloneConfig),
                    transport::make_participant(static_cast<dds_domainid_t>(domain)))),
      topics_(participant_),
      command_w_(participant_, topics_.command, transport::Profile::Command),
      ack_r_(participant_, topics_.ack, transport::Profile::CommandAck),
      state_r_(participant_, topics_.state, transport::Profile::State),
      scene_r_(participant_, topics_.scene_info, transport::Profile::SceneInfo),
      event_r_(participant_, topics_.event, transport::Profile::Event),
      stats_r_(participant_, topics_.stats, transport::Profile::Stats),
      waiter_(participant_) {
  for (const transport::Entity* r : {&ack_r_.entity(), &state_r_.entity(), &scene_r_.entity(), &event_r_.entity(),
                                     &stats_r_.entity()})
    waiter_.attach(*r);
}

void Client::poll() {
  ack_r_.take([&](const ladder_msg_CommandAck& a, const dds_sample_info_t&) {
    if (text_of(a.sim_id) != sim_id_ || text_of(a.client_id) != client_id_) return;
    acks_[a.command_id] = {a.command_id, a.accepted, text_of(a.reason), a.sim_time, a.step, a.command_seq};
    ++acks_received_;
  });
  state_r_.take([&](const ladder_msg_State& s, const dds_sample_info_t& info) {
    if (text_of(s.sim_id) != sim_id_) return;
    // One pose (three numbers) and one hinge per block; a state whose sequences disagree is not drawable.
    const std::size_t n = s.hinge_corner._length;
    if (s.poses._length != 3 * n || s.hinge_status._length != n || s.hinge_flips._length != n) {
      ++states_malformed_;
      return;
    }
    if (info.publication_handle != server_writer_) {  // the first state, or a restarted server's
      if (const auto p = transport::writer_participant(state_r_.entity(), info.publication_handle)) {
        server_ = p;
        server_writer_ = info.publication_handle;
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
  scene_r_.take([&](const ladder_msg_SceneInfo& s, const dds_sample_info_t&) {
    if (text_of(s.sim_id) != sim_id_) return;
    SceneInfo& si = scene_.emplace();
    si.generation = s.generation;
    si.scene_name = text_of(s.scene_name);
    si.description = text_of(s.description);
    si.server_version = text_of(s.server_version);
    si.replay = s.replay;
    si.top = text_of(s.top);
    si.options = text_of(s.options);
    si.blocks = s.blocks;
    si.length = s.length;
    si.thickness = s.thickness;
    si.hinge_inset = s.hinge_inset;
    si.dt = s.dt;
    si.physics_rate = s.physics_rate;
    si.publish_rate = s.publish_rate;
    si.real_time_factor = s.real_time_factor;
    si.masses.assign(s.masses._buffer, s.masses._buffer + s.masses._length);
  });
  event_r_.take([&](const ladder_msg_Event& e, const dds_sample_info_t&) {
    if (text_of(e.sim_id) != sim_id_) return;
    events_.push_back({e.seq, e.t, text_of(e.kind), e.hinge, e.energy_removed, text_of(e.detail)});
  });
  stats_r_.take([&](const ladder_msg_Stats& s, const dds_sample_info_t&) {
    if (text_of(s.sim_id) != sim_id_) return;
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

bool Client::connected() {
  if (!state_ || !scene_) return false;
  if (scene_->replay) return true;  // a replay (ladderctl replay) publishes but takes no commands
  if (!server_) return false;
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
  const std::uint64_t id = next_id_++;
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
