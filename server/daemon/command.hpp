// A user's command as the session takes it: an action on the ladder (ladder/action.hpp) or one of the session's own
// verbs. It comes from two sources, a DDS Command (a client) and a session log's command record (a re-run), which
// carry the same fields: each is read into CommandFields once (fields_of in wire.hpp and recorder.hpp), and
// request_of() makes the typed command from them, in one place for both. No DDS here.
#pragma once

#include "ladder/action.hpp"

#include <cstdint>
#include <string>
#include <variant>

namespace ladder::daemon {

// The session's verbs.
struct Pause {};
struct Resume {};
struct Step {
  std::uint32_t count = 0;  // steps to run while paused
};
struct Reset {};
struct Set {
  std::string setting;  // "key=value"
};
struct Load {
  std::string name;  // a scene in the server's scene folder
};
using Verb = std::variant<Pause, Resume, Step, Reset, Set, Load>;

using Request = std::variant<model::Action, Verb>;

// CommandKind's numbers, as msgs/ladder.idl gives them (wire.cpp checks them against it).
namespace kind {
inline constexpr std::int32_t kTip = 0, kPoke = 1, kPush = 2, kGrab = 3, kDrag = 4, kRelease = 5, kBreak = 6,
                              kJoin = 7, kPause = 8, kResume = 9, kStep = 10, kReset = 11, kSet = 12, kLoad = 13,
                              kLast = kLoad;
}  // namespace kind

// A command's fields as the wire (msgs/ladder.idl, Command) and the log (msgs/lcm/command_t.lcm) both carry them;
// the IDL says which fields each kind reads.
struct CommandFields {
  std::int32_t kind = kind::kTip;  // CommandKind's number
  std::int32_t block = 0, hinge = 0;
  std::uint32_t count = 0;
  bool has_point = false, has_target = false, has_angle = false;
  double a = 0, b = 0, c = 0, d = 0, e = 0, f = 0;
  std::string text;
};

// The fields that a DDS Command and a log's command_t name and type alike (all but the kind and the text, which
// each source reads its own way).
template <class Message>
CommandFields shared_fields(const Message& m) {
  CommandFields f;
  f.block = m.block;
  f.hinge = m.hinge;
  f.count = static_cast<std::uint32_t>(m.count);  // the log keeps the wire's uint32 in an int32
  f.has_point = m.has_point;
  f.has_target = m.has_target;
  f.has_angle = m.has_angle;
  f.a = m.a, f.b = m.b, f.c = m.c, f.d = m.d, f.e = m.e, f.f = m.f;
  return f;
}

// The typed command. Throws std::invalid_argument("unknown command kind N") when the kind names none. Fields the
// kind does not read are not read (a NaN left in one cannot reach the simulation).
Request request_of(const CommandFields& f);

// The kind's name as users type it ("tip", "break", "set", ...), or "unknown".
const char* kind_name(std::int32_t kind);

}  // namespace ladder::daemon
