// The --domain option's check, shared by ladderd and the clients: a DDS domain id, 0 to kMaxDomain, refused in words
// (CLI::Range says "Value text not in range 0 to 231" for a word). Header-only; the including program links CLI11.
#pragma once

#include "transport/dds.hpp"

#include <CLI/CLI.hpp>

#include <cerrno>
#include <cstdlib>
#include <string>

namespace ladder::transport {

inline CLI::Validator domain_check() {
  return CLI::Validator(
      [](std::string& text) -> std::string {
        char* end = nullptr;
        errno = 0;
        const long v = std::strtol(text.c_str(), &end, 10);
        if (text.empty() || end == text.c_str() || *end != '\0' || errno == ERANGE || v < 0 || v > kMaxDomain)
          return "'" + text + "' is not a DDS domain id (0 to " + std::to_string(kMaxDomain) + ")";
        return {};
      },
      "");  // (no words in --help: the type, INT, says it)
}

}  // namespace ladder::transport
