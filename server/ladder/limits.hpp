// What a scene may ask for, in one place: the scene parser refuses more, the log reader refuses a log that claims
// more, and the clients drop a peer's message that does (docs/scenes.md, docs/recording.md). Header only: the
// transport and the clients include it without linking the model.
#pragma once

#include <cstddef>
#include <cstdint>

namespace ladder {

inline constexpr std::int32_t kMaxBlocks = 1'000'000;  // ladder.blocks; about 1 GB of memory at this size
inline constexpr double kMinDt = 1e-7, kMaxDt = 0.1;   // [s] sim.dt's range
inline constexpr std::size_t kMaxSceneName = 1024;    // [bytes] scene.name (a log holds up to 64 KiB of it)
inline constexpr std::size_t kMaxOverrides = 10'000;  // --set overrides of one scene
inline constexpr std::size_t kMaxSceneFile = 64u << 20;  // [bytes] a scene file (1e6 masses take about 8 MB)

}  // namespace ladder
