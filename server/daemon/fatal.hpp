// The reason ladderd exits with an error, which reaches the user even with --log-level off.
#pragma once

#include "ladder/printable.hpp"

#include <spdlog/spdlog.h>

#include <iostream>
#include <string>

namespace ladder::daemon {

// Logs `why` as an error and returns `code`, the exit code. With the log silenced (--log-level off, or a level above
// error) `why` is written to standard error all the same: a run that fails must say why, and scripts that turn the
// log off still get the reason with the code. Made printable (each reason is one line): it may quote a path, a key or
// a name from a file or a client (a key "\u001b[2J\n[error] ..." cleared the screen and forged a line). Backslashes
// are kept: some reasons quote a peer's text already made printable.
inline int exit_with(int code, const std::string& why) {
  const std::string text = printable(why, false);
  if (spdlog::should_log(spdlog::level::err))
    spdlog::error("{}", text);
  else
    std::cerr << "ladderd: " << text << std::endl;
  return code;
}

}  // namespace ladder::daemon
