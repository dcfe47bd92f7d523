#include "daemon/command.hpp"

#include <iterator>
#include <optional>
#include <stdexcept>

namespace ladder::daemon {

namespace {
constexpr const char* kNames[] = {"tip",   "poke",   "push", "grab",  "drag", "release", "break",
                                  "join",  "pause",  "resume", "step", "reset", "set",   "load"};
static_assert(std::size(kNames) == kind::kLast + 1);
}  // namespace

const char* kind_name(std::int32_t kind) { return kind >= 0 && kind <= kind::kLast ? kNames[kind] : "unknown"; }

Request request_of(const CommandFields& m) {
  using model::Vec2;
  const Vec2 ab(m.a, m.b), cd(m.c, m.d);
  const auto point = [&] { return m.has_point ? std::optional<Vec2>(cd) : std::nullopt; };
  const auto angle = [&] { return m.has_angle ? std::optional<double>(m.f) : std::nullopt; };
  switch (m.kind) {
    case kind::kTip: return model::Tip{};
    case kind::kPoke: return model::Poke{m.block, ab, point()};
    case kind::kPush: return model::Push{m.block, ab, point().value_or(Vec2::Zero()), m.e};
    case kind::kGrab: return model::Grab{m.block, point().value_or(Vec2::Zero()),
                               m.has_target ? std::optional<Vec2>(ab) : std::nullopt, angle(), m.e};
    case kind::kDrag: return model::Drag{m.block, ab, angle()};
    case kind::kRelease: return model::Release{m.block};
    case kind::kBreak: return model::Break{m.hinge};
    case kind::kJoin: return model::Join{m.hinge};
    case kind::kPause: return Pause{};
    case kind::kResume: return Resume{};
    case kind::kStep: return Step{m.count};
    case kind::kReset: return Reset{};
    case kind::kSet: return Set{m.text};
    case kind::kLoad: return Load{m.text};
    default: throw std::invalid_argument("unknown command kind " + std::to_string(m.kind));
  }
}

}  // namespace ladder::daemon
