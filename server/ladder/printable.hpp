// Text from elsewhere (a peer, a log file, a scene file) made safe to print. Header only, like spelling.hpp: the
// transport, the offline runner and the clients use it without linking one another.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

namespace ladder {

// Text from a peer made safe for a log line or a terminal: each control character (a newline would start a forged
// line, an escape sequence would drive the terminal), the C1 controls U+0080 to U+009F and every byte that is not
// part of valid UTF-8 written as \xNN, the bidirectional controls too (U+202A to U+202E, U+2066 to U+2069, the marks
// U+200E, U+200F and U+061C: they reorder what a terminal shows, so that a name reads as another), and a backslash
// as \\ so that the escape cannot be forged either. What comes out is valid UTF-8 (cairo, which draws the viewer's
// text, needs that: with a scene name that was not, the window's picture stopped for good). With `backslash` false
// a backslash is kept as it is: for a message that may quote text already made printable (an error that names a
// peer's scene), which would otherwise show its escapes doubled.
inline std::string printable(std::string_view text, bool backslash = true) {
  std::string out;
  out.reserve(text.size());
  const auto escape = [&out](unsigned char c) {
    constexpr char kHex[] = "0123456789abcdef";
    out += "\\x";
    out += kHex[c >> 4];
    out += kHex[c & 15];
  };
  for (std::size_t i = 0; i < text.size();) {
    const auto c = static_cast<unsigned char>(text[i]);
    if (c == '\\' && backslash) {
      out += "\\\\";
      ++i;
      continue;
    }
    if (c < 0x80) {
      if (c < 0x20 || c == 0x7f) escape(c);
      else out += static_cast<char>(c);
      ++i;
      continue;
    }
    // A multi-byte sequence: its length from the lead byte, each continuation byte 10xxxxxx, no overlong form, no
    // surrogate, nothing past U+10FFFF.
    const std::size_t len = c >= 0xc2 && c <= 0xdf ? 2 : c >= 0xe0 && c <= 0xef ? 3 : c >= 0xf0 && c <= 0xf4 ? 4 : 0;
    bool valid = len > 0 && i + len <= text.size();
    std::uint32_t cp = len == 2 ? c & 0x1fu : len == 3 ? c & 0x0fu : c & 0x07u;
    for (std::size_t k = 1; valid && k < len; ++k) {
      const auto cc = static_cast<unsigned char>(text[i + k]);
      valid = (cc & 0xc0) == 0x80;
      cp = (cp << 6) | (cc & 0x3fu);
    }
    const bool overlong = (len == 3 && cp < 0x800) || (len == 4 && cp < 0x10000);
    if (valid) valid = !overlong && !(cp >= 0xd800 && cp <= 0xdfff) && cp <= 0x10ffff && !(cp >= 0x80 && cp <= 0x9f);
    if (!valid) {
      escape(c);
      ++i;
      continue;
    }
    if ((cp >= 0x202a && cp <= 0x202e) || (cp >= 0x2066 && cp <= 0x2069) || cp == 0x200e || cp == 0x200f ||
        cp == 0x061c) {
      for (std::size_t k = 0; k < len; ++k) escape(static_cast<unsigned char>(text[i + k]));
      i += len;
      continue;
    }
    out.append(text.substr(i, len));
    i += len;
  }
  return out;
}

// Lines of text each made printable, the newlines between them kept (a scene's settings, one KEY=VALUE a line; an
// error message that lists things).
inline std::string printable_lines(std::string_view text) {
  std::string out;
  for (std::size_t from = 0; from <= text.size();) {
    const std::size_t end = std::min(text.find('\n', from), text.size());
    out += printable(text.substr(from, end - from));
    if (end < text.size()) out += '\n';
    from = end + 1;
  }
  return out;
}

// The first `n` characters of UTF-8 `text` (all of it when it has no more): a heading or a terminal line cut at a
// whole character, never inside one.
inline std::string_view first_characters(std::string_view text, std::size_t n) {
  std::size_t chars = 0;
  for (std::size_t i = 0; i < text.size(); ++i)
    if ((static_cast<unsigned char>(text[i]) & 0xc0) != 0x80 && chars++ == n) return text.substr(0, i);
  return text;
}

// `text` in at most `max_bytes` bytes: as it is when it fits, else cut at the start of a character and ended with
// "..." (with room for no character, as much of "..." as fits). A cut inside a UTF-8 character left bytes that every
// reader showed as \xNN. The DDS messages' bounded text fields (transport::copy_text) and the session log's texts
// are cut with it.
inline std::string cut_text(std::string_view text, std::size_t max_bytes) {
  if (text.size() <= max_bytes) return std::string(text);
  if (max_bytes <= 3) return std::string(max_bytes, '.');
  std::size_t end = max_bytes - 3;
  while (end > 0 && (static_cast<unsigned char>(text[end]) & 0xc0) == 0x80) --end;  // text[end] begins a character
  return std::string(text.substr(0, end)) + "...";
}

}  // namespace ladder
