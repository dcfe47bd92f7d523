// A hostile DDS participant for the tests, in a process of its own:
//
//   hostile_peer stuck DOMAIN         readers of every ladder topic that never take, with room for one sample each
//                                     (reliable, keep-all; transient-local where the writer is), so that they stay
//                                     alive and heartbeat but confirm nothing beyond their first sample. Runs until
//                                     killed (Cyclone cannot delete such a reader while a sample waits for room).
//   hostile_peer bad-command DOMAIN SIM_ID COUNT
//                                     writes COUNT Commands whose kind (99) is beyond the enum, as a client built
//                                     from another msgs/ladder.idl would: the same type name, its own enum bound and
//                                     no XTypes type information (so that matching goes by the name). The server's
//                                     reader cannot deserialize them. Then runs until killed.
//
// Prints "ready" when its readers have matched (stuck) or its writer has (bad-command), "sent" after the writes.
#include "transport/dds.hpp"
#include "transport/topics.hpp"

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

namespace {

using namespace ladder::transport;

void say(const char* what) {
  std::printf("%s\n", what);
  std::fflush(stdout);
}

template <class Status, class F>
void wait_matched(const Entity& e, F get) {
  Status st{};
  while (get(e.get(), &st) >= 0 && st.current_count == 0) std::this_thread::sleep_for(std::chrono::milliseconds(10));
}

[[noreturn]] void forever() {
  while (true) std::this_thread::sleep_for(std::chrono::hours(1));
}

[[noreturn]] void stuck(int domain) {
  const Entity participant = make_participant(static_cast<dds_domainid_t>(domain));
  const Topics topics(participant);
  std::vector<Entity> readers;
  // (Stats are best-effort: nothing a reader does can hold up their writer.)
  for (const Entity* t : {&topics.scene_info, &topics.state, &topics.ack, &topics.event}) {
    Qos q;
    dds_qset_reliability(q.get(), DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
    if (t == &topics.scene_info || t == &topics.state) dds_qset_durability(q.get(), DDS_DURABILITY_TRANSIENT_LOCAL);
    dds_qset_history(q.get(), DDS_HISTORY_KEEP_ALL, 0);
    dds_qset_resource_limits(q.get(), 1, 1, 1);
    readers.emplace_back(check(dds_create_reader(participant.get(), t->get(), q.get(), nullptr), "create reader"));
  }
  for (const Entity& r : readers)
    wait_matched<dds_subscription_matched_status_t>(r, dds_get_subscription_matched_status);
  say("ready");
  forever();
}

[[noreturn]] void bad_command(int domain, const std::string& sim_id, int count) {
  // ladder_msg_Command_desc with the kind's bound raised and without type information.
  // The struct's members are all plain: an ADR op and its offset, and a bound for strings and enums. Then RTS, and
  // the key list (KOF | n and n words per key).
  const dds_topic_descriptor_t& d = ladder_msg_Command_desc;
  std::vector<std::uint32_t> ops;
  std::size_t i = 0;
  for (; d.m_ops[i] != DDS_OP_RTS; i += ops.size() - i) {
    const auto type = DDS_OP_TYPE(d.m_ops[i]);
    const std::size_t words = type == DDS_OP_VAL_BST || type == DDS_OP_VAL_ENU ? 3 : 2;
    ops.insert(ops.end(), d.m_ops + i, d.m_ops + i + words);
    if (type == DDS_OP_VAL_ENU) ops.back() = 255;
  }
  std::size_t end = i + 1;
  for (std::uint32_t k = 0; k < d.m_nkeys; ++k) end += 1 + (d.m_ops[end] & 0xffffu);
  ops.insert(ops.end(), d.m_ops + i, d.m_ops + end);
  const dds_topic_descriptor_t other{d.m_size,  d.m_align, 0u,         d.m_nkeys, d.m_typename, d.m_keys,
                                     d.m_nops,  ops.data(), d.m_meta, {},        {},           0u};
  const Entity participant = make_participant(static_cast<dds_domainid_t>(domain));
  const Entity topic = make_topic(participant, &other, "ladder/Command");
  Qos q;
  apply_profile(q, Profile::Command);
  const Entity writer(check(dds_create_writer(participant.get(), topic.get(), q.get(), nullptr), "create writer"));
  wait_matched<dds_publication_matched_status_t>(writer, dds_get_publication_matched_status);
  say("ready");
  ladder_msg_Command c{};
  copy_text(c.sim_id, sim_id);
  copy_text(c.client_id, "newer-client");
  // A kind this ladder.idl does not have: its bytes written as such (a cast to the enum would be unspecified).
  const std::int32_t unknown_kind = 99;
  static_assert(sizeof c.kind == sizeof unknown_kind);
  std::memcpy(&c.kind, &unknown_kind, sizeof c.kind);
  for (int n = 1; n <= count; ++n) {
    c.command_id = static_cast<std::uint64_t>(n);
    check(dds_write(writer.get(), &c), "write");
  }
  say("sent");
  forever();
}

}  // namespace

int main(int argc, char** argv) {
  const std::string mode = argc > 1 ? argv[1] : "";
  if (mode == "stuck" && argc == 3) stuck(std::atoi(argv[2]));
  if (mode == "bad-command" && argc == 5) bad_command(std::atoi(argv[2]), argv[3], std::atoi(argv[4]));
  std::fprintf(stderr, "usage: hostile_peer stuck DOMAIN | hostile_peer bad-command DOMAIN SIM_ID COUNT\n");
  return 2;
}
