#include "transport/lcm_decode.hpp"

#include <bit>
#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <stdexcept>
#include <type_traits>
#include <vector>

namespace ladder::transport {

namespace {

// What a decoder found wrong; caught in decode_lcm and returned as text (never thrown out of this file).
struct Bad : std::runtime_error {
  using std::runtime_error::runtime_error;
};

std::string hex(std::int64_t v) {
  char buf[24];
  std::snprintf(buf, sizeof buf, "0x%016" PRIx64, static_cast<std::uint64_t>(v));
  return buf;
}

// Reads LCM's encoding (big-endian integers, doubles as their bits, booleans as one byte, strings as an int32
// length that counts a closing NUL, then the bytes) and refuses anything that does not fit before it allocates.
class Cursor {
 public:
  explicit Cursor(std::span<const std::uint8_t> data) : data_(data) {}

  std::size_t left() const { return data_.size() - at_; }

  template <class T>
  T integer(const char* field) {
    static_assert(std::is_integral_v<T>);
    need(sizeof(T), field);
    std::uint64_t v = 0;
    for (std::size_t i = 0; i < sizeof(T); ++i) v = (v << 8) | data_[at_ + i];
    at_ += sizeof(T);
    return static_cast<T>(static_cast<std::make_unsigned_t<T>>(v));  // two's complement, as LCM writes it
  }
  double real(const char* field) { return std::bit_cast<double>(integer<std::uint64_t>(field)); }
  std::int8_t boolean(const char* field) {
    const auto v = integer<std::int8_t>(field);
    if (v != 0 && v != 1) throw Bad(std::string(field) + " = " + std::to_string(v) + " is not a boolean (0 or 1)");
    return v;
  }
  std::string text(const char* field, std::size_t max) {
    const auto n = integer<std::int32_t>(field);
    if (n < 1)  // the length counts the closing NUL: even an empty string has 1
      throw Bad("string " + std::string(field) + " has length " + std::to_string(n) + " (at least 1)");
    const auto len = static_cast<std::size_t>(n);
    if (len - 1 > max)
      throw Bad("string " + std::string(field) + " of " + std::to_string(len - 1) + " bytes is longer than " +
                std::to_string(max) + " (the most a log's " + field + " may hold)");
    need(len, field);
    const char* p = reinterpret_cast<const char*>(data_.data() + at_);
    if (p[len - 1] != 0) throw Bad("string " + std::string(field) + " does not end with a NUL");
    // lcm-gen's encoder writes C strings: a NUL inside one is not something it writes (and would cut it short).
    if (std::memchr(p, 0, len - 1)) throw Bad("string " + std::string(field) + " has a NUL inside it");
    std::string s(p, len - 1);
    at_ += len;
    return s;
  }
  // A count read from the data: not negative, at most `max`, and at least `min_bytes_each` bytes per element left.
  std::int32_t count(const char* field, std::int32_t max, const char* max_why, std::size_t min_bytes_each) {
    const auto n = integer<std::int32_t>(field);
    if (n < 0) throw Bad(std::string(field) + " = " + std::to_string(n) + " is negative");
    if (n > max)
      throw Bad(std::string(field) + " = " + std::to_string(n) + " is more than " + std::to_string(max) + " (" +
                max_why + ")");
    const auto need_bytes = static_cast<std::uint64_t>(n) * min_bytes_each;  // n <= 2^31, each <= 64: no overflow
    if (need_bytes > left())
      throw Bad(std::string(field) + " = " + std::to_string(n) + " needs " + std::to_string(need_bytes) +
                " bytes, but " + std::to_string(left()) + " remain");
    return n;
  }
  template <class T>
  void array(const char* field, std::vector<T>& out, std::int32_t n) {
    const std::size_t bytes = static_cast<std::size_t>(n) * sizeof(T);  // the caller's count() bounds n
    need(bytes, field);
    out.resize(static_cast<std::size_t>(n));
    // One check for the whole array, then a plain loop (a state of 10 000 blocks is 60 000 values).
    using U = std::conditional_t<sizeof(T) == 8, std::uint64_t,
                                 std::conditional_t<sizeof(T) == 4, std::uint32_t, std::uint8_t>>;
    const std::uint8_t* p = data_.data() + at_;
    for (T& v : out) {
      U u = 0;
      for (std::size_t i = 0; i < sizeof(T); ++i) u = static_cast<U>((u << 8) | p[i]);
      v = std::bit_cast<T>(u);
      p += sizeof(T);
    }
    at_ += bytes;
  }
  void fingerprint(std::int64_t expected, const char* type) {
    const auto h = integer<std::int64_t>("fingerprint");
    if (h != expected)
      throw Bad("its fingerprint " + hex(h) + " is not " + type + "'s (" + hex(expected) + "): not a " + type);
  }
  void end(const char* type) const {
    if (left() != 0)
      throw Bad(std::to_string(left()) + " byte(s) left over after a complete " + type + " (" +
                std::to_string(data_.size()) + " bytes)");
  }

