// Every ladder on a DDS domain, from what DDS discovery and the ladders' SceneInfo and Stats say: what
// `ladderctl list` prints and what the viewer switches between (key Tab).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace ladder::client {

struct LadderEntry {
  std::string sim_id, host, scene, server_version;  // host: "?" when discovery did not say
  std::uint32_t blocks = 0;
  bool replay = false;   // a recorded session played back (ladderctl replay)
  double rtf = -1;       // measured real-time factor; < 0: no Stats came
};

struct Directory {
  std::vector<LadderEntry> ladders;  // by sim id
  std::size_t clients = 0;           // other participants on the domain that read states (any ladder's)
};

// Listens on the domain for `seconds` (Stats come once a second).
Directory discover(int domain, double seconds);

}  // namespace ladder::client
