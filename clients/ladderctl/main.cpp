// ladderctl: the console client of ladderd. `ladderctl COMMAND ...` sends one command and prints the server's
// answer (exit code 0 accepted, 1 refused, 2 bad usage, 3 no server, 4 not permitted by DDS Security); `ladderctl`
// alone opens a prompt.
#include "cli_checks.hpp"
#include "commands.hpp"
#include "prompt.hpp"

#include <iostream>
#include <memory>

int main(int argc, char** argv) {
  using namespace ladder::ctl;
  if (const std::string empty = ladder::client::empty_argument(argc, argv); !empty.empty()) {
    std::cerr << "ladderctl: " << empty << "\n";
    return kUsage;
  }
  Connection connection;
  std::unique_ptr<ladder::client::Client> client;
  const int code = run({argv + 1, argv + argc}, connection, client, false);
  return code == kNoCommand ? prompt(connection) : code;
}
