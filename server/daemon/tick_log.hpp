// The tick log (ladderd --tick-log): one line per tick of the real-time loop, what it did and how late it started
// (docs/server.md, "The tick log"). The I/O thread writes it, from batches the physics thread hands over.
#pragma once

#include "daemon/config.hpp"
#include "daemon/outbox.hpp"

#include <cstdio>
#include <memory>
#include <string>
#include <vector>

namespace ladder::daemon {

class TickLog {
 public:
  // Creates config.tick_log with its header; throws OutputError when it cannot. No path: no log, and every call
  // does nothing.
  explicit TickLog(const ServerConfig& config);
  explicit operator bool() const { return file_ != nullptr; }
  const std::string& path() const { return path_; }
  // One line per tick, flushed (a few times a second: `tail -f` follows it).
  void write(const std::vector<TickRecord>& ticks);
  // Whether every line reached the file (flushes first).
  bool complete();

 private:
  std::string path_;
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> file_{nullptr, &std::fclose};
};

}  // namespace ladder::daemon
