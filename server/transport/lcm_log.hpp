// LCM event logs (the format of lcm-logger and lcm-logplayer): a writer with a thread of its own, so that writing
// never blocks its callers, and a reader that stops cleanly at a damaged or cut-off end.
#pragma once

#include "transport/lcm_decode.hpp"

#include <lcm/lcm-cpp.hpp>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

namespace ladder::transport {

// Channel names of a session log.
inline constexpr const char* kSceneChannel = "LADDER_SCENE";
inline constexpr const char* kStateChannel = "LADDER_STATE";
inline constexpr const char* kEventChannel = "LADDER_EVENT";
inline constexpr const char* kCommandChannel = "LADDER_COMMAND";
inline constexpr const char* kCheckpointChannel = "LADDER_CHECKPOINT";
// A step that failed (the session paused itself), as a checkpoint_t: where, and the hash of the state it was left at.
inline constexpr const char* kFailureChannel = "LADDER_FAILURE";
// A state found to hold a non-finite number, which the server did not publish (it paused): the same fields.
inline constexpr const char* kNonFiniteChannel = "LADDER_NONFINITE";

std::int64_t now_us();  // wall time [us since the epoch], the LCM convention

class LogWriter {
 public:
  // Throws std::runtime_error naming the path when the file cannot be created.
  explicit LogWriter(const std::string& path);
  LogWriter(const LogWriter&) = delete;
  LogWriter& operator=(const LogWriter&) = delete;
  // Writes what is queued, flushes and closes the file.
  ~LogWriter();

  // Encodes `message` and queues it. A droppable message (a state) is dropped, and counted, when more than
  // kMaxQueued bytes wait; the others are always kept.
  template <class T>
  void write(const char* channel, std::int64_t utime, const T& message, bool droppable) {
    std::vector<std::uint8_t> data(static_cast<std::size_t>(message.getEncodedSize()));
    message.encode(data.data(), 0, static_cast<int>(data.size()));
    write_bytes(channel, utime, std::move(data), droppable);
  }
  // An event already encoded (copying a log).
  void write_bytes(const std::string& channel, std::int64_t utime, std::vector<std::uint8_t> data, bool droppable) {
    push({channel, utime, std::move(data)}, droppable);
  }
  // Waits until everything queued so far is written and flushed to the file (in the kernel's hands: it survives
  // a kill -9 of this process, not a power cut). False when that took longer than `timeout` or writing failed;
  // then, until the writer has caught up with what was queued at that time, it returns false without waiting (a
  // stalled disk costs its callers one timeout, not one per call). ladderd calls it before it acknowledges
  // commands, so that every acknowledged command is in the log.
  bool sync(std::chrono::milliseconds timeout);
  std::uint64_t failed_syncs() const { return failed_syncs_.load(); }
  std::uint64_t written() const { return written_.load(); }
  std::uint64_t dropped() const { return dropped_.load(); }
  const std::string& path() const { return path_; }

  static constexpr std::size_t kMaxQueued = 256u << 20;

 private:
  struct Item {
    std::string channel;
    std::int64_t utime;
    std::vector<std::uint8_t> data;
  };
  void push(Item item, bool droppable);
  void run();

  std::string path_;
  lcm::LogFile file_;
  std::mutex mutex_;
  std::condition_variable wake_;
  std::deque<Item> queue_;
  std::size_t queued_bytes_ = 0;
  std::uint64_t queued_total_ = 0, flushed_total_ = 0;  // items ever queued, and ever written and flushed
  std::condition_variable flushed_;                     // flushed_total_ grew
  bool failed_ = false;                                 // a write or flush failed
  std::uint64_t behind_until_ = 0;                      // a sync timed out: do not wait until this much is flushed
  std::atomic<std::uint64_t> failed_syncs_{0};
  bool closing_ = false;
  std::atomic<std::uint64_t> written_{0}, dropped_{0};
  std::thread thread_;
};

// Reads the LCM log format itself (a sync word, event number, timestamp, channel and data lengths, then both)
// rather than through liblcm, so that a damaged file is found and reported, never trusted: a length beyond the end
// of the file or a missing sync word ends the log there, and damage() says where. Events are decoded by our own
// decoders (lcm_decode.hpp), which check every length before they allocate.
class LogReader {
 public:
  struct Event {
    std::string channel;
    std::int64_t utime = 0;
    std::vector<std::uint8_t> data;
    std::uint64_t number = 0;  // 1 for the first event of the log
    std::size_t offset = 0;    // where it starts in the file [bytes]
  };
  // Throws std::runtime_error naming the path when it cannot be opened or is not an LCM log.
  explicit LogReader(const std::string& path);
  // The same on bytes in memory (a fuzzer's input); `name` stands for the path in messages.
  LogReader(std::vector<std::uint8_t> bytes, std::string name);
  ~LogReader();
  LogReader(const LogReader&) = delete;
  LogReader& operator=(const LogReader&) = delete;
  // The next event, or nothing at the end of the log or where it is damaged or cut off.
  std::optional<Event> next();
  // The event that next() returned as number `number` from byte `offset`, read again (a reader of a long log keeps
  // where its records are rather than the records); nothing, with `why`, when the file no longer holds one there.
  std::optional<Event> event_at(std::size_t offset, std::uint64_t number, std::string& why);
  // Empty, or what was wrong where reading stopped ("cut off in event 12 at byte 4096", ...).
  const std::string& damage() const { return damage_; }
  // The bytes of events after the damage (0 when the log is cut off there, as a killed server leaves it).
  std::size_t damage_after() const { return damage_after_; }
  // Decodes an event's data; throws std::runtime_error naming the file, the event and what is wrong when it does
  // not decode or holds an impossible value.
  template <class T>
  T decode(const Event& e) const {
    T m;
    if (const std::string why = decode_lcm(e.data, m); !why.empty()) refuse(e, T::getTypeName(), why);
    return m;
  }
  // Throws the std::runtime_error that decode() throws: "<path>: event 12 (LADDER_STATE at byte 4096): <why>".
  [[noreturn]] void refuse(const Event& e, const std::string& type, const std::string& why) const;
  std::uint64_t count() const { return count_; }
  const std::string& path() const { return path_; }

 private:
  static bool starts_a_log(const std::uint8_t* p, std::size_t n);
  [[noreturn]] void not_a_log() const;
  // The log's bytes [pos, pos + n), n <= size_ - pos; null when the file no longer has them (another program made
  // it shorter since it was opened).
  const std::uint8_t* bytes_at(std::size_t pos, std::size_t n);
  std::size_t next_event_start(std::size_t from);

  // A regular file is read this much at a time (or one event, if larger), not mapped: a mapped file cut shorter by
  // another program (logrotate's copytruncate) kills its reader with SIGBUS at the first page past the new end.
  static constexpr std::size_t kWindow = std::size_t{8} << 20;  // [bytes]
  std::string path_;
  int fd_ = -1;                      // the regular file read a window at a time, or -1: the whole log in bytes_
  std::vector<std::uint8_t> bytes_;  // the whole log (given as bytes, or read from a pipe), or the window read
  std::size_t base_ = 0;             // where bytes_ starts in the log
  std::size_t size_ = 0;             // the log's size (a file's when it was opened)
  std::size_t at_ = 0;
  std::uint64_t count_ = 0;
  std::string damage_;
  std::size_t damage_after_ = 0;
};

}  // namespace ladder::transport
