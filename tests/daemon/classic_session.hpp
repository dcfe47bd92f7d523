// For the in-process tests of the command rules (session_test.cpp, session_rules_test.cpp): the classic scene's
// session, and the numbers that break arithmetic.
#pragma once

#include "daemon/session.hpp"

#include <limits>
#include <memory>
#include <string>

namespace ladder::daemon {

inline const std::string kScenes = std::string(LADDER_SOURCE_DIR) + "/config/scenes";
inline constexpr double kNan = std::numeric_limits<double>::quiet_NaN();
inline constexpr double kInf = std::numeric_limits<double>::infinity();

// The classic scene (6 blocks, the top one held) without its scripted tip, so that only the test's commands act.
inline std::unique_ptr<Session> classic() {
  scene::Scene s = scene::load_scene(kScenes + "/classic.toml");
  s.timeline.clear();
  return std::make_unique<Session>(s, kScenes, Limits{}, Rates{});
}

}  // namespace ladder::daemon
