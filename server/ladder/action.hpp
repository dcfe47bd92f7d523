// What can be done to the ladder, from any source (a client's command, a session log, a scene's timeline): one
// type, so that each source decodes into it once and the ladder dispatches it in one place (Ladder::apply).
// Checks against the server's limits are the server's (daemon/session.cpp); what the ladder itself refuses (no
// such block or hinge, a block that is held or not grabbed, a hinge already broken) Ladder::apply refuses.
#pragma once

#include "core/geometry.hpp"

#include <optional>
#include <variant>

namespace ladder::model {

using core::Vec2;

// The hand turns the held top block over, in ladder.tip_duration.
struct Tip {};
// An instantaneous impulse [N s] on a block, at a world point [m]; none: at the block's centre.
struct Poke {
  int block = -1;
  Vec2 impulse{0, 0};
  std::optional<Vec2> at;
};
// A steady force [N] on a block for `duration` [s], at a point in the block's frame [m].
struct Push {
  int block = -1;
  Vec2 force{0, 0};
  Vec2 at{0, 0};
  double duration = 0;
};
// A hand on a block (Ladder::Grip): the point `local` of the block (its frame) pulled toward `target` (a world
// point; none: where the point is now), turned toward `angle` if one is given (the turn nearest the block's own),
// with `stiffness` [N/m] (0: the default).
struct Grab {
  int block = -1;
  Vec2 local{0, 0};
  std::optional<Vec2> target;
  std::optional<double> angle;
  double stiffness = 0;
};
// Moves a grabbed block's target (and its angle, if one is given).
struct Drag {
  int block = -1;
  Vec2 target{0, 0};
  std::optional<double> angle;
};
struct Release {
  int block = -1;
};
// Cuts hinge k (hinge 0 lets go of the top block).
struct Break {
  int hinge = -1;
};
// Re-makes a broken hinge, if its corners are within ladder.capture_distance.
struct Join {
  int hinge = -1;
};

using Action = std::variant<Tip, Poke, Push, Grab, Drag, Release, Break, Join>;

}  // namespace ladder::model
