// ladderctl's commands: one parser (CLI11) for the command line and the interactive prompt, and what each does.
#pragma once

#include "client.hpp"

#include <memory>
#include <string>
#include <vector>

namespace ladder::ctl {

// Exit codes scripts can rely on.
enum Exit : int {
  kAccepted = 0,  // the server accepted the command (or watch/status ended normally)
  kRefused = 1,   // the server refused it; the reason is printed
  kUsage = 2,     // bad command line
  kNoServer = 3,  // no ladderd answered within the timeout
  kDenied = 4,    // DDS Security: this identity may not send commands (a viewer's); the missing permission is printed
  kNoCommand = -1,  // (internal) only options were given: start the prompt
};

struct Connection {
  int domain = 0;
  std::string sim_id = "ladder";
  double timeout = 3;  // [s]
  std::string security;  // DDS Security identity folder (scripts/make-pki DIR/NAME); empty = none
};

// The names of every subcommand, for help and completion.
const std::vector<std::string>& command_names();

// "unknown command 'tpi'; did you mean 'tip'?" and the list of commands (no did-you-mean when none is near).
std::string unknown_command(const std::string& word);

// Runs one command line (argv without the program name). `client` is reused if given (the prompt keeps one);
// otherwise one is made and dropped; it is remade when --domain or --sim-id change it. Returns an Exit code.
int run(const std::vector<std::string>& args, Connection& connection, std::unique_ptr<client::Client>& client,
        bool interactive);

// Splits a prompt line into words: whitespace separates, quotes group, backslash escapes.
std::vector<std::string> split_words(const std::string& line);

}  // namespace ladder::ctl
