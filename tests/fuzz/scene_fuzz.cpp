// Fuzz target: bytes as a scene file and its --set overrides -> scene::parse_scene, then each override again as a
// live setting (the path of `ladderctl set`). The text is everything before the first NUL byte; after it, each
// NUL-separated piece is one "table.key=value" override. A bad scene must be refused with scene::SceneError;
// a sanitizer report or any other exception is a finding.
#include "scene/scene.hpp"

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view input(reinterpret_cast<const char*>(data), size);
  const std::size_t end = input.find('\0');
  const std::string_view text = input.substr(0, end);
  std::vector<std::string> overrides;
  for (std::size_t at = end; at != std::string_view::npos && at < input.size();) {
    const std::size_t next = input.find('\0', at + 1);
    overrides.emplace_back(input.substr(at + 1, next == std::string_view::npos ? next : next - at - 1));
    at = next;
  }
  try {
    const ladder::scene::Scene scene = ladder::scene::parse_scene(text, "fuzz.toml", overrides);
    for (const std::string& o : overrides) {
      try {
        ladder::scene::with_live_setting(scene, o);
      } catch (const ladder::scene::SceneError&) {  // not live, or refused as --set refuses it
      }
    }
  } catch (const ladder::scene::SceneError&) {
  }
  return 0;
}
