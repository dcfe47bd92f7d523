#include "daemon/wire.hpp"

#include "transport/dds.hpp"

#include <cstring>

namespace ladder::daemon {

static_assert(ladder_msg_TIP == kind::kTip && ladder_msg_POKE == kind::kPoke && ladder_msg_PUSH == kind::kPush &&
              ladder_msg_GRAB == kind::kGrab && ladder_msg_DRAG == kind::kDrag && ladder_msg_RELEASE == kind::kRelease &&
              ladder_msg_BREAK_HINGE == kind::kBreak && ladder_msg_JOIN_HINGE == kind::kJoin &&
              ladder_msg_PAUSE == kind::kPause && ladder_msg_RESUME == kind::kResume && ladder_msg_STEP == kind::kStep &&
              ladder_msg_RESET == kind::kReset && ladder_msg_SET_PARAM == kind::kSet &&
              ladder_msg_LOAD_SCENE == kind::kLoad && kind::kLast == kind::kLoad,
              "command.hpp numbers the kinds as msgs/ladder.idl does");

CommandFields fields_of(const ladder_msg_Command& c) {
  CommandFields f;
  static_assert(sizeof c.kind == sizeof f.kind);
  std::memcpy(&f.kind, &c.kind, sizeof f.kind);
  f.block = c.block;
  f.hinge = c.hinge;
  f.count = c.count;
  f.has_point = c.has_point;
  f.has_target = c.has_target;
  f.has_angle = c.has_angle;
  f.a = c.a, f.b = c.b, f.c = c.c, f.d = c.d, f.e = c.e, f.f = c.f;
  f.text = transport::text_of(c.text);
  return f;
}

}  // namespace ladder::daemon
