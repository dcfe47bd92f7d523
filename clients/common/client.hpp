// A ladder client over DDS: sends commands to one ladderd (by sim id) and keeps what it publishes. Used by
// ladderctl, ladder-view and the integration tests. Single-threaded: every call reads DDS in the caller's thread.
#pragma once

#include "ladder.h"
#include "transport/dds.hpp"
#include "transport/security.hpp"
#include "transport/topics.hpp"

#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

namespace ladder::client {

using Millis = std::chrono::milliseconds;

struct Ack {
  std::uint64_t command_id = 0;
  bool accepted = false;
  std::string reason;
  double sim_time = 0;
  std::uint64_t step = 0;
  std::uint64_t command_seq = 0;  // a State with commands_applied >= this shows the command's effect
};

struct Event {
  std::uint64_t seq = 0;
  double t = 0;
  std::string kind;
  int hinge = 0;
  double energy_removed = 0;
  std::string detail;
};

// One block's pose: its centre [m] and angle [rad].
struct Pose {
  double x = 0, y = 0, theta = 0;
};

// Hinge k (above block k): the particle number (0..3) it joins on both blocks, its status and its flip-flops.
struct Hinge {
  std::uint8_t corner = 0;
  ladder_msg_HingeStatus status = ladder_msg_HINGED;
  std::uint32_t flips = 0;
};

struct State {
  std::uint32_t generation = 0;
  std::uint64_t seq = 0, step = 0, commands_applied = 0;
  double sim_time = 0, energy = 0;
  bool paused = false;
  std::vector<Pose> blocks;
  std::vector<Hinge> hinges;
  std::vector<ladder_msg_Grip> grips;
  double latency = 0;  // [s] from the server's write to our take (same host: one clock; across hosts: clock offset)
};

struct SceneInfo {
  std::uint32_t generation = 0;
  std::string scene_name, description, server_version, top, options;
  bool replay = false;
  std::uint32_t blocks = 0;
  double length = 0, thickness = 0, hinge_inset = 0, dt = 0;
  double physics_rate = 0, publish_rate = 0, real_time_factor = 0;
  std::vector<double> masses;  // one a block, or none (a peer's that are not: client.cpp, poll)
};

// Sends Cyclone DDS's own log lines to standard error, three every ten seconds at most (client.cpp). Every Client
// does it; a program that reads DDS without one (ladderctl list) calls it first.
void route_cyclone_log();

// A peer's number for a line of text: with `decimals` decimals, or as %g from 1e9 on (a forged sim time of 1e300
// would otherwise print 300 digits and cut the line it is in).
std::string fixed(double v, int decimals);

// Why a file could not be written at `path`, or "" when its folder takes it (checked without creating it): for an
// output named on the command line, checked before any waiting.
std::string unwritable(const std::string& path);

// Command builders: each fills the fields its kind uses.
namespace cmd {
ladder_msg_Command make(ladder_msg_CommandKind kind);
ladder_msg_Command tip();
ladder_msg_Command poke(int block, double jx, double jy);                       // at the block's centre
ladder_msg_Command poke_at(int block, double jx, double jy, double px, double py);  // at a world point
ladder_msg_Command push(int block, double fx, double fy, double duration);             // at the centre
ladder_msg_Command push_at(int block, double fx, double fy, double duration, double lx, double ly);  // block frame
ladder_msg_Command grab(int block);                                 // held where it is, by its centre
ladder_msg_Command grab_to(int block, double tx, double ty);        // centre pulled toward a world point
ladder_msg_Command drag(int block, double tx, double ty);
ladder_msg_Command drag_pose(int block, double tx, double ty, double angle);
ladder_msg_Command release(int block);
ladder_msg_Command break_hinge(int hinge);
ladder_msg_Command join_hinge(int hinge);
ladder_msg_Command pause();
ladder_msg_Command resume();
ladder_msg_Command step(std::uint32_t count);
ladder_msg_Command reset();
ladder_msg_Command set(const std::string& key_value);
ladder_msg_Command load(const std::string& scene);
}  // namespace cmd

// A command this client's DDS Security permissions do not allow (a viewer's): what() names the permission.
class PermissionDenied : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

class Client {
 public:
  // client_id: how the server's log and acks name this client; empty = "<host>-<pid>". identity: DDS Security
  // (docs/security.md); nullptr = the process's default identity (transport::set_default_identity), if any.
  Client(int domain, std::string sim_id, std::string client_id = {}, const transport::Identity* identity = nullptr);

  // Waits until the server of our sim id takes our commands and publishes to us (a replay: publishes to us); false
  // at the timeout. "Takes our commands" means matched with that server's own participant: in a domain that other
  // servers share, a match with theirs would let a first command be lost.
  bool wait_for_server(Millis timeout);
  // Sends a command (sim id, client id and a fresh command id filled in) and returns its id. Throws
  // PermissionDenied when this participant may not publish commands (see may_command).
  std::uint64_t send(ladder_msg_Command c);
  // Sends command `id` again (sim id and client id filled in): the resend after no answer, e.g. when a partition
  // longer than the DDS lease lost what was written during it. The server applies a (client id, command id) among
  // the client's last 1024 once and answers a repeat with the first ack (docs/server.md; docs/network.md, "When the
  // network fails").
  void resend(ladder_msg_Command c, std::uint64_t id);
  // Whether DDS Security lets this participant publish commands; if not, denied() says which permission it lacks.
  bool may_command() const { return static_cast<bool>(command_w_.entity()); }
  const std::string& denied() const { return denied_; }
  // The ack of command `id`, waiting up to `timeout`.
  std::optional<Ack> wait_ack(std::uint64_t id, Millis timeout);
  // send + wait_ack; throws std::runtime_error at the timeout.
  Ack call(const ladder_msg_Command& c, Millis timeout = Millis(5000));

