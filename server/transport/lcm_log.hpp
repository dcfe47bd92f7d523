// LCM event logs (the format of lcm-logger and lcm-logplayer): a writer with a thread of its own, so that writing
// never blocks its callers, and a reader that stops cleanly at a damaged or cut-off end.
#pragma once

#include <lcm/lcm-cpp.hpp>

#include <atomic>
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
  bool closing_ = false;
  std::atomic<std::uint64_t> written_{0}, dropped_{0};
  std::thread thread_;
};

// Reads the LCM log format itself (a sync word, event number, timestamp, channel and data lengths, then both)
// rather than through liblcm, so that a damaged file is found and reported, never trusted: a length beyond the end
// of the file or a missing sync word ends the log there, and damage() says where.
class LogReader {
 public:
  struct Event {
    std::string channel;
    std::int64_t utime = 0;
    std::vector<std::uint8_t> data;
  };
  // Throws std::runtime_error naming the path when it cannot be opened or is not an LCM log.
  explicit LogReader(const std::string& path);
  // The next event, or nothing at the end of the log or where it is damaged or cut off.
  std::optional<Event> next();
  // Empty, or what was wrong where reading stopped ("cut off in event 12 at byte 4096", ...).
  const std::string& damage() const { return damage_; }
  // Decodes an event's data; throws std::runtime_error naming the event when it does not decode.
  template <class T>
  T decode(const Event& e) const {
    T m;
    int used = -1;
    try {
      used = m.decode(e.data.data(), 0, static_cast<int>(e.data.size()));
    } catch (const std::exception&) {  // lcm-gen's decoders throw on some bad lengths (a string of length 0)
    }
    if (used < 0)
      throw std::runtime_error(path_ + ": event " + std::to_string(count_) + " on " + e.channel +
                               " does not decode as " + T::getTypeName() + " (a damaged log)");
    return m;
  }
  std::uint64_t count() const { return count_; }
  const std::string& path() const { return path_; }

 private:
  std::string path_;
  std::vector<std::uint8_t> bytes_;  // the whole file (logs are read once, front to back)
  std::size_t at_ = 0;
  std::uint64_t count_ = 0;
  std::string damage_;
};

}  // namespace ladder::transport
