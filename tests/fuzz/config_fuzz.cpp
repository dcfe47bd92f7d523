// Fuzz target: bytes as ladderd.toml -> daemon::load_config, then daemon::check_config (what ladderd does before
// it starts). A bad file must be refused with daemon::ConfigError; a sanitizer report or any other exception is a
// finding.
#include "daemon/config.hpp"
#include "memfile.hpp"

#include <cstdint>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static ladder::fuzz::MemFile file("ladderd.toml");
  const std::string path = file.hold(data, size);
  ladder::daemon::DaemonConfig config;
  try {
    ladder::daemon::load_config(path, config);
    ladder::daemon::check_config(config);
  } catch (const ladder::daemon::ConfigError&) {
  }
  return 0;
}
