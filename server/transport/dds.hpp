// Small RAII owners of Cyclone DDS entities (C API), and the project's QoS profiles.
//
// No framework: an Entity deletes its dds_entity_t when it goes out of scope, a failed call throws DdsError with
// dds_strretcode's text, and the typed Writer/Reader only add the sample type. Declare the Participant first so it
// is destroyed last (deleting a participant deletes its children, and an Entity whose handle is already gone just
// gets DDS_RETCODE_BAD_PARAMETER back, which it ignores).
#pragma once

#include <dds/dds.h>

#include "ladder/printable.hpp"

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace ladder::transport {

class DdsError : public std::runtime_error {
 public:
  DdsError(const std::string& what, dds_return_t rc)
      : std::runtime_error(what + ": " + dds_strretcode(rc)), code_(rc) {}
  dds_return_t code() const { return code_; }

 private:
  dds_return_t code_;
};

// Throws DdsError when rc is negative (an error code or an invalid entity); returns it otherwise.
inline dds_return_t check(dds_return_t rc, const std::string& what) {
  if (rc < 0) throw DdsError(what, rc);
  return rc;
}

// Makes Cyclone use the project's loopback configuration unless the user chose one: CYCLONEDDS_URI, when set,
// always wins (docs/network.md). `xml` is the text of config/cyclonedds.xml, built into the binaries.
void use_default_config(const std::string& xml);

class Entity {
 public:
  Entity() = default;
  explicit Entity(dds_entity_t e) : e_(e) {}
  Entity(Entity&& o) noexcept : e_(std::exchange(o.e_, 0)) {}
  Entity& operator=(Entity&& o) noexcept {
    if (this != &o) {
      reset();
      e_ = std::exchange(o.e_, 0);
    }
    return *this;
  }
  Entity(const Entity&) = delete;
  Entity& operator=(const Entity&) = delete;
  ~Entity() { reset(); }

  dds_entity_t get() const { return e_; }
  explicit operator bool() const { return e_ > 0; }
  void reset() {
    if (e_ > 0) dds_delete(e_);
    e_ = 0;
  }

 private:
  dds_entity_t e_ = 0;
};

// Owns a dds_qos_t.
class Qos {
 public:
  Qos() : q_(dds_create_qos()) {}
  Qos(const Qos&) = delete;
  Qos& operator=(const Qos&) = delete;
  ~Qos() { dds_delete_qos(q_); }
  dds_qos_t* get() const { return q_; }

 private:
  dds_qos_t* q_;
};

// The QoS of each topic (docs/server.md, "Topics"); writer and reader of a topic use the same profile, but for the
// depth of a keyed topic's reader history (see Side).
enum class Profile {
  SceneInfo,   // reliable, transient-local, keep-last 1 (reader: kSceneReaderDepth)
  State,       // reliable, keep-last 1, transient-local (both sides: late joiners get the latest; a slow reader is
               // skipped ahead, never waited for: see .cpp) (reader: kStateReaderDepth)
  Command,     // reliable, keep-all
  CommandAck,  // reliable, keep-last kAckDepth (a writer that never waits for a reader, see .cpp)
  Event,       // reliable, keep-last 64
  Stats,       // best-effort, keep-last 1
};
// A reader's history is per instance, and an instance is a sim id: every writer of a sim id shares it. A reader of
// depth 1 keeps only the latest sample of all of them, so another participant publishing under the server's sim id
// faster than the server (a forger, without DDS Security) would replace the server's every sample before the client
// takes it, and the client would never find its server. The readers of SceneInfo and State therefore keep several
// samples, so that the server's last one is still among them when the client takes (the writers keep one).
enum class Side { Writer, Reader };
inline constexpr std::int32_t kStateReaderDepth = 8;
inline constexpr std::int32_t kSceneReaderDepth = 16;
void apply_profile(Qos& q, Profile p, Side side = Side::Writer);
// How many acknowledgements the server's writer keeps for readers that have not confirmed them yet. A reader further
// behind than this loses the oldest (it was not taking them); a server's commands.burst stays below it.
inline constexpr std::int32_t kAckDepth = 4096;
// The largest domain id every participant can use with the shipped configurations: DDS's port mapping puts a
// participant's unicast ports at 7400 + 250 domain + 10 + 2 index (and + 1), and config/cyclonedds*.xml allow
// indices up to 64, so 232 (the mapping's own limit) would put the last ones past port 65535 (Cyclone then logs a
// failed write to port 65536 every few seconds).
inline constexpr int kMaxDomain = 231;

// Routes Cyclone's own warnings and errors (which it would print to stderr) to `sink`, and counts the samples of
// `topic` that Cyclone could not deserialize (and so never delivered): a hostile or mismatched writer's. The sink
// may be called from any of Cyclone's threads. Process-wide; call before the first entity is created.
void route_cyclone_log(void (*sink)(const char* message), const char* topic);
std::uint64_t undecodable_samples();

// At most `max_lines` lines shown in each `period`, for a sink of route_cyclone_log(): admit() says whether this one
// is (`shown`), and returns how many were not in the period just ended when a new one starts (0 otherwise), for a
// line that says so. Not thread-safe: the sink holds a lock around it.
class LineLimiter {
 public:
  LineLimiter(int max_lines, std::chrono::steady_clock::duration period) : max_lines_(max_lines), period_(period) {}
  std::uint64_t admit(std::chrono::steady_clock::time_point now, bool& shown) {
    std::uint64_t report = 0;
    if (now - window_ >= period_) {
      report = std::exchange(hidden_, 0);
      window_ = now;
      lines_ = 0;
    }
    shown = ++lines_ <= max_lines_;
    if (!shown) ++hidden_;
    return report;
  }

 private:
  int max_lines_;
  std::chrono::steady_clock::duration period_;
  std::chrono::steady_clock::time_point window_{};
  int lines_ = 0;
  std::uint64_t hidden_ = 0;
};

struct Identity;  // transport/security.hpp
// A participant on `domain`; with DDS Security when `identity` is given, or else when a default identity is set
// (set_default_identity, from a program's --security).
Entity make_participant(dds_domainid_t domain, const Identity* identity = nullptr);
Entity make_topic(const Entity& participant, const dds_topic_descriptor_t* desc, const char* name);

// Which participant a remote endpoint belongs to, from the built-in topics' data. A client uses this to know that
// its command writer has found the reader of the server whose states it sees, and not only some other server's.
// The participant of the writer a reader's sample came from (dds_sample_info_t::publication_handle); nullopt when
// the reader is no longer matched with that writer.
std::optional<dds_guid_t> writer_participant(const Entity& reader, dds_instance_handle_t writer);
// The writers a reader is matched with now (their handles are those of dds_sample_info_t::publication_handle).
std::vector<dds_instance_handle_t> matched_writers(const Entity& reader);
// Whether a writer is matched with a reader in `participant`, or a reader with a writer in it.
bool writer_matched_in(const Entity& writer, const dds_guid_t& participant);
bool reader_matched_in(const Entity& reader, const dds_guid_t& participant);

template <class T>
class Writer {
 public:
  Writer() = default;
  Writer(const Entity& participant, const Entity& topic, Profile p) {
    Qos q;
    apply_profile(q, p);
    e_ = Entity(check(dds_create_writer(participant.get(), topic.get(), q.get(), nullptr), "create writer"));
  }
  void write(const T& sample) const { check(dds_write(e_.get(), &sample), "write"); }
  // The same, returning dds_write's code instead of throwing: for a server, whose writes must not end it.
  dds_return_t try_write(const T& sample) const { return dds_write(e_.get(), &sample); }
  // Readers matched now.
  std::uint32_t matched() const {
    dds_publication_matched_status_t st{};
    check(dds_get_publication_matched_status(e_.get(), &st), "publication matched status");
    return st.current_count;
  }
  bool matched_in(const dds_guid_t& participant) const { return writer_matched_in(e_, participant); }
  const Entity& entity() const { return e_; }

 private:
  Entity e_;
};

template <class T>
class Reader {
 public:
  Reader() = default;
  Reader(const Entity& participant, const Entity& topic, Profile p) {
    Qos q;
    apply_profile(q, p, Side::Reader);
    e_ = Entity(check(dds_create_reader(participant.get(), topic.get(), q.get(), nullptr), "create reader"));
  }
  // Takes every available sample (valid data only) and passes each to f(const T&, const dds_sample_info_t&),
  // using the reader's loans (no copy). Returns how many valid samples were passed.
  template <class F>
  std::size_t take(F&& f, std::size_t max = SIZE_MAX) const {
    constexpr std::size_t kBatch = 64;
    std::size_t n_valid = 0;
    while (n_valid < max) {
      void* buf[kBatch] = {};
      dds_sample_info_t info[kBatch];
      const dds_return_t n = check(dds_take(e_.get(), buf, info, kBatch, kBatch), "take");
      for (dds_return_t i = 0; i < n; ++i) {
        if (!info[i].valid_data) continue;
        ++n_valid;
        try {
          f(*static_cast<const T*>(buf[i]), info[i]);
        } catch (...) {
          dds_return_loan(e_.get(), buf, n);
          throw;
        }
      }
      dds_return_loan(e_.get(), buf, n);
      if (n < static_cast<dds_return_t>(kBatch)) break;
    }
    return n_valid;
  }
  // Writers matched now.
  std::uint32_t matched() const {
    dds_subscription_matched_status_t st{};
    check(dds_get_subscription_matched_status(e_.get(), &st), "subscription matched status");
    return st.current_count;
  }
  bool matched_in(const dds_guid_t& participant) const { return reader_matched_in(e_, participant); }
  const Entity& entity() const { return e_; }

 private:
  Entity e_;
};

// A waitset with the reader's data-available condition and a guard condition another thread triggers.
class Waiter {
 public:
  explicit Waiter(const Entity& participant);
  void attach(const Entity& reader);  // wakes when the reader has data
  void wake() const;                  // from any thread
  // Waits until data, wake() or the timeout; returns true unless it timed out.
  bool wait(std::chrono::nanoseconds timeout) const;

 private:
  Entity ws_, guard_;
  std::vector<Entity> conditions_;
};

// Lends a vector's elements to an IDL sequence field for one write: DDS serialises them and must not free them.
template <class Seq, class T>
void lend(Seq& seq, const std::vector<T>& v) {
  seq._buffer = const_cast<T*>(v.data());
  seq._length = seq._maximum = static_cast<std::uint32_t>(v.size());
  seq._release = false;
}

// Copies a std::string into a bounded char[N] field, cut at a whole character with "..." when it does not fit
// (ladder::cut_text).
template <std::size_t N>
void copy_text(char (&dst)[N], const std::string& src) {
  static_assert(N > 4);
  const std::string fits = src.size() < N ? std::string() : ladder::cut_text(src, N - 1);
  const std::string& text = src.size() < N ? src : fits;
  std::copy(text.begin(), text.end(), dst);
  dst[text.size()] = '\0';
}
// A bounded char[N] field as a string (never reads past the field, even without a terminator).
template <std::size_t N>
std::string text_of(const char (&src)[N]) {
  std::size_t n = 0;
  while (n < N && src[n] != '\0') ++n;
  return std::string(src, n);
}

// printable(text): text from a peer made safe for a log line or a terminal (ladder/printable.hpp).
using ladder::printable;
using ladder::printable_lines;

}  // namespace ladder::transport
