// ladderctl plot: the ripple's front and the energy of a session as a PNG (clients/ladder-view/plot.hpp), from a
// running server (the states of the next --for seconds) or from a recorded session log (all of its states).
#pragma once

#include "client.hpp"

#include <string>

namespace ladder::ctl {

struct PlotOptions {
  std::string png;
  std::string log;      // a session log (ladderd --record); empty = the running server
  double seconds = 10;  // live: how long to watch [s of wall time]
  int width = 900, height = 600;
};

// Each returns an exit code: 0 written, 1 not written (the reason printed), 2 an unreadable log.
int plot_log(const PlotOptions& o);
int plot_live(client::Client& c, const PlotOptions& o);

}  // namespace ladder::ctl
