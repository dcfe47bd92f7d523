// Fuzz target: bytes -> up to 16 decoded ladder_msg_Command, each applied to a daemon::Session on the built-in
// classic scene (ladderd's default) followed by a few physics steps, as the server's loop does. Every field comes
// from the bytes: kinds that name no command, any block and hinge, strings without their terminating NUL, NaN,
// infinities and huge or tiny doubles. After every command and step the quantities ladderd publishes in State
// (sim time, energy, every block's pose, every grip's target and angle) are checked: a non-finite one aborts
// with its name, so that libFuzzer keeps the input. A refused command and a failed step (the session pauses,
// as the server does) are outcomes, not findings.
#include "daemon/builtin_scene.hpp"
#include "daemon/session.hpp"
#include "daemon/wire.hpp"
#include "scene/scene.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <stdexcept>

namespace {

using ladder::daemon::Session;

constexpr int kMaxCommands = 16;
constexpr int kMaxStepsAfter = 4;  // steps after each command (a step command's pending steps are taken so too)
// Steps are taken only while the ladder has at most this many blocks. A loaded long.toml (1000 slats on rolling
// hinges) or a `set ladder.blocks` of thousands costs tens of milliseconds a step under the sanitizers, and once the
// fuzzer had found such a load it spent its time there: 2 200 executions a second at the start of a run, 60 after
// 40 minutes. The load, and every command on the large ladder, are still applied and checked; the 64-slat
// tall.toml and the 1889 toy still step, so the rolling hinge's steps are fuzzed.
constexpr int kMaxBlocksStepped = 64;

// The bytes read front to back, zeros once they run out. A plain layout rather than FuzzedDataProvider (which
// takes numbers from the end), so that make_command_seeds.py can write real commands as seeds.
class Bytes {
 public:
  Bytes(const std::uint8_t* data, std::size_t size) : data_(data), size_(size) {}
  bool empty() const { return at_ == size_; }
  template <class T>
  T take() {
    unsigned char raw[sizeof(T)] = {};
    const std::size_t n = std::min(sizeof(T), size_ - at_);
    std::memcpy(raw, data_ + at_, n);
    at_ += n;
    T v;
    std::memcpy(&v, raw, sizeof(T));  // little-endian, as the seeds are written
    return v;
  }

 private:
  const std::uint8_t* data_;
  std::size_t size_, at_ = 0;
};

// A tag byte, then: < 16 a value that breaks arithmetic more often than random bits do; < 128 an int16 in
// thousandths (where the ladder is: most checks pass); otherwise the next 8 bytes as they are.
double number(Bytes& in) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  static constexpr std::array kSpecial{0.0, std::numeric_limits<double>::quiet_NaN(), kInf, -kInf, -0.0, 1e300,
                                       -1e300, 1e-300, std::numeric_limits<double>::denorm_min(),
                                       std::numeric_limits<double>::max(), 0.5, -1.0, 1.0, 3.14159, 10.0, 100.0};
  const auto tag = in.take<std::uint8_t>();
  if (tag < kSpecial.size()) return kSpecial[tag];
  if (tag < 128) return in.take<std::int16_t>() / 1000.0;
  return in.take<double>();
}

// A bounded DDS string (char[N]): a length (up to N - 1), then that many bytes; when `unterminated`, the rest is
// filled with 'x' and the NUL too, so that nothing in the array ends it.
template <class Length, std::size_t N>
void text(Bytes& in, bool unterminated, char (&out)[N]) {
  const std::size_t n = std::min<std::size_t>(in.take<Length>(), N - 1);
  for (std::size_t i = 0; i < n; ++i) out[i] = static_cast<char>(in.take<std::uint8_t>());
  std::fill(out + n, out + N, unterminated ? 'x' : '\0');
}

