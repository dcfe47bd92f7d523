#include "transport/lcm_log.hpp"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <cstdio>
#include <fstream>
#include <iterator>

namespace ladder::transport {

std::int64_t now_us() {
  return std::chrono::duration_cast<std::chrono::microseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

LogWriter::LogWriter(const std::string& path) : path_(path), file_(path, "w") {
  const int why = errno;  // fopen's, if it failed
  if (!file_.good())
    throw std::runtime_error("cannot create the session log '" + path + "': " + std::strerror(why));
  thread_ = std::thread([this] { run(); });
}

LogWriter::~LogWriter() {
  {
    std::lock_guard lock(mutex_);
    closing_ = true;
  }
  wake_.notify_one();
  thread_.join();
}

void LogWriter::push(Item item, bool droppable) {
  {
    std::lock_guard lock(mutex_);
    if (droppable && queued_bytes_ > kMaxQueued) {
      dropped_.fetch_add(1);
      return;
    }
    queued_bytes_ += item.data.size();
    ++queued_total_;
    queue_.push_back(std::move(item));
  }
  wake_.notify_one();
}

bool LogWriter::sync(std::chrono::milliseconds timeout) {
  std::unique_lock lock(mutex_);
  const std::uint64_t target = queued_total_;
  const auto caught_up = [&] { return flushed_total_ >= target; };
  // The writer wakes as soon as something is queued (push notifies it), so this waits for one write and flush.
  const bool done = flushed_total_ < behind_until_ ? caught_up() : flushed_.wait_for(lock, timeout, caught_up);
  if (!done) behind_until_ = target;
  if (!done || failed_) failed_syncs_.fetch_add(1);
  return done && !failed_;
}

// Writes in batches and flushes after each, so that a crash loses at most the batch being written; LCM's reader
// stops at a cut-off last event, so everything before it stays readable.
void LogWriter::run() {
  std::deque<Item> batch;
  while (true) {
    bool closing = false;
    {
      std::unique_lock lock(mutex_);
      wake_.wait_for(lock, std::chrono::milliseconds(50), [&] { return closing_ || !queue_.empty(); });
      batch.swap(queue_);
      queued_bytes_ = 0;
      closing = closing_;
    }
    bool ok = true;
    for (Item& item : batch) {
      lcm::LogEvent e{};
      e.timestamp = item.utime;
      e.channel = item.channel;
      e.datalen = static_cast<int32_t>(item.data.size());
      e.data = item.data.data();
      ok = file_.writeEvent(&e) == 0 && ok;
    }
    written_.fetch_add(batch.size());
    ok = std::fflush(file_.getFilePtr()) == 0 && ok;
    {
      std::lock_guard lock(mutex_);
      flushed_total_ += batch.size();
      failed_ = failed_ || !ok;
    }
    flushed_.notify_all();
    batch.clear();
    if (closing) break;
  }
  fsync(fileno(file_.getFilePtr()));
}

// A regular file is mapped, not read: a reader then holds only the part it is reading (the pages behind it are
// given back as it goes, kReleaseEvery at a time), where a copy in memory took twice the file (a vector grown to its
// size) before the first event was played (a 1.1 GB log: 2.1 GB for ladderctl replay). Anything else (a pipe,
// /dev/zero) is read into memory once its first four bytes are a log's.
LogReader::LogReader(const std::string& path) : path_(path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error("cannot open the log file '" + path + "'");
  // The sync word first: a file that is not a log (/dev/zero, say, which never ends) is refused before it is read.
  char start[4] = {};
  in.read(start, sizeof start);
  bytes_.assign(start, start + in.gcount());
  data_ = bytes_.data(), size_ = bytes_.size();
  check_start();
  if (const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC); fd >= 0) {
    struct stat st {};
    if (::fstat(fd, &st) == 0 && S_ISREG(st.st_mode) && st.st_size >= 4) {
      void* m = ::mmap(nullptr, static_cast<std::size_t>(st.st_size), PROT_READ, MAP_PRIVATE, fd, 0);
      if (m != MAP_FAILED) {
        ::madvise(m, static_cast<std::size_t>(st.st_size), MADV_SEQUENTIAL);
        map_ = m, map_size_ = static_cast<std::size_t>(st.st_size);
        data_ = static_cast<const std::uint8_t*>(m), size_ = map_size_;
        bytes_.clear();
      }
    }
    ::close(fd);
  }
  if (map_) {
    check_start();  // (the file may have changed between the two opens)
    return;
  }
  bytes_.insert(bytes_.end(), std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  data_ = bytes_.data(), size_ = bytes_.size();
}

LogReader::LogReader(std::vector<std::uint8_t> bytes, std::string name)
    : path_(std::move(name)), bytes_(std::move(bytes)), data_(bytes_.data()), size_(bytes_.size()) {
  check_start();
}

LogReader::~LogReader() {
  if (map_) ::munmap(map_, map_size_);
}

void LogReader::check_start() const {
  if (size_ < 4 || data_[0] != 0xED || data_[1] != 0xA1 || data_[2] != 0xDA || data_[3] != 0x01)
    throw std::runtime_error("'" + path_ + "' is not an LCM event log (it does not start with LCM's sync word)");
}

void LogReader::refuse(const Event& e, const std::string& type, const std::string& why) const {
  throw std::runtime_error(path_ + ": event " + std::to_string(e.number) + " (" + e.channel + " at byte " +
                           std::to_string(e.offset) + ") is not a valid " + type + ": " + why);
}

namespace {
std::uint64_t big_endian(const std::uint8_t* p, int n) {
  std::uint64_t v = 0;
  for (int i = 0; i < n; ++i) v = (v << 8) | p[i];
  return v;
}
// An event's header: sync word, event number, timestamp, channel and data lengths.
constexpr std::size_t kHeader = 4 + 8 + 8 + 4 + 4;
// Lengths no event has (a channel name of LCM's at most 999 bytes, data under 2 GiB).
bool impossible_lengths(std::uint64_t channel_len, std::uint64_t data_len) {
  return channel_len == 0 || channel_len >= 1000 || data_len >= 0x80000000u;
}
}  // namespace

// The first place at or after `from` where a whole event header with plausible lengths starts (a sync word), or the
// end of the file.
std::size_t LogReader::next_event_start(std::size_t from) const {
  for (std::size_t i = from; i + kHeader <= size_; ++i) {
    const std::uint8_t* h = data_ + i;
    if (h[0] != 0xED || big_endian(h, 4) != 0xEDA1DA01u) continue;
    const std::uint64_t channel_len = big_endian(h + 20, 4), data_len = big_endian(h + 24, 4);
    if (!impossible_lengths(channel_len, data_len) && size_ - i - kHeader >= channel_len + data_len) return i;
  }
  return size_;
}

std::optional<LogReader::Event> LogReader::next() {
  if (!damage_.empty() || at_ == size_) return std::nullopt;
  const auto stop = [&](const std::string& why) {
    damage_ = why + " at byte " + std::to_string(at_) + ", after " + std::to_string(count_) + " complete events";
    // A log cut off (a server killed while writing) ends in its damage; one damaged in the middle has events after
    // it, which a reader that stops here does not see.
    if (const std::size_t later = next_event_start(at_ + 1); later < size_) {
      damage_after_ = size_ - later;
      damage_ += ", and the log goes on: " + std::to_string(damage_after_) + " bytes of events from byte " +
                 std::to_string(later) + " on are not read (the log is damaged in the middle, not cut off)";
    }
    return std::nullopt;
  };
  if (size_ - at_ < kHeader) return stop("the log is cut off in an event header");
  const std::uint8_t* h = data_ + at_;
  if (big_endian(h, 4) != 0xEDA1DA01u) return stop("no sync word where an event should start");
  const std::uint64_t channel_len = big_endian(h + 20, 4), data_len = big_endian(h + 24, 4);
  if (impossible_lengths(channel_len, data_len)) return stop("an impossible event length");
  if (size_ - at_ - kHeader < channel_len + data_len) return stop("the log is cut off inside an event");
  Event e;
  e.number = count_ + 1;
  e.offset = at_;
  e.utime = static_cast<std::int64_t>(big_endian(h + 12, 8));
  const auto* body = h + kHeader;
  e.channel.assign(reinterpret_cast<const char*>(body), channel_len);
  e.data.assign(body + channel_len, body + channel_len + data_len);
  at_ += kHeader + channel_len + data_len;
  ++count_;
  // The mapped pages behind the event just read are given back (a reader never reads back).
  if (map_ && at_ - released_ >= kReleaseEvery) {
    const std::size_t page = static_cast<std::size_t>(::sysconf(_SC_PAGESIZE)), upto = at_ / page * page;
    ::madvise(static_cast<std::uint8_t*>(map_) + released_, upto - released_, MADV_DONTNEED);
    released_ = upto;
  }
  return e;
}

}  // namespace ladder::transport
