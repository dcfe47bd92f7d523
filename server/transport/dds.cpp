#include "transport/dds.hpp"

#include "transport/security.hpp"

#include <algorithm>
#include <atomic>
#include <cstdlib>
#include <cstring>
#include <string>
#include <utility>

namespace ladder::transport {

void use_default_config(const std::string& xml) {
  // setenv with overwrite = 0 keeps a user's CYCLONEDDS_URI. Cyclone reads it when the first entity is created.
  setenv("CYCLONEDDS_URI", xml.c_str(), 0);
}

namespace {

struct CycloneLog {
  void (*sink)(const char*) = nullptr;
  std::string topic;  // whose undecodable samples are counted
  std::atomic<std::uint64_t> undecodable{0};
};
CycloneLog g_cyclone_log;
// Cyclone's last error line on this thread, for a message of ours that says why a call failed. Per thread: an entity
// is made on the caller's thread, which logs its errors, and two threads making entities at once (a server's
// threads, a test's clients) must not read each other's reasons.
thread_local std::string t_last_error;

// Cyclone calls this for its info, warning, error and fatal messages, from its own threads. A sample it cannot
// deserialize it drops with "deserialization TOPIC/TYPE failed": that is the only trace such a sample leaves.
// d->message is the text alone: Cyclone's header (time, domain, thread; d->hdrsize bytes) sits in front of it, where
// its own default sink starts writing (ddsrt/src/log.c). Skipping hdrsize into the message cut the first ~40
// characters of every line ("cyclone:  address" for "add_peer_addresses: ladderd: unknown address").
void on_cyclone_log(void*, const dds_log_data_t* d) {
  std::string line(d->message, d->size);
  while (!line.empty() && (line.back() == '\n' || line.back() == ' ')) line.pop_back();
  if (line.find("deserialization " + g_cyclone_log.topic + "/") != std::string::npos)
    g_cyclone_log.undecodable.fetch_add(1, std::memory_order_relaxed);
  if ((d->priority & (DDS_LC_ERROR | DDS_LC_FATAL)) != 0 && !line.empty()) t_last_error = line;
  if (g_cyclone_log.sink != nullptr && !line.empty()) g_cyclone_log.sink(line.c_str());
}

std::string take_last_error() {
  return std::exchange(t_last_error, {});
}

// Why a participant could not be made, from Cyclone's error line when its log comes here (route_cyclone_log).
std::string participant_failure(dds_domainid_t domain, const std::string& line) {
  const std::string reason = printable(line);  // (a line of Cyclone's may quote a peer's text)
  const std::string what = "create DDS participant on domain " + std::to_string(domain);
  if (reason.find("free participant index") != std::string::npos)
    return what + " (Cyclone: \"" + reason + "\": this host already has as many participants on the domain as the "
           "configuration allows, 64 with the shipped one; stop some clients or servers, or use another domain)";
  if (!reason.empty())
    return what + " (Cyclone: \"" + reason + "\"; is CYCLONEDDS_URI a readable, valid configuration?)";
  return what + " (is CYCLONEDDS_URI a readable, valid configuration? Cyclone's reason is logged above)";
}

using MatchedFn = dds_return_t (*)(dds_entity_t, dds_instance_handle_t*, size_t);
using MatchedDataFn = dds_builtintopic_endpoint_t* (*)(dds_entity_t, dds_instance_handle_t);

bool same_participant(const dds_guid_t& a, const dds_guid_t& b) { return std::memcmp(a.v, b.v, sizeof a.v) == 0; }

std::optional<dds_guid_t> participant_of(dds_entity_t e, dds_instance_handle_t ih, MatchedDataFn data) {
  dds_builtintopic_endpoint_t* ep = data(e, ih);
  if (ep == nullptr) return std::nullopt;  // unmatched in the meantime
  const dds_guid_t p = ep->participant_key;
  dds_builtintopic_free_endpoint(ep);
  return p;
}

std::vector<dds_instance_handle_t> matched_handles(dds_entity_t e, MatchedFn matched) {
  std::vector<dds_instance_handle_t> handles(8);
  while (true) {  // the count may grow between two calls: ask again until the array held them all
    const auto n = static_cast<std::size_t>(check(matched(e, handles.data(), handles.size()), "matched endpoints"));
    const bool all = n <= handles.size();
    handles.resize(n);
    if (all) return handles;
  }
}

bool matched_in(dds_entity_t e, const dds_guid_t& participant, MatchedFn matched, MatchedDataFn data) {
  const std::vector<dds_instance_handle_t> handles = matched_handles(e, matched);
  return std::any_of(handles.begin(), handles.end(), [&](dds_instance_handle_t ih) {
    const auto p = participant_of(e, ih, data);
    return p && same_participant(*p, participant);
  });
}

}  // namespace

std::optional<dds_guid_t> writer_participant(const Entity& reader, dds_instance_handle_t writer) {
  return participant_of(reader.get(), writer, dds_get_matched_publication_data);
}

std::vector<dds_instance_handle_t> matched_writers(const Entity& reader) {
  return matched_handles(reader.get(), dds_get_matched_publications);
}

bool writer_matched_in(const Entity& writer, const dds_guid_t& participant) {
  return matched_in(writer.get(), participant, dds_get_matched_subscriptions, dds_get_matched_subscription_data);
}

bool reader_matched_in(const Entity& reader, const dds_guid_t& participant) {
  return matched_in(reader.get(), participant, dds_get_matched_publications, dds_get_matched_publication_data);
}

void route_cyclone_log(void (*sink)(const char*), const char* topic) {
  g_cyclone_log.sink = sink;
  g_cyclone_log.topic = topic;
  dds_set_log_mask(DDS_LC_FATAL | DDS_LC_ERROR | DDS_LC_WARNING);
  dds_set_log_sink(on_cyclone_log, nullptr);
}

std::uint64_t undecodable_samples() { return g_cyclone_log.undecodable.load(std::memory_order_relaxed); }

void apply_profile(Qos& qos, Profile p, Side side) {
  dds_qos_t* q = qos.get();
  const dds_duration_t block = DDS_MSECS(100);  // longest a reliable write may wait for room (keep-last never does)
  switch (p) {
    case Profile::SceneInfo:
      dds_qset_reliability(q, DDS_RELIABILITY_RELIABLE, block);
      dds_qset_durability(q, DDS_DURABILITY_TRANSIENT_LOCAL);
      dds_qset_history(q, DDS_HISTORY_KEEP_LAST, side == Side::Reader ? kSceneReaderDepth : 1);
      break;
    case Profile::State:
      // A reader that joins late gets the latest state only if both sides are reliable and transient-local
      // (a best-effort reader receives no history: docs/network.md). The writer keeps the last one only, so a slow
      // reader is simply skipped ahead: the writer never waits for it. The reader keeps a few (dds.hpp, Side): a
      // client takes them all and keeps the server's latest.
      dds_qset_reliability(q, DDS_RELIABILITY_RELIABLE, block);
      dds_qset_durability(q, DDS_DURABILITY_TRANSIENT_LOCAL);
      dds_qset_history(q, DDS_HISTORY_KEEP_LAST, side == Side::Reader ? kStateReaderDepth : 1);
      break;
    case Profile::Command:
      // Every command counts, so keep-all: a client whose server is slow to take its commands waits (up to 1 s),
      // rather than losing one. The server takes them as they come (docs/server.md, "Intake").
      dds_qset_reliability(q, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
      dds_qset_history(q, DDS_HISTORY_KEEP_ALL, 0);
      break;
    case Profile::CommandAck:
      // Keep-last, not keep-all: a keep-all writer keeps every sample until each reader has confirmed it and, once
      // its history is full, blocks the writing thread; one reader that stops confirming (a client suspended with
      // Ctrl-Z, or one whose resource limits are full) would then hold up every other client's answers and, when the
      // write timed out, end the server. Cyclone never blocks a keep-last writer: it overwrites the oldest sample of
      // the instance, confirmed or not, so a reader that falls kAckDepth acks behind loses the oldest ones. The
      // server's intake keeps any one client well below that (commands.burst).
      dds_qset_reliability(q, DDS_RELIABILITY_RELIABLE, block);
      dds_qset_history(q, DDS_HISTORY_KEEP_LAST, kAckDepth);
      break;
    case Profile::Event:
      dds_qset_reliability(q, DDS_RELIABILITY_RELIABLE, block);
      dds_qset_history(q, DDS_HISTORY_KEEP_LAST, 64);
      break;
    case Profile::Stats:
      dds_qset_reliability(q, DDS_RELIABILITY_BEST_EFFORT, 0);
      dds_qset_history(q, DDS_HISTORY_KEEP_LAST, 1);
      break;
  }
}

Entity make_participant(dds_domainid_t domain, const Identity* identity) {
  if (identity == nullptr) identity = default_identity();
  if (identity == nullptr) {
    take_last_error();
    const dds_entity_t p = dds_create_participant(domain, nullptr, nullptr);
    if (p < 0) throw DdsError(participant_failure(domain, take_last_error()), p);
    return Entity(p);
  }
  Qos q;
  apply_security(q, *identity);
  take_last_error();
  const dds_entity_t p = dds_create_participant(domain, q.get(), nullptr);
  if (p >= 0) return Entity(p);
  if (const std::string reason = take_last_error(); reason.find("free participant index") != std::string::npos)
    throw DdsError(participant_failure(domain, reason), p);
  throw DdsError("create DDS participant on domain " + std::to_string(domain) + " with the " +
                     role_name(identity->role) + " identity " + identity->dir +
                     " (Cyclone's security plugins refused it; run with --log-level debug for their reason)",
                 p);
}

Entity make_topic(const Entity& participant, const dds_topic_descriptor_t* desc, const char* name) {
  return Entity(check(dds_create_topic(participant.get(), desc, name, nullptr, nullptr),
                      std::string("create topic ") + name));
}

Waiter::Waiter(const Entity& participant)
    : ws_(check(dds_create_waitset(participant.get()), "create waitset")),
      guard_(check(dds_create_guardcondition(participant.get()), "create guard condition")) {
  check(dds_waitset_attach(ws_.get(), guard_.get(), guard_.get()), "attach guard condition");
}

void Waiter::attach(const Entity& reader) {
  Entity rc(check(dds_create_readcondition(reader.get(), DDS_ANY_STATE), "create read condition"));
  check(dds_waitset_attach(ws_.get(), rc.get(), rc.get()), "attach read condition");
  conditions_.push_back(std::move(rc));
}

void Waiter::wake() const { dds_set_guardcondition(guard_.get(), true); }

bool Waiter::wait(std::chrono::nanoseconds timeout) const {
  const dds_return_t n = check(dds_waitset_wait(ws_.get(), nullptr, 0, timeout.count()), "wait");
  dds_set_guardcondition(guard_.get(), false);
  return n > 0;
}

}  // namespace ladder::transport