// One command: kind, flags, block, hinge, count, id, a..f, sim_id, client_id, text (make_command_seeds.py).
ladder_msg_Command command(Bytes& in) {
  ladder_msg_Command c{};
  // 0..15, the enum's range of values (its enumerators go to 13): 14 and 15 name no kind. No more: Cyclone
  // refuses a Command whose kind exceeds 13 before it is read (the type's ops carry the maximum), and in C++ an
  // enum object holding a value outside 0..15 is undefined behaviour already where it is read.
  c.kind = static_cast<ladder_msg_CommandKind>(in.take<std::uint8_t>() % 16);
  const auto flags = in.take<std::uint8_t>();
  c.has_point = flags & 1, c.has_target = flags & 2, c.has_angle = flags & 4;
  c.block = flags & 8 ? in.take<std::int32_t>() : in.take<std::int8_t>();
  c.hinge = flags & 16 ? in.take<std::int32_t>() : in.take<std::int8_t>();
  c.count = flags & 32 ? in.take<std::uint32_t>() : in.take<std::uint8_t>();
  c.command_id = in.take<std::uint64_t>();
  c.a = number(in), c.b = number(in), c.c = number(in), c.d = number(in), c.e = number(in), c.f = number(in);
  text<std::uint8_t>(in, flags & 128, c.sim_id);
  text<std::uint8_t>(in, flags & 128, c.client_id);
  text<std::uint16_t>(in, flags & 64, c.text);
  return c;
}

void require_finite(double v, const char* what, int index, const ladder_msg_Command& last) {
  if (std::isfinite(v)) return;
  std::fprintf(stderr, "command_fuzz: published %s [%d] = %g after a command of kind %d (block %d, a..f = %g %g %g "
               "%g %g %g, has_point %d has_target %d has_angle %d)\n", what, index, v, static_cast<int>(last.kind),
               last.block, last.a, last.b, last.c, last.d, last.e, last.f, last.has_point, last.has_target,
               last.has_angle);
  std::abort();
}

// What fill_frame (server.cpp) copies into a State.
void check_published(const Session& s, const ladder_msg_Command& last) {
  const ladder::model::Ladder& l = s.sim().ladder();
  require_finite(s.sim().time(), "sim_time", 0, last);
  require_finite(l.energy(), "energy", 0, last);
  for (int i = 0; i < l.blocks(); ++i) {
    ladder::core::Vec2 c;
    double angle = 0;
    l.block_pose(i, c, angle);
    require_finite(c.x(), "pose x", i, last);
    require_finite(c.y(), "pose y", i, last);
    require_finite(angle, "pose angle", i, last);
  }
  for (std::size_t i = 0; i < l.grips().size(); ++i) {
    const auto& g = l.grips()[i];
    require_finite(g.target.x(), "grip target_x", static_cast<int>(i), last);
    require_finite(g.target.y(), "grip target_y", static_cast<int>(i), last);
    require_finite(g.angle, "grip angle", static_cast<int>(i), last);
  }
}

// One tick of the server's loop: a step when running, or one of the pending steps of a step command.
void tick(Session& s) {
  if (s.paused()) {
    if (s.pending_steps() == 0) return;
    s.take_pending_step();
  }
  try {
    s.step();
  } catch (const std::runtime_error&) {  // the step failed: the session paused itself, as ladderd's loop expects
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const ladder::scene::Scene scene =
      ladder::scene::remake_scene(ladder::daemon::kBuiltinSceneToml, "built-in classic scene", {}, true);
  Session session(scene, LADDER_SOURCE_DIR "/config/scenes", ladder::daemon::Limits{}, ladder::daemon::Rates{});
  Bytes in(data, size);
  for (int n = 0; n < kMaxCommands && !in.empty(); ++n) {
    const ladder_msg_Command c = command(in);
    session.apply(ladder::daemon::fields_of(c));  // accepted or refused with a reason: both fine here, only what is published is checked
    check_published(session, c);
    const int steps = session.sim().ladder().blocks() <= kMaxBlocksStepped
                          ? in.take<std::uint8_t>() % (kMaxStepsAfter + 1)
                          : (in.take<std::uint8_t>(), 0);
    for (int i = 0; i < steps; ++i) {
      tick(session);
      check_published(session, c);
    }
  }
  return 0;
}
