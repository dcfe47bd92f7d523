// ladderd --offline: run a scene as fast as possible with no network, writing events, a trajectory and a summary.
#pragma once

#include <string>
#include <vector>

namespace ladder::daemon {

struct OfflineOptions {
  std::string scene;                 // scene file
  std::vector<std::string> overrides;  // --set KEY=VALUE
  double duration = 0;               // [s] of simulated time
  std::string events;                // JSON lines, one per event ("" = none)
  std::string trajectory;            // CSV t,block,x,y,theta every 10 ms of sim time ("" = none)
  std::string summary;               // one JSON object ("" = none)
  bool progress = true;              // a progress line every few seconds of wall time
};

// Returns the process exit code: 0 done, 2 bad input (scene, overrides, output files), 3 the simulation failed.
int run_offline(const OfflineOptions& options);

}  // namespace ladder::daemon