 private:
  void need(std::size_t n, const char* field) const {
    if (n > left())
      throw Bad(std::string(field) + " needs " + std::to_string(n) + " byte(s), but " + std::to_string(left()) +
                " remain (the data is cut short)");
  }
  std::span<const std::uint8_t> data_;
  std::size_t at_ = 0;
};

constexpr const char* kBlocksWhy = "the most blocks a scene may have";

void read(Cursor& c, ladderlcm::scene_t& m) {
  m.utime = c.integer<std::int64_t>("utime");
  m.sim_id = c.text("sim_id", kLogMaxText);
  m.generation = c.integer<std::int32_t>("generation");
  m.name = c.text("name", kLogMaxText);
  m.source = c.text("source", kLogMaxText);
  m.toml = c.text("toml", kLogMaxSceneText);
  m.num_overrides = c.count("num_overrides", kLogMaxOverrides, "the most overrides a log may hold", 5);
  m.overrides.clear();
  m.overrides.reserve(static_cast<std::size_t>(m.num_overrides));
  for (std::int32_t i = 0; i < m.num_overrides; ++i) m.overrides.push_back(c.text("overrides", kLogMaxSceneText));
  m.clear_timeline = c.boolean("clear_timeline");
  // blocks counts the masses, which come after five more fields: 8 bytes each at least.
  m.blocks = c.count("blocks", kLogMaxBlocks, kBlocksWhy, 8);
  m.length = c.real("length");
  m.thickness = c.real("thickness");
  m.hinge_inset = c.real("hinge_inset");
  m.dt = c.real("dt");
  m.top = c.text("top", kLogMaxText);
  c.array("masses", m.masses, m.blocks);
  m.server_version = c.text("server_version", kLogMaxText);
}

void read(Cursor& c, ladderlcm::state_t& m) {
  m.utime = c.integer<std::int64_t>("utime");
  m.generation = c.integer<std::int32_t>("generation");
  m.seq = c.integer<std::int64_t>("seq");
  m.step = c.integer<std::int64_t>("step");
  m.sim_time = c.real("sim_time");
  m.paused = c.boolean("paused");
  m.commands_applied = c.integer<std::int64_t>("commands_applied");
  m.energy = c.real("energy");
  // Per block: x, y, theta (8 bytes each), corner, status (1 each), flips (4).
  m.num_blocks = c.count("num_blocks", kLogMaxBlocks, kBlocksWhy, 3 * 8 + 1 + 1 + 4);
  c.array("x", m.x, m.num_blocks);
  c.array("y", m.y, m.num_blocks);
  c.array("theta", m.theta, m.num_blocks);
  c.array("corner", m.corner, m.num_blocks);
  c.array("status", m.status, m.num_blocks);
  c.array("flips", m.flips, m.num_blocks);
}

void read(Cursor& c, ladderlcm::command_t& m) {
  m.utime = c.integer<std::int64_t>("utime");
  m.generation = c.integer<std::int32_t>("generation");
  m.step = c.integer<std::int64_t>("step");
  m.command_seq = c.integer<std::int64_t>("command_seq");
  m.client_id = c.text("client_id", kLogMaxText);
  m.command_id = c.integer<std::int64_t>("command_id");
  m.kind = c.integer<std::int32_t>("kind");
  m.block = c.integer<std::int32_t>("block");
  m.hinge = c.integer<std::int32_t>("hinge");
  m.count = c.integer<std::int32_t>("count");
  m.has_point = c.boolean("has_point");
  m.has_target = c.boolean("has_target");
  m.has_angle = c.boolean("has_angle");
  m.a = c.real("a"), m.b = c.real("b"), m.c = c.real("c");
  m.d = c.real("d"), m.e = c.real("e"), m.f = c.real("f");
  m.text = c.text("text", kLogMaxText);
  m.accepted = c.boolean("accepted");
  m.reason = c.text("reason", kLogMaxText);
}

void read(Cursor& c, ladderlcm::event_t& m) {
  m.utime = c.integer<std::int64_t>("utime");
  m.seq = c.integer<std::int64_t>("seq");
  m.t = c.real("t");
  m.kind = c.text("kind", kLogMaxText);
  m.hinge = c.integer<std::int32_t>("hinge");
  m.energy_removed = c.real("energy_removed");
  m.detail = c.text("detail", kLogMaxText);
}

void read(Cursor& c, ladderlcm::checkpoint_t& m) {
  m.utime = c.integer<std::int64_t>("utime");
  m.generation = c.integer<std::int32_t>("generation");
  m.step = c.integer<std::int64_t>("step");
  m.sim_time = c.real("sim_time");
  m.commands_applied = c.integer<std::int64_t>("commands_applied");
  m.state_hash = c.integer<std::int64_t>("state_hash");
}

template <class T>
std::string decode_any(std::span<const std::uint8_t> data, T& out) {
  try {
    Cursor c(data);
    c.fingerprint(T::getHash(), T::getTypeName());
    read(c, out);
    c.end(T::getTypeName());
  } catch (const Bad& e) {
    return e.what();
  } catch (const std::bad_alloc&) {  // within the maxima, but this machine has not the memory
    return "out of memory decoding it";
  }
  return check_record(out);
}

// The value checks: each returns "" or what is wrong.
std::string not_negative(const char* field, std::int64_t v) {
  return v < 0 ? std::string(field) + " = " + std::to_string(v) + " is negative" : "";
}
// A count not negative and at most `most`, which `why` explains.
std::string at_most(const char* field, std::int64_t v, std::int64_t most, const char* why) {
  if (v < 0) return not_negative(field, v);
  if (v > most) return std::string(field) + " = " + std::to_string(v) + " is beyond " + std::to_string(most) + why;
  return {};
}
std::string a_step(const char* field, std::int64_t v) {
  return at_most(field, v, kLogMaxStep, " (the most steps of a scene: 1e7 s at dt = 1e-7 s)");
}
// A count of commands (command_seq, commands_applied): a server that took one every microsecond for
// kLogMaxSimTime would not reach kLogMaxCommands. (A log's 2^63 - 1 made a resumed server count on from it.)
std::string a_count(const char* field, std::int64_t v) {
  return at_most(field, v, kLogMaxCommands, " (more commands than a server takes)");
}
std::string a_time(const char* field, double t) {
  char buf[160];
  if (!std::isfinite(t) || t < 0 || t > kLogMaxSimTime) {
    std::snprintf(buf, sizeof buf, "%s = %g is not a time in 0 .. %g s", field, t, kLogMaxSimTime);
    return buf;
  }
  return {};
}
std::string finite(const char* field, double v) {
  return std::isfinite(v) ? "" : std::string(field) + " is " + (std::isnan(v) ? "NaN" : "infinite");
}
std::string finite_all(const char* field, const std::vector<double>& v) {
  for (std::size_t i = 0; i < v.size(); ++i)
    if (!std::isfinite(v[i])) return finite((std::string(field) + "[" + std::to_string(i) + "]").c_str(), v[i]);
  return {};
}
// The first non-empty of the checks.
std::string first(std::initializer_list<std::string> checks) {
  for (const std::string& c : checks)
    if (!c.empty()) return c;
  return {};
}

}  // namespace

std::string check_record(const ladderlcm::scene_t& m) {
  char masses[96] = "";
  for (std::size_t i = 0; i < m.masses.size() && !masses[0]; ++i)
    if (!(m.masses[i] > 0) || !std::isfinite(m.masses[i]))
      std::snprintf(masses, sizeof masses, "masses[%zu] = %g is not a mass (finite, > 0)", i, m.masses[i]);
  char dt[96] = "";
  if (!(m.dt >= kLogMinDt && m.dt <= kLogMaxDt))
    std::snprintf(dt, sizeof dt, "dt = %g s is outside sim.dt's range %g .. %g s", m.dt, kLogMinDt, kLogMaxDt);
  return first({not_negative("generation", m.generation), m.blocks >= 1 ? "" : "blocks = 0 (at least 1)",
                finite("length", m.length), finite("thickness", m.thickness), finite("hinge_inset", m.hinge_inset),
                dt, masses});
}

std::string check_record(const ladderlcm::state_t& m) {
  return first({not_negative("generation", m.generation), not_negative("seq", m.seq), a_step("step", m.step),
                a_time("sim_time", m.sim_time), a_count("commands_applied", m.commands_applied),
                finite("energy", m.energy), finite_all("x", m.x), finite_all("y", m.y),
                finite_all("theta", m.theta)});
}

std::string check_record(const ladderlcm::command_t& m) {
  std::string params;
  // A refused command may carry anything (a NaN force is refused, and logged as sent); an accepted one was applied.
  if (m.accepted) {
    const double p[6] = {m.a, m.b, m.c, m.d, m.e, m.f};
    static const char* kName[6] = {"a", "b", "c", "d", "e", "f"};
    for (int i = 0; i < 6 && params.empty(); ++i) params = finite(kName[i], p[i]);
    if (!params.empty()) params = "accepted, but its parameter " + params;
  }
  return first({not_negative("generation", m.generation), a_step("step", m.step),
                m.command_seq >= 1 ? a_count("command_seq", m.command_seq)
                                   : "command_seq = " + std::to_string(m.command_seq) + " (they start at 1)",
                params});
}

std::string check_record(const ladderlcm::event_t& m) {
  return first({finite("t", m.t), finite("energy_removed", m.energy_removed)});
}

std::string check_record(const ladderlcm::checkpoint_t& m) {
  return first({not_negative("generation", m.generation), a_step("step", m.step), a_time("sim_time", m.sim_time),
                a_count("commands_applied", m.commands_applied)});
}

std::string decode_lcm(std::span<const std::uint8_t> d, ladderlcm::scene_t& out) { return decode_any(d, out); }
std::string decode_lcm(std::span<const std::uint8_t> d, ladderlcm::state_t& out) { return decode_any(d, out); }
std::string decode_lcm(std::span<const std::uint8_t> d, ladderlcm::command_t& out) { return decode_any(d, out); }
std::string decode_lcm(std::span<const std::uint8_t> d, ladderlcm::event_t& out) { return decode_any(d, out); }
std::string decode_lcm(std::span<const std::uint8_t> d, ladderlcm::checkpoint_t& out) { return decode_any(d, out); }

}  // namespace ladder::transport
