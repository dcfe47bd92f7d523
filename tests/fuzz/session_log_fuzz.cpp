// Fuzz target: bytes as a session log -> the LCM log reader (transport::LogReader), the session-log decoding
// (daemon::read_session_log) and the first scene made again from the log, as --resimulate, --resume and replay
// start. A hostile log may be refused (std::runtime_error, with a message) or cut off; anything else (a sanitizer
// report, std::bad_alloc or std::length_error from a length taken on trust, a hang) is a finding.
#include "daemon/resimulate.hpp"
#include "memfile.hpp"
#include "scene/scene.hpp"

#include <cstdint>
#include <stdexcept>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static ladder::fuzz::MemFile file("session-log");
  const std::string path = file.hold(data, size);
  try {
    const ladder::daemon::SessionLog log = ladder::daemon::read_session_log(path);
    const ladderlcm::scene_t& s = log.scenes.front();  // read_session_log refuses a log without one
    ladder::scene::remake_scene(s.toml, s.source, s.overrides, s.clear_timeline);
  } catch (const std::runtime_error&) {  // refused with a reason (SceneError is one too)
  }
  return 0;
}
