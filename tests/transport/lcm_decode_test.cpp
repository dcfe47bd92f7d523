// Our decoders of the session log's LCM types against lcm-gen's encoders (round trips, and every accepted input is
// exactly what the encoder writes) and against crafted bytes (each count, length and value refused with its name);
// then the checks across the records of a whole log (read_session_log_bytes), on logs made in memory.
#include "daemon/resimulate.hpp"
#include "transport/lcm_decode.hpp"
#include "transport/lcm_log.hpp"

#include <gtest/gtest.h>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <bit>
#include <cstring>
#include <cmath>
#include <limits>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <memory>
#include <random>
#include <thread>

namespace ladder::test {
namespace {

using Bytes = std::vector<std::uint8_t>;

template <class T>
Bytes encode(const T& m) {
  Bytes b(static_cast<std::size_t>(m.getEncodedSize()));
  EXPECT_EQ(m.encode(b.data(), 0, static_cast<int>(b.size())), static_cast<int>(b.size()));
  return b;
}
template <class T>
std::string decode(const Bytes& b) {
  T m;
  return transport::decode_lcm(b, m);
}
void put(Bytes& b, std::size_t at, std::uint64_t v, int bytes) {
  for (int i = bytes - 1; i >= 0; --i, v >>= 8) b.at(at + static_cast<std::size_t>(i)) = v & 0xFF;
}
bool has(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

ladderlcm::scene_t a_scene(int blocks = 3, int generation = 0, double dt = 0.001) {
  ladderlcm::scene_t s;
  s.utime = 1'700'000'000'000'000;
  s.sim_id = "ladder";
  s.generation = generation;
  s.name = "classic";
  s.source = "config/scenes/classic.toml";
  s.toml = "[ladder]\nblocks = " + std::to_string(blocks) + "\n";
  s.overrides = {"sim.dt=0.001", "damping.linear=0.2"};
  s.num_overrides = 2;
  s.clear_timeline = true;
  s.blocks = blocks;
  s.length = 0.08, s.thickness = 0.004, s.hinge_inset = 0.002, s.dt = dt;
  s.top = "held";
  s.masses.assign(static_cast<std::size_t>(blocks), 0.025);
  s.server_version = "0.1.0";
  return s;
}
ladderlcm::state_t a_state(int blocks = 3, std::int64_t step = 10, double t = 0.01, int generation = 0) {
  ladderlcm::state_t s;
  s.utime = 1'700'000'000'000'000;
  s.generation = generation;
  s.seq = 4;
  s.step = step;
  s.sim_time = t;
  s.paused = 0;
  s.commands_applied = 0;
  s.energy = -0.5;
  s.num_blocks = blocks;
  for (int i = 0; i < blocks; ++i) {
    s.x.push_back(0.001 * i), s.y.push_back(-0.08 * i), s.theta.push_back(0.1 * i);
    s.corner.push_back(static_cast<std::int8_t>(i % 4)), s.status.push_back(0), s.flips.push_back(i);
  }
  return s;
}
ladderlcm::command_t a_command(std::int64_t seq = 1, std::int64_t step = 5) {
  ladderlcm::command_t c;
  c.utime = 1'700'000'000'000'000;
  c.generation = 0;
  c.step = step;
  c.command_seq = seq;
  c.client_id = "test";
  c.command_id = 7;
  c.kind = 1, c.block = 2, c.hinge = -1, c.count = 0;
  c.has_point = 1, c.has_target = 0, c.has_angle = 0;
  c.a = 0.002, c.b = 0, c.c = 0.01, c.d = 0, c.e = 0, c.f = 0;
  c.text = "";
  c.accepted = 1;
  c.reason = "";
  return c;
}
ladderlcm::event_t an_event() {
  ladderlcm::event_t e;
  e.utime = 1;
  e.seq = 1;
  e.t = 0.5;
  e.kind = "flip_flop";
  e.hinge = 2;
  e.energy_removed = 0.001;
  e.detail = "hinge 2 flipped to corner 1";
  return e;
}
ladderlcm::checkpoint_t a_checkpoint(std::int64_t step = 0, double t = 0, int generation = 0) {
  ladderlcm::checkpoint_t c;
  c.utime = 1;
  c.generation = generation;
  c.step = step;
  c.sim_time = t;
  c.commands_applied = 0;
  c.state_hash = -42;
  return c;
}

// A failed step's record (LADDER_FAILURE): a checkpoint_t on a channel of its own.
struct FailureRecord : ladderlcm::checkpoint_t {};
FailureRecord a_failure(std::int64_t step, double t) {
  FailureRecord f;
  static_cast<ladderlcm::checkpoint_t&>(f) = a_checkpoint(step, t);
  return f;
}

// Decoded and encoded again, a message gives back the same bytes: every field read as written.
template <class T>
void round_trip(const T& m) {
  const Bytes b = encode(m);
  T out;
  ASSERT_EQ(transport::decode_lcm(b, out), "") << T::getTypeName();
  EXPECT_EQ(encode(out), b) << T::getTypeName();
}

TEST(LcmDecode, EveryTypeRoundTripsThroughLcmGensEncoder) {
  round_trip(a_scene());
  round_trip(a_scene(1));
  round_trip(a_state());
  round_trip(a_state(0));
  round_trip(a_command());
  round_trip(an_event());
  round_trip(a_checkpoint(1000, 1.0));
  ladderlcm::command_t refused = a_command();
  refused.accepted = 0;
  refused.a = std::nan("");  // a refused command is logged as it came
  refused.reason = "impulse: must be finite";
  round_trip(refused);
  // An override may be as long as a scene's text (`--set ladder.masses=[...]` of 10 000 blocks is about 80 KB; one
  // over 64 KiB was refused, the log with it), a name only as long as every other text.
  ladderlcm::scene_t masses = a_scene();
  masses.overrides = {"ladder.masses=[" + std::string(70'000, '1') + "]"};
  masses.num_overrides = 1;
  round_trip(masses);
  ladderlcm::scene_t named = a_scene();
  named.name = std::string(70'000, 'n');
  ladderlcm::scene_t out;
  EXPECT_EQ(transport::decode_lcm(encode(named), out),
            "string name of 70000 bytes is longer than 65536 (the most a log's name may hold)");
}

// Cut short anywhere, or with a byte too many, no message decodes; the message names what is missing.
template <class T>
void refuses_every_cut(const T& m) {
  const Bytes b = encode(m);
  for (std::size_t n = 0; n < b.size(); ++n) {
    const std::string why = decode<T>(Bytes(b.begin(), b.begin() + static_cast<std::ptrdiff_t>(n)));
    EXPECT_FALSE(why.empty()) << T::getTypeName() << " cut to " << n << " bytes";
  }
  Bytes longer = b;
  longer.push_back(0);
  EXPECT_EQ(decode<T>(longer), "1 byte(s) left over after a complete " + std::string(T::getTypeName()) + " (" +
                                   std::to_string(longer.size()) + " bytes)");
}

TEST(LcmDecode, EveryCutAndEveryExtraByteIsRefused) {
  refuses_every_cut(a_scene());
  refuses_every_cut(a_state());
  refuses_every_cut(a_command());
  refuses_every_cut(an_event());
  refuses_every_cut(a_checkpoint());
  const Bytes b = encode(a_state());
  EXPECT_EQ(decode<ladderlcm::state_t>(Bytes(b.begin(), b.begin() + 20)),
            "seq needs 8 byte(s), but 0 remain (the data is cut short)");
}

// Offsets in an encoded state_t: fingerprint 8, utime 8, generation 4, seq 8, step 8, sim_time 8, paused 1,
// commands_applied 8, energy 8, num_blocks 4, then the arrays.
constexpr std::size_t kStep = 28, kTime = 36, kPaused = 44, kNumBlocks = 61;

TEST(LcmDecode, CountsAreCheckedAgainstTheirMaximumAndTheBytesLeftBeforeAnyAllocation) {
  Bytes b = encode(a_state());
  put(b, kNumBlocks, (1u << 28) + 1, 4);  // lcm_coretypes.h's int total_size = 8 * 268435457 overflows
  EXPECT_EQ(decode<ladderlcm::state_t>(b),
            "num_blocks = 268435457 is more than 1000000 (the most blocks a scene may have)");
  put(b, kNumBlocks, 0xFFFFFFFF, 4);
  EXPECT_EQ(decode<ladderlcm::state_t>(b), "num_blocks = -1 is negative");
  put(b, kNumBlocks, 1000, 4);  // three blocks' worth of data follows
  EXPECT_EQ(decode<ladderlcm::state_t>(b), "num_blocks = 1000 needs 30000 bytes, but 90 remain");

  // scene_t: blocks (masses) and num_overrides, and the strings.
  const ladderlcm::scene_t s = a_scene();
  const Bytes sb = encode(s);
  // Where num_overrides lies: after the fingerprint, utime, sim_id, generation, name, source and toml.
  const std::size_t strings = 4 + s.sim_id.size() + 1 + 4 + s.name.size() + 1 + 4 + s.source.size() + 1 + 4 +
                              s.toml.size() + 1;
  const std::size_t overrides = 8 + 8 + 4 + strings;
  Bytes bad = sb;
  put(bad, overrides, (1u << 28) + 1, 4);
  EXPECT_EQ(decode<ladderlcm::scene_t>(bad),
            "num_overrides = 268435457 is more than 10000 (the most overrides a log may hold)");
  put(bad, overrides, 9000, 4);
  EXPECT_TRUE(has(decode<ladderlcm::scene_t>(bad), "num_overrides = 9000 needs 45000 bytes, but "))
      << decode<ladderlcm::scene_t>(bad);
  // blocks: after the overrides and clear_timeline.
  std::size_t at = overrides + 4;
  for (const std::string& o : s.overrides) at += 4 + o.size() + 1;
  bad = sb;
  put(bad, at + 1, (1u << 28) + 1, 4);
  EXPECT_EQ(decode<ladderlcm::scene_t>(bad),
            "blocks = 268435457 is more than 1000000 (the most blocks a scene may have)");

  // A string's length: its maximum, at least 1 (the closing NUL), the bytes left, the NUL itself.
  const std::size_t sim_id = 16;  // the fingerprint and utime before it
  bad = sb;
  put(bad, sim_id, 0x7FFFFFFF, 4);
  EXPECT_EQ(decode<ladderlcm::scene_t>(bad),
            "string sim_id of 2147483646 bytes is longer than 65536 (the most a log's sim_id may hold)");
  put(bad, sim_id, 0, 4);
  EXPECT_EQ(decode<ladderlcm::scene_t>(bad), "string sim_id has length 0 (at least 1)");
  put(bad, sim_id, 60000, 4);
  EXPECT_TRUE(has(decode<ladderlcm::scene_t>(bad), "sim_id needs 60000 byte(s), but "))
      << decode<ladderlcm::scene_t>(bad);
  bad = sb;
  bad[sim_id + 4 + s.sim_id.size()] = 'x';  // where the NUL was
  EXPECT_EQ(decode<ladderlcm::scene_t>(bad), "string sim_id does not end with a NUL");
}

TEST(LcmDecode, TheFingerprintBooleansAndValuesAreChecked) {
  Bytes b = encode(a_state());
  EXPECT_TRUE(has(decode<ladderlcm::scene_t>(b), "is not scene_t's")) << decode<ladderlcm::scene_t>(b);
  const Bytes all7f(b.size(), 0x7f);
  EXPECT_EQ(decode<ladderlcm::state_t>(all7f).substr(0, 41), "its fingerprint 0x7f7f7f7f7f7f7f7f is not");
  Bytes rest7f = b;
  std::fill(rest7f.begin() + 8, rest7f.end(), 0x7f);
  EXPECT_EQ(decode<ladderlcm::state_t>(rest7f), "paused = 127 is not a boolean (0 or 1)");
  b[kPaused] = 2;
  EXPECT_EQ(decode<ladderlcm::state_t>(b), "paused = 2 is not a boolean (0 or 1)");

  ladderlcm::state_t s = a_state();
  s.step = std::int64_t{1} << 62;
  EXPECT_EQ(decode<ladderlcm::state_t>(encode(s)),
            "step = 4611686018427387904 is beyond 100000000000000 (the most steps of a scene: 1e7 s at dt = 1e-7 s)");
  s = a_state();
  s.sim_time = INFINITY;
  EXPECT_EQ(decode<ladderlcm::state_t>(encode(s)), "sim_time = inf is not a time in 0 .. 1e+07 s");
  s = a_state();
  s.x[2] = std::nan("");
  EXPECT_EQ(decode<ladderlcm::state_t>(encode(s)), "x[2] is NaN");
  s = a_state();
  s.generation = -1;
  EXPECT_EQ(decode<ladderlcm::state_t>(encode(s)), "generation = -1 is negative");

  ladderlcm::scene_t sc = a_scene();
  sc.dt = 0;
  EXPECT_EQ(decode<ladderlcm::scene_t>(encode(sc)), "dt = 0 s is outside sim.dt's range 1e-07 .. 0.1 s");
  sc = a_scene();
  sc.masses[1] = -1;
  EXPECT_EQ(decode<ladderlcm::scene_t>(encode(sc)), "masses[1] = -1 is not a mass (finite, > 0)");

  ladderlcm::command_t c = a_command();
  c.b = INFINITY;
  EXPECT_EQ(decode<ladderlcm::command_t>(encode(c)), "accepted, but its parameter b is infinite");
  c = a_command(0);
  EXPECT_EQ(decode<ladderlcm::command_t>(encode(c)), "command_seq = 0 (they start at 1)");
  c = a_command(std::numeric_limits<std::int64_t>::max());  // (a resumed server counted on from it)
  EXPECT_EQ(decode<ladderlcm::command_t>(encode(c)),
            "command_seq = 9223372036854775807 is beyond 1000000000000000 (more commands than a server takes)");
  ladderlcm::state_t st = a_state();
  st.commands_applied = 1'000'000'000'000'001;
  EXPECT_EQ(decode<ladderlcm::state_t>(encode(st)),
            "commands_applied = 1000000000000001 is beyond 1000000000000000 (more commands than a server takes)");
  ladderlcm::checkpoint_t k = a_checkpoint();
  k.step = -5;
  EXPECT_EQ(decode<ladderlcm::checkpoint_t>(encode(k)), "step = -5 is negative");
  ladderlcm::event_t e = an_event();
  e.energy_removed = std::nan("");
  EXPECT_EQ(decode<ladderlcm::event_t>(encode(e)), "energy_removed is NaN");
  Bytes t = encode(a_state());
  put(t, kTime, std::bit_cast<std::uint64_t>(-1.0), 8);
  EXPECT_EQ(decode<ladderlcm::state_t>(t), "sim_time = -1 is not a time in 0 .. 1e+07 s");
  put(t, kStep, 0, 8);  // (the first problem found is the one named)
}

// Random damage (a few bytes overwritten, or a count made large): never a crash, and whatever is accepted is
// exactly what lcm-gen's encoder writes for the decoded message (nothing skipped, nothing read twice).
template <class T>
void survives_damage(const T& m, std::mt19937& rng, int& accepted) {
  const Bytes b = encode(m);
  for (int trial = 0; trial < 3000; ++trial) {
    Bytes d = b;
    const int flips = 1 + static_cast<int>(rng() % 4);
    for (int k = 0; k < flips; ++k) d[rng() % d.size()] = static_cast<std::uint8_t>(rng());
    T out;
    if (transport::decode_lcm(d, out).empty()) {
      ++accepted;
      EXPECT_EQ(encode(out), d) << T::getTypeName() << " trial " << trial;
    }
  }
}

TEST(LcmDecode, RandomDamageNeverCrashesAndWhatIsAcceptedIsCanonical) {
  std::mt19937 rng(18);
  int accepted = 0;
  survives_damage(a_scene(), rng, accepted);
  survives_damage(a_state(), rng, accepted);
  survives_damage(a_command(), rng, accepted);
  survives_damage(an_event(), rng, accepted);
  survives_damage(a_checkpoint(), rng, accepted);
  EXPECT_GT(accepted, 100);  // damage to values (a coordinate's low bits) is not detectable, and is accepted
}

// Logs made in memory: a file written by LogWriter, read back as bytes.
class LogBytes : public ::testing::Test {
 protected:
  void SetUp() override {
    path_ = (std::filesystem::temp_directory_path() /
             ("ladder-lcm-decode-" + std::to_string(getpid()) + "-" +
              ::testing::UnitTest::GetInstance()->current_test_info()->name() + ".lcmlog"))
                .string();
  }
  void TearDown() override {
    std::filesystem::remove(path_);
    std::filesystem::remove(path_ + ".fifo");
  }
  // Writes the events and returns the file's bytes.
  template <class... Ts>
  Bytes log(const Ts&... records) {
    {
      transport::LogWriter w(path_);
      (w.write(channel(records), 1, records, false), ...);
    }
    std::ifstream in(path_, std::ios::binary);
    return Bytes(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  // What read_session_log_bytes says: "" when it reads the log.
  std::string read(const Bytes& b) {
    try {
      daemon::read_session_log_bytes(b, "mem.lcmlog");
    } catch (const std::exception& e) {
      return e.what();
    }
    return {};
  }
  static const char* channel(const ladderlcm::scene_t&) { return transport::kSceneChannel; }
  static const char* channel(const ladderlcm::state_t&) { return transport::kStateChannel; }
  static const char* channel(const ladderlcm::command_t&) { return transport::kCommandChannel; }
  static const char* channel(const ladderlcm::event_t&) { return transport::kEventChannel; }
  static const char* channel(const ladderlcm::checkpoint_t&) { return transport::kCheckpointChannel; }
  static const char* channel(const FailureRecord&) { return transport::kFailureChannel; }
  std::string path_;
};

TEST_F(LogBytes, ABadEventIsNamedByItsNumberChannelAndOffset) {
  const Bytes good = log(a_scene(), a_checkpoint(), a_state());
  EXPECT_EQ(read(good), "");
  ladderlcm::state_t s = a_state();
  s.paused = 3;
  const Bytes bad = log(a_scene(), a_checkpoint(), s);
  const std::size_t offset = good.size() - encode(a_state()).size() - 28 - std::strlen(transport::kStateChannel);
  EXPECT_EQ(read(bad), "mem.lcmlog: event 3 (LADDER_STATE at byte " + std::to_string(offset) +
                           ") is not a valid state_t: paused = 3 is not a boolean (0 or 1)");
  // The reader on bytes, as a fuzzer calls it.
  transport::LogReader r(bad, "mem");
  std::size_t events = 0;
  while (auto e = r.next()) ++events;
  EXPECT_EQ(events, 3u);
  EXPECT_THROW(transport::LogReader(Bytes{1, 2, 3}, "junk"), std::runtime_error);
}

TEST_F(LogBytes, RecordsAreCheckedAgainstEachOther) {
  const std::string blocks = read(log(a_scene(), a_checkpoint(), a_state(4)));
  EXPECT_TRUE(has(blocks, "mem.lcmlog: event 3 (LADDER_STATE at byte ")) << blocks;
  EXPECT_TRUE(has(blocks, "): a state of 4 blocks in a scene of 3")) << blocks;
  EXPECT_TRUE(has(read(log(a_scene(), a_checkpoint(), a_state(3, 10, 0.01, 1))),
                  "a state of generation 1, which no scene record starts"));
  EXPECT_TRUE(has(read(log(a_scene(3, 1))), "the first scene record has generation 1 (a log starts at 0)"));
  // Its step does not fit its time at dt = 1 ms.
  EXPECT_TRUE(has(read(log(a_scene(), a_checkpoint(), a_state(3, 10, 5.0))),
                  "a state at generation 0, step 10 with t = 5 s: 10 steps of dt = 0.001 .. 0.001 s take 0.01 .. "
                  "0.01 s"));
  // Its time fits, but no checkpoint lies within 2.1 s (2102 steps) before it; with one at step 2000 it is fine.
  EXPECT_TRUE(has(read(log(a_scene(), a_checkpoint(), a_state(3, 3000, 3.0))),
                  "a state at generation 0, step 3000, 3000 steps after the checkpoint before it (step 0)"));
  EXPECT_EQ(read(log(a_scene(), a_checkpoint(), a_checkpoint(2000, 2.0), a_state(3, 3000, 3.0))), "");
  // A live dt change within the generation widens what a time may be.
  EXPECT_EQ(read(log(a_scene(), a_scene(3, 0, 0.002), a_checkpoint(), a_state(3, 1000, 1.5))), "");
  // Commands in increasing command_seq, each within reach of a checkpoint.
  EXPECT_EQ(read(log(a_scene(), a_checkpoint(), a_command(1), a_command(2))), "");
  EXPECT_TRUE(has(read(log(a_scene(), a_checkpoint(), a_command(2), a_command(2))),
                  "command_seq 2 after 2 (the server logs them in increasing order)"));
  EXPECT_TRUE(has(read(log(a_scene(), a_checkpoint(), a_command(1, 1'000'000))),
                  "a command at generation 0, step 1000000, 1000000 steps after the checkpoint"));
  // A kind beyond the enum (a command that cannot come over DDS) is refused before the enum holds it.
  ladderlcm::command_t k = a_command(1);
  k.kind = 99;
  EXPECT_TRUE(has(read(log(a_scene(), a_checkpoint(), k)), "kind 99 is no command kind (0 to 13)"));
  EXPECT_TRUE(has(read(log(an_event())), "no scene record"));
}

// A failed step's time moves on inside the step (to the last piece its watchdog accepted) but its count does not:
// each failure before a record lets the record's time lie a dt further past its step count. Two at one place (the
// server pauses at the first) are refused.
TEST_F(LogBytes, EachFailedStepLetsTheTimeRunAStepFurtherAheadOfTheStepCount) {
  // 30 steps of 1 ms and two failed steps that took 0.9 ms each: 31.8 ms, more than 30 steps and the one to spare.
  EXPECT_TRUE(has(read(log(a_scene(), a_checkpoint(), a_state(3, 30, 0.0318))),
                  "30 steps of dt = 0.001 .. 0.001 s take 0.03 .. 0.03 s"));
  EXPECT_EQ(read(log(a_scene(), a_checkpoint(), a_failure(10, 0.0109), a_failure(20, 0.0209), a_state(3, 30, 0.0318))),
            "");
  // Each failure before it adds a dt to what the state's time may be (32.7 ms: 30 steps, the spare and two); one
  // after it does not.
  EXPECT_EQ(read(log(a_scene(), a_checkpoint(), a_failure(10, 0.0109), a_failure(20, 0.0209), a_state(3, 30, 0.0327))),
            "");
  EXPECT_TRUE(has(read(log(a_scene(), a_checkpoint(), a_failure(10, 0.0109), a_failure(40, 0.0419),
                           a_state(3, 30, 0.0327))),
                  "30 steps of dt = 0.001 .. 0.001 s take 0.03 .. 0.03 s, and 1 failed before it at most 0.001 s"));
  EXPECT_TRUE(has(read(log(a_scene(), a_checkpoint(), a_failure(10, 0.0109), a_failure(10, 0.0109))),
                  "a second failure at generation 0, step 10 with 0 commands taken (the server pauses at the first)"));
}

// A scene record whose text makes another number of blocks than it says: the re-run refuses it before it builds
// the simulation (its states were checked against the number it says).
TEST_F(LogBytes, AReRunRefusesASceneRecordWhoseTextMakesOtherBlocks) {
  ladderlcm::scene_t s = a_scene(4);
  s.toml = "[ladder]\nblocks = 3\n";
  s.masses.assign(4, 0.025);
  const daemon::SessionLog parsed = daemon::read_session_log_bytes(log(s, a_checkpoint()), "mem.lcmlog");
  std::unique_ptr<daemon::Session> session;
  try {
    daemon::resimulate(parsed, session);
    ADD_FAILURE() << "re-run";
  } catch (const std::runtime_error& e) {
    EXPECT_STREQ(e.what(), "the scene record of generation 0 says 4 blocks, but its text makes 3");
  }
  EXPECT_EQ(session, nullptr);
}

// The reader on a file, which it reads a window of 8 MiB at a time: every event as written, one larger than the window
// among them; from a pipe the same; damage in the middle found to go on past the window it was met in; and a file
// cut shorter by another program while it is read (logrotate's copytruncate) ends the log as damage at the last
// whole event still in it, not with SIGBUS (as a mapped file did).
TEST_F(LogBytes, AFileIsReadInWindowsAndOneShortenedWhileItIsReadEndsAsDamage) {
  constexpr std::size_t kMiB = std::size_t{1} << 20;
  std::vector<std::size_t> sizes(24, kMiB);
  sizes[5] = 9 * kMiB + 7;  // larger than the window
  {
    transport::LogWriter w(path_);
    for (std::size_t i = 0; i < sizes.size(); ++i)
      w.write_bytes(transport::kEventChannel, static_cast<std::int64_t>(i),
                    Bytes(sizes[i], static_cast<std::uint8_t>(i)), false);
  }
  const auto read_all = [&](transport::LogReader& r, std::size_t first) {
    std::size_t i = first;
    for (; auto e = r.next(); ++i) {
      EXPECT_EQ(e->channel, transport::kEventChannel);
      EXPECT_EQ(e->utime, static_cast<std::int64_t>(i));
      EXPECT_EQ(e->number, i + 1);
      EXPECT_EQ(e->data, Bytes(sizes[i], static_cast<std::uint8_t>(i))) << "event " << i + 1;
    }
    return i;
  };
  transport::LogReader file(path_);
  EXPECT_EQ(read_all(file, 0), sizes.size());
  EXPECT_EQ(file.damage(), "");

  const std::string fifo = path_ + ".fifo";
  ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
  std::thread feed([&] {
    std::ifstream from(path_, std::ios::binary);
    std::ofstream(fifo, std::ios::binary) << from.rdbuf();
  });
  {
    transport::LogReader pipe(fifo);
    feed.join();
    EXPECT_EQ(read_all(pipe, 0), sizes.size());
    EXPECT_EQ(pipe.damage(), "");
  }
  std::filesystem::remove(fifo);

  // Event k starts at the sum of the ones before, each 28 bytes of header and the channel's name before its data.
  const std::size_t header = 28 + std::strlen(transport::kEventChannel);
  std::vector<std::size_t> start{0};
  for (const std::size_t n : sizes) start.push_back(start.back() + header + n);
  // Damage in the middle: the reader stops there, and finds where the events go on across its windows (the sync
  // word of event 6, the 9 MiB one, is broken: the next event starts 9 MiB on, past the window it stopped in), as on
  // the same bytes in memory.
  const auto set_byte = [&](std::size_t at, char c) {
    std::fstream f(path_, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(static_cast<std::streamoff>(at));
    f.put(c);
  };
  set_byte(start[5], 0x00);
  const std::string damage = "no sync word where an event should start at byte " + std::to_string(start[5]) +
                             ", after 5 complete events, and the log goes on: " +
                             std::to_string(start.back() - start[6]) + " bytes of events from byte " +
                             std::to_string(start[6]) +
                             " on are not read (the log is damaged in the middle, not cut off)";
  transport::LogReader damaged(path_);
  EXPECT_EQ(read_all(damaged, 0), 5u);
  EXPECT_EQ(damaged.damage(), damage);
  std::ifstream in(path_, std::ios::binary);
  transport::LogReader in_memory(Bytes(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()), "mem");
  EXPECT_EQ(read_all(in_memory, 0), 5u);
  EXPECT_EQ(in_memory.damage(), damage);
  set_byte(start[5], static_cast<char>(0xED));

  transport::LogReader cut(path_);
  for (int i = 0; i < 3; ++i) ASSERT_TRUE(cut.next());
  const std::size_t kept = start[14] + 100;  // inside event 15 (the reader's window holds its first 8 MiB now)
  ASSERT_EQ(truncate(path_.c_str(), static_cast<off_t>(kept)), 0);
  EXPECT_EQ(read_all(cut, 3), 14u);
  EXPECT_EQ(cut.damage(),
            "the log file became shorter while it was read (another program cut it), cutting off the event at byte " +
                std::to_string(start[14]) + ", after 14 complete events");
  EXPECT_EQ(cut.damage_after(), 0u);
}

// A re-run reads each state from the log again when it compares it (the log read keeps where its states are, not
// the states): a log that another program cut shorter after it was read is refused at the first state it lost,
// named, and not read past its end. (The states lie 9 MiB apart, so that the first is no longer in the reader's
// window when the re-run comes to it.)
TEST_F(LogBytes, AReRunOfALogCutShorterAfterItWasReadNamesTheStateItLost) {
  {
    transport::LogWriter w(path_);
    w.write(transport::kSceneChannel, 1, a_scene(), false);
    w.write(transport::kStateChannel, 2, a_state(), false);
    w.write_bytes("PADDING", 3, Bytes(std::size_t{9} << 20, 0), false);  // a channel the re-run does not read
    w.write(transport::kStateChannel, 4, a_state(3, 20, 0.02), false);
  }
  const daemon::SessionLog parsed = daemon::read_session_log(path_);
  ASSERT_EQ(parsed.states.size(), 2u);
  EXPECT_EQ(parsed.state(1).theta, a_state().theta);
  EXPECT_EQ(parsed.state(0).x, a_state().x);
  EXPECT_EQ(parsed.states[1].step, 20);
  const std::size_t first = parsed.states[0].offset;
  EXPECT_EQ(first, 28 + std::strlen(transport::kSceneChannel) + encode(a_scene()).size());
  ASSERT_EQ(parsed.state(1).step, 20);  // the reader's window is now at the second state
  ASSERT_EQ(truncate(path_.c_str(), static_cast<off_t>(first + 40)), 0);
  std::unique_ptr<daemon::Session> session;
  try {
    daemon::resimulate(parsed, session);
    ADD_FAILURE() << "re-run";
  } catch (const std::runtime_error& e) {
    EXPECT_EQ(std::string(e.what()), path_ + ": event 2 (LADDER_STATE at byte " + std::to_string(first) +
                                         ") changed since the log was read: the log file became shorter while it "
                                         "was read (another program cut it), cutting off the event");
  }
}

// LogWriter::sync (ladderd's ack waits on it): true once what was queued is written and flushed; on a file that
// takes nothing (a FIFO nobody reads), false after the timeout, then false at once until the writer catches up,
// and true again after.
TEST(LogWriterSync, WaitsForTheFlushAndGivesUpOnceOnAStalledFile) {
  const std::string fifo = (std::filesystem::temp_directory_path() /
                            ("ladder-sync-" + std::to_string(getpid()) + ".fifo")).string();
  ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
  const int rd = open(fifo.c_str(), O_RDONLY | O_NONBLOCK);  // so that the writer's open does not block
  ASSERT_GE(rd, 0);
  auto w = std::make_unique<transport::LogWriter>(fifo);
  w->write_bytes(transport::kEventChannel, 1, Bytes(10, 1), false);
  EXPECT_TRUE(w->sync(std::chrono::seconds(30)));  // 10 bytes fit in the pipe
  w->write_bytes(transport::kEventChannel, 1, Bytes(1 << 20, 2), false);  // 1 MB: more than a pipe holds
  EXPECT_FALSE(w->sync(std::chrono::milliseconds(200)));
  EXPECT_EQ(w->failed_syncs(), 1u);
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_FALSE(w->sync(std::chrono::seconds(60)));  // still behind: no second wait
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(30));
  EXPECT_EQ(w->failed_syncs(), 2u);
  // A reader drains the pipe: the writer catches up, and sync waits (and succeeds) again.
  std::atomic<bool> done{false};
  std::thread drain([&] {
    char buf[65536];
    while (!done)
      if (read(rd, buf, sizeof buf) <= 0) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  });
  bool caught_up = false;
  for (int i = 0; i < 3000 && !caught_up; ++i) {  // up to 30 s
    caught_up = w->sync(std::chrono::milliseconds(10));
    if (!caught_up) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  EXPECT_TRUE(caught_up);
  w->write_bytes(transport::kEventChannel, 1, Bytes(10, 3), false);
  EXPECT_TRUE(w->sync(std::chrono::seconds(30)));
  w.reset();  // its last flush and fsync, still drained
  done = true;
  drain.join();
  close(rd);
  std::filesystem::remove(fifo);
}

}  // namespace
}  // namespace ladder::test
