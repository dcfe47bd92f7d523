// A hostile DDS participant for the tests: readers of every ladder topic that never take, with room for one sample
// each (reliable, keep-all; transient-local where the writer is), so that they stay alive and heartbeat but confirm nothing beyond their
// first sample. Runs until killed (a process of its own: Cyclone cannot delete such a reader while a sample waits
// for room in it). Prints "ready" once every reader has matched a writer.
#include "transport/dds.hpp"
#include "transport/topics.hpp"

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <thread>
#include <vector>

int main(int argc, char** argv) {
  using namespace ladder::transport;
  if (argc != 2) {
    std::fprintf(stderr, "usage: stuck_reader DOMAIN\n");
    return 2;
  }
  const Entity participant = make_participant(static_cast<dds_domainid_t>(std::atoi(argv[1])));
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
  for (const Entity& r : readers) {
    dds_subscription_matched_status_t st{};
    while (dds_get_subscription_matched_status(r.get(), &st) >= 0 && st.current_count == 0)
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  std::printf("ready\n");
  std::fflush(stdout);
  while (true) std::this_thread::sleep_for(std::chrono::hours(1));
}
