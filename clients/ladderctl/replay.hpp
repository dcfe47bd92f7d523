// ladderctl replay: a recorded session log (ladderd --record) published on DDS as if live, for any viewer.
#pragma once

#include <string>

namespace ladder::ctl {

struct ReplayOptions {
  std::string log;
  std::string sim_id = "replay";  // published as this sim id, apart from any live ladder
  int domain = 0;
  double speed = 1;               // wall-clock pace: 2 = twice as fast; 0 = as fast as possible
  double from = 0;                // [s of sim time] where to start
};

// Publishes the log's scenes (SceneInfo with replay = true), states and events, paced by their recorded wall
// times. Returns an exit code: 0 played to the end (or Ctrl-C), 2 an unreadable log.
int replay(const ReplayOptions& options);

}  // namespace ladder::ctl
