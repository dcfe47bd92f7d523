// How near a word is to a name, for the "did you mean" of the scene parser's and the programs' errors, and CLI11's
// words for an option given twice put in a user's. Header only, like limits.hpp: the clients include it without
// linking the model.
#pragma once

#include <algorithm>
#include <cstddef>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace ladder {

// Optimal string alignment distance (edits and adjacent transpositions, so '--domian' is one from '--domain'), with
// three rows of the table.
inline std::size_t edit_distance(std::string_view a, std::string_view b) {
  std::vector<std::size_t> before(b.size() + 1), prev(b.size() + 1), cur(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) prev[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    cur[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t cost = a[i - 1] == b[j - 1] ? 0 : 1;
      cur[j] = std::min({prev[j] + 1, cur[j - 1] + 1, prev[j - 1] + cost});
      if (i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1]) cur[j] = std::min(cur[j], before[j - 2] + 1);
    }
    std::swap(before, prev);
    std::swap(prev, cur);
  }
  return prev[b.size()];
}

// The distance when it is below `limit`, else some figure at least `limit`. Lengths that differ by `limit` or more
// cost no table at all: a message is built for every refused key, and a hostile file's key may be kilobytes long
// (measured: a 6 KB key in a fuzzed scene took 0.3 s against the full tables under ASan).
inline std::size_t edit_distance_below(std::string_view a, std::string_view b, std::size_t limit) {
  const std::size_t gap = a.size() > b.size() ? a.size() - b.size() : b.size() - a.size();
  return gap >= limit ? gap : edit_distance(a, b);
}

// The name of `names` nearest to `word` (one it starts, or at most two edits away and fewer than the word has
// letters), or "".
inline std::string nearest(const std::string& word, const std::vector<std::string>& names) {
  std::string best;
  std::size_t best_d = 3;
  for (const std::string& n : names) {
    const std::size_t d = n.starts_with(word) ? 0 : edit_distance_below(word, n, best_d);
    if (d < best_d && d < word.size()) best = n, best_d = d;
  }
  return best;
}

// CLI11's message for an option given more often than it is taken, "--domain: At Most 1 required but received 2",
// as "--domain is given 2 times; give it once". Any other message comes back as it is.
inline std::string repeated_option(std::string_view message) {
  constexpr std::string_view kWords = ": At Most 1 required but received ";
  const std::size_t at = message.find(kWords);
  if (at == std::string_view::npos) return std::string(message);
  const std::string_view name = message.substr(0, at), count = message.substr(at + kWords.size());
  if (name.empty() || name.find(' ') != std::string_view::npos || count.empty() ||
      count.find_first_not_of("0123456789") != std::string_view::npos)
    return std::string(message);
  return std::string(name) + " is given " + std::string(count) + " times; give it once";
}

}  // namespace ladder
