// Checks of numeric command-line values that say what was wrong in words. (CLI11's PositiveNumber answers a 0 with
// "Value 0 not in range 0.000000 to 1797...", the largest double written out in 300 digits.)
#pragma once

#include <CLI/CLI.hpp>

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <string>

namespace ladder::client {

// A finite number above 0 (strictly == true) or at least 0, and at most `most`.
inline CLI::Validator number_check(bool strictly, double most = HUGE_VAL) {
  return CLI::Validator(
      [strictly, most](std::string& text) -> std::string {
        errno = 0;
        char* end = nullptr;
        const double x = std::strtod(text.c_str(), &end);
        const std::string want = strictly ? "a number greater than 0" : "a number of 0 or more";
        if (text.empty() || end == text.c_str() || *end != '\0' || errno == ERANGE || !std::isfinite(x))
          return "'" + text + "' is not " + want;
        if (strictly ? !(x > 0) : !(x >= 0)) return "must be " + want + ", not " + text;
        if (x > most) return "must be at most " + CLI::detail::to_string(most) + ", not " + text;
        return {};
      },
      strictly ? "POSITIVE" : "NONNEGATIVE");
}
inline CLI::Validator positive(double most = HUGE_VAL) { return number_check(true, most); }
inline CLI::Validator non_negative() { return number_check(false); }

}  // namespace ladder::client
