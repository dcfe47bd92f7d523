// systemd's service notification protocol (sd_notify(3)), spoken directly: a datagram of "KEY=VALUE" lines to the
// AF_UNIX socket named by $NOTIFY_SOCKET. Written here rather than linking libsystemd for three messages, so that
// ladderd needs no systemd library where it runs without systemd (a container, a shell); without $NOTIFY_SOCKET
// every call does nothing.
#pragma once

#include <chrono>
#include <optional>
#include <string>

namespace ladder::daemon {

class Notifier {
 public:
  // Reads $NOTIFY_SOCKET, $WATCHDOG_USEC and $WATCHDOG_PID (the watchdog is ours only if the pid is ours or unset).
  Notifier();
  Notifier(const Notifier&) = delete;
  Notifier& operator=(const Notifier&) = delete;
  ~Notifier();

  bool enabled() const { return fd_ >= 0; }
  // How often systemd expects WATCHDOG=1 (WatchdogSec=), if it does.
  std::optional<std::chrono::microseconds> watchdog() const { return watchdog_; }
  // Sends `state` ("READY=1", "WATCHDOG=1", "STOPPING=1", "STATUS=..."); async-signal-safe apart from the string.
  // Returns whether it was sent (always false without $NOTIFY_SOCKET).
  bool send(const std::string& state) const;

 private:
  int fd_ = -1;
  std::string address_;  // the socket's path; a leading '@' is an abstract socket
  std::optional<std::chrono::microseconds> watchdog_;
};

}  // namespace ladder::daemon
