// The programs' command-line errors (ladderd, ladderctl, ladder-view), said as their other errors are: the program's
// name first, and for an option or a word it does not know, which one, and the nearest it does know. Header only,
// for the programs that link CLI11 (the libraries do not).
#pragma once

#include <CLI/CLI.hpp>

#include "ladder/printable.hpp"
#include "ladder/spelling.hpp"

#include <algorithm>
#include <cstddef>
#include <iostream>
#include <string>
#include <vector>

namespace ladder {

// Reports a parse error of `app` on standard error as "PROGRAM: ..." (no prefix when `program` is empty: the
// prompt's commands) and returns the exit code: 0 for --help and --version (CLI11 prints those), else 2. Words the
// command line did not expect (CLI11's "The following arguments were not expected: 228 --domian", in reverse order
// when the words were parsed reversed) are named in the order given, an unknown option with the nearest option of
// the command and of its parsed subcommand.
inline int report_parse_error(const CLI::App& app, const CLI::ParseError& e, const std::string& program) {
  if (e.get_exit_code() == 0) return app.exit(e);
  const std::string prefix = program.empty() ? "" : program + ": ";
  if (dynamic_cast<const CLI::ExtrasError*>(&e) == nullptr) {
    std::cerr << prefix << printable_lines(repeated_option(e.what())) << "\nRun with --help for the options.\n";
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
  std::cerr << prefix << printable_lines(text) << "\nRun with --help for the options.\n";
  return 2;
}

}  // namespace ladder
