#include "list.hpp"

#include "client.hpp"
#include "directory.hpp"

#include <cstdio>
#include <iostream>

namespace ladder::ctl {

int list(int domain, double seconds) {
  const client::Directory d = client::discover(domain, seconds);
  if (d.ladders.empty()) {
    char t[32];
    std::snprintf(t, sizeof t, "%g", seconds);
    std::cerr << "ladderctl: no ladderd on DDS domain " << domain << " after " << t
              << " s; is one running, and is CYCLONEDDS_URI the same on both sides?\n";
    return 3;
  }
  std::printf("%zu ladder%s on DDS domain %d:\n", d.ladders.size(), d.ladders.size() == 1 ? "" : "s", domain);
  std::printf("%-32s %-20s %-28s %8s %10s\n", "sim id", "host", "scene", "blocks", "real-time");
  for (const client::LadderEntry& l : d.ladders) {
    std::string rtf = "-";
    if (l.rtf >= 0) rtf = 'x' + client::fixed(l.rtf, 2);
    std::printf("%-32s %-20s %-28s %8u %10s%s\n", l.sim_id.c_str(), l.host.c_str(), l.scene.c_str(), l.blocks,
                rtf.c_str(), l.replay ? "  (a replay)" : "");
  }
  std::printf("clients on the domain: %zu participant%s reading states (discovery does not say which ladder each "
              "one watches)\n",
              d.clients, d.clients == 1 ? "" : "s");
  return 0;
}

}  // namespace ladder::ctl
