#include "directory.hpp"
#include "client.hpp"

#include "transport/default_config.hpp"
#include "transport/dds.hpp"
#include "transport/topics.hpp"

#include <chrono>
#include <cstring>
#include <map>
#include <set>
#include <string>
#include <thread>

namespace ladder::client {

namespace {

using Guid = std::string;  // a participant's GUID as bytes
Guid key_of(const dds_guid_t& g) { return Guid(reinterpret_cast<const char*>(g.v), sizeof g.v); }

// What has come of one ladder so far.
struct Ladder {
  std::string scene, server_version;
  std::uint32_t blocks = 0;
  bool replay = false;
  double rtf = -1;  // measured; < 0: no Stats yet
  Guid participant;
};

// What DDS discovery says of each participant: its host (Cyclone's "__Hostname" property) and whether it reads
// ladder/State (a viewer, or any other client that watches a ladder).
struct Participants {
  std::map<Guid, std::string> host;
  std::set<Guid> state_readers;
};

// Reads (without taking: each pass sees them all again) up to 256 samples of a built-in topic, on the reader's
// loan, and passes each valid one to f.
template <class T, class F>
void read_builtin(const transport::Entity& reader, F&& f) {
  constexpr int kMax = 256;
  void* buf[kMax] = {};  // buf[0] null: Cyclone lends its own memory
  dds_sample_info_t info[kMax];
  const dds_return_t n = dds_read(reader.get(), buf, info, kMax, kMax);
  for (dds_return_t i = 0; i < n; ++i)
    if (info[i].valid_data) f(*static_cast<const T*>(buf[i]));
  if (n > 0) dds_return_loan(reader.get(), buf, n);
}

void read_builtins(const transport::Entity& participants, const transport::Entity& subscriptions, Participants& out) {
  read_builtin<dds_builtintopic_participant_t>(participants, [&](const dds_builtintopic_participant_t& p) {
    char* host = nullptr;
    if (p.qos && dds_qget_prop(p.qos, "__Hostname", &host) && host) {
      out.host[key_of(p.key)] = host;
      dds_free(host);
    }
  });
  read_builtin<dds_builtintopic_endpoint_t>(subscriptions, [&](const dds_builtintopic_endpoint_t& s) {
    if (s.topic_name && std::strcmp(s.topic_name, "ladder/State") == 0)
      out.state_readers.insert(key_of(s.participant_key));
  });
}

}  // namespace

Directory discover(int domain, double seconds) {
  transport::use_default_config(transport::kDefaultCycloneConfig);
  route_cyclone_log();
  const transport::Entity participant = transport::make_participant(static_cast<dds_domainid_t>(domain));
  const transport::Topics topics(participant, false);
  const transport::Reader<ladder_msg_SceneInfo> scenes(participant, topics.scene_info, transport::Profile::SceneInfo);
  const transport::Reader<ladder_msg_Stats> stats(participant, topics.stats, transport::Profile::Stats);
  const transport::Entity builtin_participants(
      transport::check(dds_create_reader(participant.get(), DDS_BUILTIN_TOPIC_DCPSPARTICIPANT, nullptr, nullptr),
                       "read participants"));
  const transport::Entity builtin_subscriptions(
      transport::check(dds_create_reader(participant.get(), DDS_BUILTIN_TOPIC_DCPSSUBSCRIPTION, nullptr, nullptr),
                       "read subscriptions"));
  std::map<std::string, Ladder> ladders;  // by sim id
  Participants seen;
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  while (std::chrono::steady_clock::now() < end) {
    scenes.take([&](const ladder_msg_SceneInfo& s, const dds_sample_info_t& info) {
      Ladder& l = ladders[transport::text_of(s.sim_id)];
      l.scene = transport::text_of(s.scene_name);
      l.server_version = transport::text_of(s.server_version);
      l.blocks = s.blocks;
      l.replay = s.replay;
      if (const auto p = transport::writer_participant(scenes.entity(), info.publication_handle))
        l.participant = key_of(*p);
    });
    stats.take([&](const ladder_msg_Stats& s, const dds_sample_info_t&) {
      if (const auto it = ladders.find(transport::text_of(s.sim_id)); it != ladders.end())
        it->second.rtf = s.real_time_factor;
    });
    read_builtins(builtin_participants, builtin_subscriptions, seen);
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  Directory out;
  std::set<Guid> servers;
  for (const auto& [id, l] : ladders) {
    servers.insert(l.participant);
    const auto h = seen.host.find(l.participant);
    // (Every text from a peer, the sim id and the host included, made printable: transport::printable.)
    out.ladders.push_back({transport::printable(id), h == seen.host.end() ? "?" : transport::printable(h->second),
                           transport::printable(l.scene), transport::printable(l.server_version), l.blocks, l.replay,
                           l.rtf});
  }
  dds_guid_t own{};
  dds_get_guid(participant.get(), &own);
  servers.insert(key_of(own));  // this listing reads states too
  for (const Guid& g : seen.state_readers) out.clients += servers.count(g) == 0;
  return out;
}

}  // namespace ladder::client
