// ladderctl list: every ladderd (and replay) on a DDS domain, from what DDS discovery and their SceneInfo and Stats
// say: sim id, host, scene, blocks, the measured real-time factor.
#pragma once

namespace ladder::ctl {

// Listens for `seconds` (Stats come once a second) and prints one line per ladder. Returns 0 if it found one, 3 if
// none answered.
int list(int domain, double seconds);

}  // namespace ladder::ctl
