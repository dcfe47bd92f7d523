// What a scene may ask for, in one place: the scene parser refuses more, the log reader refuses a log that claims
// more, and the clients drop a peer's message that does (docs/scenes.md, docs/recording.md). Header only: the
// transport and the clients include it without linking the model.
#pragma once

#include <cstdint>

namespace ladder {

inline constexpr std::int32_t kMaxBlocks = 1'000'000;  // ladder.blocks; about 1 GB of memory at this size
inline constexpr double kMinDt = 1e-7, kMaxDt = 0.1;   // [s] sim.dt's range

}  // namespace ladder
