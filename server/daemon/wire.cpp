#include "daemon/wire.hpp"

#include "transport/dds.hpp"

#include <cstring>

namespace ladder::daemon {

// command.hpp numbers the kinds as msgs/ladder.idl does.
static_assert(ladder_msg_TIP == kind::kTip && ladder_msg_POKE == kind::kPoke && ladder_msg_PUSH == kind::kPush);
static_assert(ladder_msg_GRAB == kind::kGrab && ladder_msg_DRAG == kind::kDrag && ladder_msg_RELEASE == kind::kRelease);
static_assert(ladder_msg_BREAK_HINGE == kind::kBreak && ladder_msg_JOIN_HINGE == kind::kJoin);
static_assert(ladder_msg_PAUSE == kind::kPause && ladder_msg_RESUME == kind::kResume && ladder_msg_STEP == kind::kStep);
static_assert(ladder_msg_RESET == kind::kReset && ladder_msg_SET_PARAM == kind::kSet);
static_assert(ladder_msg_LOAD_SCENE == kind::kLoad && kind::kLast == kind::kLoad);

CommandFields fields_of(const ladder_msg_Command& c) {
  CommandFields f = shared_fields(c);
  static_assert(sizeof c.kind == sizeof f.kind);
  std::memcpy(&f.kind, &c.kind, sizeof f.kind);
  f.text = transport::text_of(c.text);
  return f;
}

}  // namespace ladder::daemon
