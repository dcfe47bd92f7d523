// SIGINT, SIGTERM and SIGHUP turned into a flag for as long as the object lives, for the clients' long loops
// (ladderctl watch and replay, ladder-view --ascii): they end their loop and delete their DDS participant. Ended by
// a signal's default action instead (`timeout`, `kill`, a closed terminal), a client left its readers behind, and
// the server's reliable writers that still had samples for them waited on them when the server stopped
// (docs/network.md).
#pragma once

#include <csignal>
#include <cstddef>

namespace ladder::client {

class StopSignals {
 public:
  explicit StopSignals(void (*handler)(int)) {
    struct sigaction sa {};
    sa.sa_handler = handler;
    for (std::size_t i = 0; i < kCount; ++i) sigaction(kSignals[i], &sa, &old_[i]);
  }
  StopSignals(const StopSignals&) = delete;
  StopSignals& operator=(const StopSignals&) = delete;
  ~StopSignals() {
    for (std::size_t i = 0; i < kCount; ++i) sigaction(kSignals[i], &old_[i], nullptr);
  }

 private:
  static constexpr std::size_t kCount = 3;
  static constexpr int kSignals[kCount] = {SIGINT, SIGTERM, SIGHUP};
  struct sigaction old_[kCount] {};
};

}  // namespace ladder::client
