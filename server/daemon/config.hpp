// ladderd's configuration file (config/ladderd.toml): every key optional, checked with file:line:column errors.
#pragma once

#include "daemon/server.hpp"
#include "transport/security.hpp"

#include <stdexcept>
#include <string>
#include <utility>

namespace ladder::daemon {

struct DaemonConfig {
  ServerConfig server;
  std::string scene;  // scene file; empty = the built-in classic toy at rest
  std::string log_level = "info";
  std::string log_file;  // empty = standard error only
  std::string security;  // DDS Security: the server's identity folder (scripts/make-pki); empty = none
};

class ConfigError : public std::runtime_error {
 public:
  explicit ConfigError(const std::string& what, std::string key = {}) : std::runtime_error(what), key_(std::move(key)) {}
  const std::string& key() const { return key_; }  // the offending key, when one is to blame

 private:
  std::string key_;
};

// Reads `path` over the defaults in `config`. Relative paths in the file are taken from the file's folder.
// Throws ConfigError "FILE:LINE:COLUMN: message" (or "FILE: cannot open ...").
void load_config(const std::string& path, DaemonConfig& config);

// The checks a value gets whether it comes from the file or the command line: ConfigError("KEY ...why", KEY).
void check_config(const DaemonConfig& config);

// The checked server identity of the folder `dir` (server.security, --security); throws ConfigError with what is wrong.
transport::Identity server_identity(const std::string& dir);

}  // namespace ladder::daemon
