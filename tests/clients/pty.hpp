// A program on a pseudo-terminal of a given size, as a user at a terminal runs it: what it writes is kept as it
// comes (escape sequences included), keys are typed into it, and its exit status is read.
#pragma once

#include "process.hpp"

#include <pty.h>
#include <signal.h>
#include <sys/select.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <optional>
#include <string>
#include <thread>
#include <vector>

namespace ladder::test {

class Pty {
 public:
  Pty(const std::vector<std::string>& args, int cols, int rows) {
    winsize ws{};
    ws.ws_col = static_cast<unsigned short>(cols);
    ws.ws_row = static_cast<unsigned short>(rows);
    pid_ = forkpty(&fd_, nullptr, nullptr, &ws);
    if (pid_ == 0) Process::exec(args);
  }
  Pty(const Pty&) = delete;
  Pty& operator=(const Pty&) = delete;
  ~Pty() {
    if (pid_ > 0 && !status_) {
      kill(pid_, SIGKILL);
      waitpid(pid_, nullptr, 0);
    }
    if (fd_ >= 0) close(fd_);
  }
  bool started() const { return pid_ > 0; }
  pid_t pid() const { return pid_; }

  // Reads until `words` appear after offset `from` of the screen (everything written so far), or `seconds` pass.
  bool read_until(const std::string& words, double seconds, std::size_t from = 0) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
    while (screen_.find(words, from) == std::string::npos && std::chrono::steady_clock::now() < deadline)
      if (read_some() < 0) break;
    return screen_.find(words, from) != std::string::npos;
  }
  void type(const std::string& keys) const {
    if (write(fd_, keys.data(), keys.size()) != static_cast<ssize_t>(keys.size())) return;
  }
  const std::string& screen() const { return screen_; }

  // The exit status (as from waitpid) once it has ended, reading what it writes meanwhile.
  std::optional<int> wait_exit(double seconds) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
    while (!status_ && std::chrono::steady_clock::now() < deadline) {
      int st = 0;
      if (waitpid(pid_, &st, WNOHANG) == pid_) status_ = st;
      else if (read_some() < 0) std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    while (status_ && read_some() > 0) {
    }
    return status_;
  }

 private:
  // Waits up to 0.1 s for output: 1 if some came, 0 if none, -1 if the terminal is closed (the program ended).
  int read_some() {
    fd_set set;
    FD_ZERO(&set);
    FD_SET(fd_, &set);
    timeval tv{0, 100000};
    if (select(fd_ + 1, &set, nullptr, nullptr, &tv) <= 0) return 0;
    char buf[4096];
    const ssize_t n = read(fd_, buf, sizeof buf);
    if (n <= 0) return -1;
    screen_.append(buf, static_cast<std::size_t>(n));
    return 1;
  }

  int fd_ = -1;
  pid_t pid_ = -1;
  std::string screen_;
  std::optional<int> status_;
};

}  // namespace ladder::test
