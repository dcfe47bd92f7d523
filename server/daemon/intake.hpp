// ladderd's intake of commands: per sender, how fast it may send, what it sent lately and what it was answered,
// and the queues the physics thread takes from. No DDS and no threads here (the I/O thread holds the locks), so
// that the rules are tested alone (docs/server.md, "Intake").
//
// A sender is one client process: the DDS participant of its command writers (docs/server.md, "Intake").
#pragma once

#include "ladder.h"  // generated from msgs/ladder.idl

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <optional>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

namespace ladder::daemon {

using SenderKey = std::uint64_t;  // the I/O thread's number for a sender
using IntakeClock = std::chrono::steady_clock;

// A command on its way to the physics thread, with who sent it (its answer goes back to that sender's record).
struct Incoming {
  ladder_msg_Command command;
  SenderKey sender = 0;
};

// Commands waiting for the physics thread: one queue per sender, taken round-robin, so that a sender with many
// queued commands delays another's by at most one command per turn. Only senders with queued commands have a
// queue (a handful), so a linear search finds them.
class Inbox {
 public:
  // Queues `in` unless its sender already has `cap` commands queued; returns whether it did.
  bool push(Incoming in, std::size_t cap);
  // Moves up to n commands to `out`, one from each sender in turn.
  void take(std::size_t n, std::vector<Incoming>& out);
  // Everything queued, in turn order (at the stop).
  std::vector<Incoming> drain();
  std::size_t size() const { return total_; }
  bool empty() const { return total_ == 0; }

 private:
  std::vector<std::pair<SenderKey, std::deque<Incoming>>> queues_;
  std::size_t next_ = 0;  // the queue whose turn is next
  std::size_t total_ = 0;
};

// A token bucket: on average `rate` a second, up to `burst` at once. It starts full.
class Bucket {
 public:
  Bucket(double rate, double burst, IntakeClock::time_point now) : rate_(rate), burst_(burst), tokens_(burst), at_(now) {}
  // Takes one token if there is one.
  bool take(IntakeClock::time_point now);

 private:
  double rate_, burst_, tokens_;
  IntakeClock::time_point at_;
};

// Log lines that a peer can make the server write (a refusal, a client that never reads its answers): at most
// `per_second` a second on average, as many at once; the lines held back are counted, and said with the next one
// written, so that a flood of them can fill neither the disk nor the console.
class LogBudget {
 public:
  LogBudget(double per_second, IntakeClock::time_point now) : lines_(per_second, per_second, now) {}
  // Whether a line may be written now; when it may, `held_back` is how many were not since the last one written.
  bool allow(IntakeClock::time_point now, std::uint64_t& held_back);

 private:
  Bucket lines_;
  std::uint64_t held_back_ = 0;
};

// The answer a command got, kept to answer it again.
struct Answer {
  bool accepted = false;
  std::string reason;
  double sim_time = 0;
  std::uint64_t step = 0, command_seq = 0;
};

// The last kWindow commands of one sender, by client id and command id, and their answers once given. A command
// that comes again (a client's retry after a lost answer, or a hostile copy) is never applied twice: it gets the
// first one's answer again, or, while that is pending, the one answer both will share.
class RecentCommands {
 public:
  static constexpr std::size_t kWindow = 1024;
  enum class Seen { New, Pending, Answered };
  // Whether `c` was seen; a new one is remembered as pending.
  Seen note(const ladder_msg_Command& c);
  // The answer of a command noted before, if it has one.
  const Answer* answer(const ladder_msg_Command& c) const;
  // Records the answer of a noted command (ignored if the window has moved past it).
  void answered(const char (&client_id)[65], std::uint64_t command_id, Answer a);
  // Forgets a noted command that never reached the simulation (refused for rate): sent again, it is new.
  void forget(const ladder_msg_Command& c);

 private:
  static std::string key(const char (&client_id)[65], std::uint64_t command_id);
  std::unordered_map<std::string, std::optional<Answer>> seen_;
  std::deque<std::string> order_;  // oldest first
};

}  // namespace ladder::daemon