  // Waits until the latest State (already received or new) satisfies pred, and returns it. For "a newer state than
  // X", put that in pred (e.g. st.seq > x.seq).
  std::optional<State> wait_state(const std::function<bool(const State&)>& pred, Millis timeout);
  // The latest SceneInfo once there is one (that satisfies `pred`, when given).
  std::optional<SceneInfo> wait_scene_info(Millis timeout, const std::function<bool(const SceneInfo&)>& pred = {});
  std::optional<ladder_msg_Stats> wait_stats(const std::function<bool(const ladder_msg_Stats&)>& pred, Millis timeout);
  // Reads what has arrived, without waiting.
  void poll();
  // Events received so far, in order (moved out).
  std::vector<Event> take_events();
  const std::optional<State>& latest_state() const { return state_; }
  const std::optional<SceneInfo>& scene_info() const { return scene_; }
  // The latest Stats and how many have been received (each covers the server's last window of about a second).
  const std::optional<ladder_msg_Stats>& latest_stats() const { return stats_; }
  std::uint64_t stats_received() const { return stats_count_; }
  std::size_t acks_received() const { return acks_received_; }
  // States dropped as not a ladderd's: their sequences disagree (not one pose and one hinge per block), a number (a
  // pose, the energy, the sim time, a grip's target or angle) is not finite, the sim time is negative, or there are
  // more grips than blocks.
  std::uint64_t states_malformed() const { return states_malformed_; }
  const std::string& client_id() const { return client_id_; }
  // Samples (acks, states, scene infos, events, stats) ignored because their writer is not in the participant of
  // the server this client found: another program publishing under the server's topics (docs/security.md).
  std::uint64_t forged() const { return forged_; }
  // The sim ids of the other ladders whose SceneInfo came (at most kMaxOtherSimIds, made printable): what a user who
  // mistyped --sim-id meant.
  const std::set<std::string>& other_sim_ids() const { return other_sim_ids_; }
  static constexpr std::size_t kMaxOtherSimIds = 8;
  // "no ladderd with sim id 'ID' on DDS domain N after T s; ..." and what may be wrong: the ladders that are there
  // (other_sim_ids()), or else the DDS configuration.
  std::string no_server(double timeout_s) const;

 private:
  using Key = std::string;  // a participant's GUID as bytes
  static Key key_of(const dds_guid_t& g) { return Key(reinterpret_cast<const char*>(g.v), sizeof g.v); }
  // The participant of the writer of a sample `reader` took, cached per writer; nullopt when it is no longer known.
  std::optional<Key> owner(const transport::Entity& reader, dds_instance_handle_t writer);
  // Whether that writer is in the server's participant.
  bool from_server(const transport::Entity& reader, dds_instance_handle_t writer);
  void take_states();
  bool wait(Millis timeout, const std::function<bool()>& done);
  bool connected();
  bool serves_us(const dds_guid_t& participant);  // it sent a SceneInfo and reads our commands and answers us

  std::string sim_id_, client_id_;
  std::string denied_;  // declared before topics_, whose initialisation (topics_for) sets it
  transport::Entity participant_;
  transport::Topics topics_;
  transport::Writer<ladder_msg_Command> command_w_;
  transport::Reader<ladder_msg_CommandAck> ack_r_;
  transport::Reader<ladder_msg_State> state_r_;
  transport::Reader<ladder_msg_SceneInfo> scene_r_;
  transport::Reader<ladder_msg_Event> event_r_;
  transport::Reader<ladder_msg_Stats> stats_r_;
  transport::Waiter waiter_;
  std::uint64_t next_id_ = 1;
  std::map<std::uint64_t, Ack> acks_;
  std::size_t acks_received_ = 0;
  std::vector<Event> events_;
  std::optional<State> state_;
  // The participant of the writer of our latest State (the server's), and that writer.
  std::optional<dds_guid_t> server_;
  dds_instance_handle_t server_writer_ = 0;
  bool confirmed_ = false;  // connected() found server_ to be a server (see take_states)
  // Until then, the participants (and their State writers) that may be the server, the latest last.
  std::vector<std::pair<dds_guid_t, dds_instance_handle_t>> candidates_;
  // And the latest State of each candidate but the latest (whose is state_): a paused server writes no new State, so
  // the one it sent must be kept when another participant's States come after it.
  std::map<Key, State> candidate_states_;
  // connected() said yes for this server's writer while the command writer had this many readers.
  dds_instance_handle_t connected_writer_ = 0;
  std::uint32_t connected_readers_ = 0;
  std::uint64_t state_count_ = 0;
  std::uint64_t states_malformed_ = 0;
  std::optional<SceneInfo> scene_;
  // The latest SceneInfo of each participant that sent one (a few): the server's may come before its first State.
  std::map<Key, SceneInfo> scenes_;
  std::vector<std::pair<Key, Event>> early_events_;  // events that came before the server was known (bounded)
  std::map<dds_instance_handle_t, Key> owners_;       // writer -> its participant (owner())
  std::uint64_t forged_ = 0;
  std::set<std::string> other_sim_ids_;
  int domain_ = 0;
  std::optional<ladder_msg_Stats> stats_;
  std::uint64_t stats_count_ = 0;
};

}  // namespace ladder::client
