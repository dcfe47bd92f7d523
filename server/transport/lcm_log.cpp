#include "transport/lcm_log.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <cstdio>

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

namespace {
// Reads up to n bytes at `offset` (pread) or, with offset < 0, from where the file is (read); fewer at its end.
std::size_t read_fully(int fd, std::uint8_t* to, std::size_t n, off_t offset) {
  std::size_t got = 0;
  while (got < n) {
    const ssize_t r = offset < 0 ? ::read(fd, to + got, n - got)
                                 : ::pread(fd, to + got, n - got, offset + static_cast<off_t>(got));
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0) break;
    got += static_cast<std::size_t>(r);
  }
  return got;
}
}  // namespace

// A regular file is read a window at a time: a reader then holds only the part it is reading (a 1.1 GB log took
// 2.1 GB for ladderctl replay when it was read into memory whole, a vector grown to its size), and a file shortened
// by another program while it is read ends the log there, as damage. Anything else (a pipe) is read into memory once
// its first four bytes are a log's (/dev/zero, which never ends, is refused before it is read).
LogReader::LogReader(const std::string& path) : path_(path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw std::runtime_error("cannot open the log file '" + path + "'");
  struct stat st {};
  if (::fstat(fd, &st) == 0 && S_ISREG(st.st_mode)) {
    fd_ = fd, size_ = static_cast<std::size_t>(st.st_size);
    const std::uint8_t* start = size_ >= 4 ? bytes_at(0, 4) : nullptr;
    if (start && starts_a_log(start, 4)) return;
    ::close(fd_);  // (the destructor does not run when the constructor throws)
    not_a_log();
  }
  bytes_.resize(4);
  bytes_.resize(read_fully(fd, bytes_.data(), 4, -1));
  if (starts_a_log(bytes_.data(), bytes_.size())) {
    std::vector<std::uint8_t> chunk(std::size_t{1} << 16);
    for (std::size_t got; (got = read_fully(fd, chunk.data(), chunk.size(), -1)) > 0;)
      bytes_.insert(bytes_.end(), chunk.begin(), chunk.begin() + static_cast<std::ptrdiff_t>(got));
  }
  ::close(fd);
  if (!starts_a_log(bytes_.data(), bytes_.size())) not_a_log();
  size_ = bytes_.size();
}

LogReader::LogReader(std::vector<std::uint8_t> bytes, std::string name)
    : path_(std::move(name)), bytes_(std::move(bytes)), size_(bytes_.size()) {
  if (!starts_a_log(bytes_.data(), bytes_.size())) not_a_log();
}

LogReader::~LogReader() {
  if (fd_ >= 0) ::close(fd_);
}

bool LogReader::starts_a_log(const std::uint8_t* p, std::size_t n) {
  return n >= 4 && p[0] == 0xED && p[1] == 0xA1 && p[2] == 0xDA && p[3] == 0x01;
}

void LogReader::not_a_log() const {
  throw std::runtime_error("'" + path_ + "' is not an LCM event log (it does not start with LCM's sync word)");
}

const std::uint8_t* LogReader::bytes_at(std::size_t pos, std::size_t n) {
  if (fd_ < 0) return bytes_.data() + pos;
  if (pos >= base_ && pos - base_ + n <= bytes_.size()) return bytes_.data() + (pos - base_);
  const std::size_t want = std::min(size_ - pos, std::max(n, kWindow));
  bytes_.resize(want);
  bytes_.resize(read_fully(fd_, bytes_.data(), want, static_cast<off_t>(pos)));
  base_ = pos;
  return bytes_.size() >= n ? bytes_.data() : nullptr;
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
std::size_t LogReader::next_event_start(std::size_t from) {
  for (std::size_t i = from; i + kHeader <= size_;) {
    const std::uint8_t* h = bytes_at(i, kHeader);
    if (!h) break;  // the file was shortened
    // The candidates whose headers lie whole in the bytes at hand are searched for the sync word's first byte at
    // memchr's speed (a damaged log may have gigabytes after its damage, or a hole of zeros).
    const std::size_t held = fd_ < 0 ? size_ - i : base_ + bytes_.size() - i;
    const std::size_t candidates = held - kHeader + 1;
    const auto* hit = static_cast<const std::uint8_t*>(std::memchr(h, 0xED, candidates));
    if (!hit) {
      i += candidates;
      continue;
    }
    i += static_cast<std::size_t>(hit - h);
    const std::uint64_t channel_len = big_endian(hit + 20, 4), data_len = big_endian(hit + 24, 4);
    if (big_endian(hit, 4) == 0xEDA1DA01u && !impossible_lengths(channel_len, data_len) &&
        size_ - i - kHeader >= channel_len + data_len)
      return i;
    ++i;
  }
  return size_;
}

std::optional<LogReader::Event> LogReader::event_at(std::size_t pos, std::uint64_t number, std::string& why) {
  static const std::string shortened = "the log file became shorter while it was read (another program cut it), "
                                       "cutting off the event";
  if (pos >= size_ || size_ - pos < kHeader) return why = "the log is cut off in an event header", std::nullopt;
  const std::uint8_t* h = bytes_at(pos, kHeader);
  if (!h) return why = shortened, std::nullopt;
  if (big_endian(h, 4) != 0xEDA1DA01u) return why = "no sync word where an event should start", std::nullopt;
  const std::uint64_t channel_len = big_endian(h + 20, 4), data_len = big_endian(h + 24, 4);
  if (impossible_lengths(channel_len, data_len)) return why = "an impossible event length", std::nullopt;
  if (size_ - pos - kHeader < channel_len + data_len) return why = "the log is cut off inside an event", std::nullopt;
  if (!(h = bytes_at(pos, kHeader + channel_len + data_len))) return why = shortened, std::nullopt;
  Event e;
  e.number = number;
  e.offset = pos;
  e.utime = static_cast<std::int64_t>(big_endian(h + 12, 8));
  const auto* body = h + kHeader;
  e.channel.assign(reinterpret_cast<const char*>(body), channel_len);
  e.data.assign(body + channel_len, body + channel_len + data_len);
  return e;
}

std::optional<LogReader::Event> LogReader::next() {
  if (!damage_.empty() || at_ == size_) return std::nullopt;
  std::string why;
  std::optional<Event> e = event_at(at_, count_ + 1, why);
  if (!e) {
    damage_ = why + " at byte " + std::to_string(at_) + ", after " + std::to_string(count_) + " complete events";
    // A log cut off (a server killed while writing) ends in its damage; one damaged in the middle has events after
    // it, which a reader that stops here does not see.
    if (const std::size_t later = next_event_start(at_ + 1); later < size_) {
      damage_after_ = size_ - later;
      damage_ += ", and the log goes on: " + std::to_string(damage_after_) + " bytes of events from byte " +
                 std::to_string(later) + " on are not read (the log is damaged in the middle, not cut off)";
    }
    return std::nullopt;
  }
  at_ += kHeader + e->channel.size() + e->data.size();
  ++count_;
  return e;
}

}  // namespace ladder::transport
