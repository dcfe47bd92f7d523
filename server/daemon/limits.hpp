// What a user may ask of the server (ladderd.toml [commands] and the live `set` of the rates), and the rates its
// loop runs at. Plain values: the session checks commands against them, the configuration reads them.
#pragma once

#include "scene/scene.hpp"

#include <cstdint>

namespace ladder::daemon {

// Bounds on what a user may ask for (ladderd.toml [commands]); beyond them a command is refused, not clamped.
struct Limits {
  double max_impulse = scene::kMaxImpulse;    // [N s] poke
  double max_force = scene::kMaxForce;        // [N] push
  double max_duration = scene::kMaxDuration;  // [s] push
  double reach = scene::kReach;               // [m] targets and points must lie this close to the origin
  std::uint32_t max_step_count = 100'000;  // one step command
};

// The widest bounds a configuration may set (ladderd.toml [commands]): what any ladderd can have accepted, and so
// what a re-run of a session log (--resimulate, --resume) holds the logged commands to.
constexpr Limits kWidestLimits{.max_impulse = 1e6,
                               .max_force = 1e9,
                               .max_duration = 1e9,
                               .reach = 1e9,
                               .max_step_count = 1'000'000'000};

// The bounds of the rates, for `set` as for ladderd.toml and the command line. Below them the server would stop
// publishing (at 1e-300 Hz the next state is due in 1e300 s) or the simulation would freeze (a real-time factor of
// 1e-300 owes one step every 1e297 s). 1 Hz keeps a client's view of a running ladder at most a second old.
constexpr double kMinPublishRate = 1;        // [Hz]
constexpr double kMinStatsRate = 0.01;       // [Hz] ladderd.toml's server.stats_rate: one Stats every 100 s
constexpr double kMinRealTimeFactor = 0.01;  // besides 0 (as fast as possible): 10 ms of sim time per second
constexpr double kMaxRealTimeFactor = 1000;
// The largest grab stiffness and angle. A hand is softer than 1e6 N/m (the grip's frequency is capped at 0.2/dt in
// any case); an angle is an orientation, wrapped to within half a turn of the block's own (a hand turns a block
// the short way), and beyond 1000 rad (160 turns) a value is a mistake, not a turn.
constexpr double kMaxStiffness = 1e6;  // [N/m]
constexpr double kMaxAngle = 1000;     // [rad]

// What the server's loop runs at; the live keys server.real_time_factor and server.publish_rate change it.
struct Rates {
  double physics = 1000;          // ticks per wall second
  double publish = 60;            // states per wall second
  double real_time_factor = 1.0;  // sim seconds per wall second; 0 = as fast as possible
};

}  // namespace ladder::daemon
