// ladderctl's interactive prompt: line editing, history (~/.ladderctl_history) and tab completion (libedit).
#pragma once

#include "commands.hpp"

namespace ladder::ctl {

// Reads commands until quit or end of input; returns the exit code of the last command.
int prompt(Connection& connection);

}  // namespace ladder::ctl
