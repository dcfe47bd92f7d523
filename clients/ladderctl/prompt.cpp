#include "prompt.hpp"

#include <editline/readline.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <iostream>

namespace ladder::ctl {

namespace {

// Tab completion of the first word: the command names.
char* next_name(const char* text, int state) {
  static std::size_t i = 0;
  if (state == 0) i = 0;
  const auto& names = command_names();
  while (i < names.size()) {
    const std::string& n = names[i++];
    if (n.compare(0, std::strlen(text), text) == 0) return strdup(n.c_str());
  }
  return nullptr;
}

char** complete(const char* text, int start, int) {
  rl_attempted_completion_over = 1;  // no file-name completion
  return start == 0 ? rl_completion_matches(text, next_name) : nullptr;
}

std::string history_file() {
  const char* home = std::getenv("HOME");
  return home ? std::string(home) + "/.ladderctl_history" : std::string();
}

const char* kHelp =
    "commands (each takes --help):\n"
    "  tip                          turn the held top block over\n"
    "  poke BLOCK [--impulse X,Y] [--at X,Y]\n"
    "  push BLOCK --force X,Y --for S [--at X,Y]\n"
    "  grab BLOCK [--to X,Y] [--stiffness K]   drag BLOCK X,Y[,THETA]   release BLOCK\n"
    "  break HINGE                  join HINGE\n"
    "  pause   resume   step [N]   reset\n"
    "  set KEY VALUE                e.g. set damping.linear 0.5, set server.real_time_factor 0.25\n"
    "  load SCENE                   e.g. load double-ripple\n"
    "  status                       watch events|stats|state [--json]   (Ctrl-C ends a watch)\n"
    "  list                         every ladderd on the domain (sim id, host, scene, blocks, real-time factor)\n"
    "  plot PNG [--log FILE | --for S]   the ripple's front and the energy, from a log or the server\n"
    "  replay FILE [--speed X] [--from T] [--as ID]   a recorded session, published as if live\n"
    "  help   quit                  (quit exits 0; Ctrl-D exits with the last command's status)\n";

}  // namespace

int prompt(Connection& connection) {
  rl_readline_name = "ladderctl";
  rl_attempted_completion_function = complete;
  const std::string history = history_file();
  if (!history.empty()) read_history(history.c_str());
  std::unique_ptr<client::Client> client;
  std::cout << "ladderctl: sim id '" << connection.sim_id << "' on DDS domain " << connection.domain
            << ". Type help for the commands, quit or Ctrl-D to leave.\n";
  int last = kAccepted;
  while (char* raw = readline("ladder> ")) {
    const std::string line(raw);
    std::free(raw);
    const std::vector<std::string> words = split_words(line);
    if (words.empty()) continue;
    add_history(line.c_str());
    if (words[0] == "quit" || words[0] == "exit") {
      last = kAccepted;  // leaving on purpose: whatever an earlier command's answer was
      break;
    }
    if (words[0] == "help") {
      std::cout << kHelp;
      continue;
    }
    last = run(words, connection, client, true);
    std::cout.flush();
  }
  if (!history.empty()) write_history(history.c_str());
  return last == kNoCommand ? kAccepted : last;
}

}  // namespace ladder::ctl
