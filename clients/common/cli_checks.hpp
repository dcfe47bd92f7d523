// Checks of numeric command-line values that say what was wrong in words. (CLI11's PositiveNumber answers a 0 with
// "Value 0 not in range 0.000000 to 1797...", the largest double written out in 300 digits.)
#pragma once

#include "ladder/sim_id.hpp"

#include <CLI/CLI.hpp>

#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <string>

namespace ladder::client {

// `text` read whole as a number: false when it is not one (or not all of it is); `underflow` when it is too close to 0
// to be told from it (strtod's ERANGE for a finite result).
inline bool read_number(const std::string& text, double& x, bool& underflow) {
  errno = 0;
  char* end = nullptr;
  x = std::strtod(text.c_str(), &end);
  underflow = errno == ERANGE && std::isfinite(x);
  return !text.empty() && end != text.c_str() && *end == '\0';
}

// A finite number above 0 (strictly == true) or at least 0, and at most `most`.
inline CLI::Validator number_check(bool strictly, double most = HUGE_VAL) {
  return CLI::Validator(
      [strictly, most](std::string& text) -> std::string {
        double x = 0;
        bool underflow = false;
        const std::string want = strictly ? "a number greater than 0" : "a number of 0 or more";
        if (!read_number(text, x, underflow) || !std::isfinite(x)) return "'" + text + "' is not " + want;
        if (underflow) return "'" + text + "' is too close to 0 to be told from it";
        if (strictly ? !(x > 0) : !(x >= 0)) return "must be " + want + ", not " + text;
        if (x > most) return "must be at most " + CLI::detail::to_string(most) + ", not " + text;
        return {};
      },
      strictly ? "POSITIVE" : "NONNEGATIVE");
}
inline CLI::Validator positive(double most = HUGE_VAL) { return number_check(true, most); }

// A whole number from 1 to `most`, e.g. of steps. (CLI11 said "Could not convert: N = 1e3" of one it could not read
// into its integer.)
inline CLI::Validator count(std::uint64_t most) {
  return CLI::Validator(
      [most](std::string& text) -> std::string {
        std::uint64_t n = 0;
        const char* last = text.data() + text.size();
        const auto [end, ec] = std::from_chars(text.data(), last, n);
        const bool whole = end == last && !text.empty();
        if (whole && (ec == std::errc::result_out_of_range || (ec == std::errc() && n > most)))
          return "must be at most " + std::to_string(most) + ", not " + text;
        if (ec != std::errc() || !whole)
          return "'" + text + "' is not a whole number (1 to " + std::to_string(most) + ")";
        if (n == 0) return "must be 1 or more, not 0";
        return {};
      },
      "COUNT");
}
inline CLI::Validator non_negative(double most = HUGE_VAL) { return number_check(false, most); }

// A sim id as the server takes one (ladder/sim_id.hpp): a client given another would look for, or publish as, a
// ladder no server can be.
inline CLI::Validator sim_id_check() {
  return CLI::Validator([](std::string& text) { return sim_id_problem(text); }, "ID");
}

// A finite number from lo to hi (CLI::Range lets a NaN through: it compares, and every comparison with NaN is false).
inline CLI::Validator finite_range(double lo, double hi) {
  return CLI::Validator(
      [lo, hi](std::string& text) -> std::string {
        double x = 0;
        bool underflow = false;
        if (!read_number(text, x, underflow) || !(x >= lo && x <= hi))
          return "'" + text + "' is not a number from " + CLI::detail::to_string(lo) + " to " +
                 CLI::detail::to_string(hi);
        return {};
      },
      "NUMBER");
}

// The first empty argument on a command line, in words, or "" if none is. An empty argument is most often a shell
// variable that was not set (--security "$DIR"), and every option would take it as its default: a client would then
// run without DDS Security, or on block 0.
inline std::string empty_argument(int argc, char** argv) {
  for (int i = 1; i < argc; ++i)
    if (argv[i][0] == '\0')
      return std::string("argument ") + std::to_string(i) + " is empty" +
             (i > 1 ? std::string(" (after '") + argv[i - 1] + "')" : std::string()) +
             "; an unset shell variable? Every option needs a value";
  return {};
}

}  // namespace ladder::client
