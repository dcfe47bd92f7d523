// What a sim id may be, for the server (server.sim_id, --sim-id) and the clients (--sim-id, ladderctl replay --as)
// alike. Header only, like limits.hpp: the clients include it without linking the model.
#pragma once

#include <cctype>
#include <cstddef>
#include <string>
#include <string_view>

namespace ladder {

inline constexpr std::size_t kMaxSimId = 64;  // the DDS topics' key field holds 64 bytes

// Why `id` cannot be a sim id, or "" when it can: 1 to 64 letters, digits, '-', '_' and '.'. A sim id is the key of
// every topic and a heading in the clients: a longer one was cut on the wire (no client could find it under the name
// it was given), and one that was not UTF-8 stopped the viewer's drawing.
inline std::string sim_id_problem(std::string_view id) {
  if (id.empty() || id.size() > kMaxSimId) return "must be 1 to " + std::to_string(kMaxSimId) + " characters";
  for (const char ch : id)
    if (!(std::isalnum(static_cast<unsigned char>(ch)) || ch == '-' || ch == '_' || ch == '.'))
      return "may hold only letters, digits, '-', '_' and '.'";
  return {};
}

}  // namespace ladder
