// The clients' command-line errors, said as their other errors are: the program's name first, and for an option or
// a word it does not know, which one, and the nearest it does know. Header only: the client library has no CLI11.
#pragma once

#include <CLI/CLI.hpp>

#include <algorithm>
#include <cstddef>
#include <iostream>
#include <string>
#include <vector>

namespace ladder::client {

// Levenshtein distance with one row of the table (the words are short).
inline std::size_t edit_distance(const std::string& a, const std::string& b) {
  std::vector<std::size_t> row(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    std::size_t diagonal = row[0];
    row[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t above = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diagonal + (a[i - 1] == b[j - 1] ? 0 : 1)});
      diagonal = above;
    }
  }
  return row[b.size()];
}

// The name of `names` nearest to `word` (one it starts, or at most two edits away and fewer than the word has
// letters), or "".
inline std::string nearest(const std::string& word, const std::vector<std::string>& names) {
  std::string best;
  std::size_t best_d = 3;
  for (const std::string& n : names) {
    const std::size_t d = n.starts_with(word) ? 0 : edit_distance(word, n);
    if (d < best_d && d < word.size()) best = n, best_d = d;
  }
  return best;
}

// Reports a parse error of `app` on standard error as "PROGRAM: ..." (no prefix when `program` is empty: the
// prompt's commands) and returns the exit code: 0 for --help and --version (CLI11 prints those), else 2. Words the
// command line did not expect (CLI11's "The following arguments were not expected: 228 --domian", in reverse order
// when the words were parsed reversed) are named in the order given, an unknown option with the nearest option of
// the command and of its parsed subcommand.
inline int report_parse_error(const CLI::App& app, const CLI::ParseError& e, const std::string& program) {
  if (e.get_exit_code() == 0) return app.exit(e);
  const std::string prefix = program.empty() ? "" : program + ": ";
  if (dynamic_cast<const CLI::ExtrasError*>(&e) == nullptr) {
    std::cerr << prefix << e.what() << "\nRun with --help for the options.\n";
    return 2;
  }
  std::vector<std::string> options;
  const auto add = [&](const CLI::App& a) {
    for (const CLI::Option* o : a.get_options()) {
      for (const std::string& n : o->get_lnames()) options.push_back("--" + n);
      for (const std::string& n : o->get_snames()) options.push_back("-" + n);
    }
  };
  add(app);
  for (const CLI::App* sub : app.get_subcommands()) add(*sub);
  const std::vector<std::string> extras = app.remaining(true);
  std::string text;
  bool after_option = false;  // a word after an unknown option is taken for its value, and not named
  for (const std::string& w : extras) {
    if (w.starts_with("-")) {
      const std::string name = w.substr(0, w.find('='));
      text += (text.empty() ? "" : "; ") + ("unknown option '" + name + "'");
      if (const std::string best = nearest(name, options); !best.empty()) text += " (did you mean '" + best + "'?)";
      after_option = w.find('=') == std::string::npos;
    } else {
      if (!after_option) text += (text.empty() ? "" : "; ") + ("unexpected '" + w + "'");
      after_option = false;
    }
  }
  if (text.empty()) text = e.what();
  std::cerr << prefix << text << "\nRun with --help for the options.\n";
  return 2;
}

}  // namespace ladder::client
