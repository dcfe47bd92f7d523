// The session log (ladderd --record): what was published, and the commands as the simulation took them, as LCM
// records (docs/recording.md). The encoding happens on the I/O thread; the log writer's own thread does the file I/O.
#pragma once

#include "daemon/command.hpp"
#include "daemon/handoff.hpp"
#include "daemon/outbox.hpp"
#include "ladderlcm/command_t.hpp"
#include "transport/lcm_log.hpp"

#include <cstdint>
#include <string>

namespace ladder::daemon {

class Recorder {
 public:
  Recorder(transport::LogWriter& log, std::string sim_id) : log_(log), sim_id_(std::move(sim_id)) {}
  // The scenes, commands, events and checkpoints of one outbox.
  void record(const Outbox& out);
  // A state as published, with its sequence number.
  void record_state(const StateFrame& f, std::uint64_t seq);

 private:
  transport::LogWriter& log_;
  std::string sim_id_;
  std::uint64_t logged_events_ = 0;
};

// A command as the log records it (its own fields; where and when it was applied, and its answer, are the
// recorder's to fill in), and its fields read back for a re-run. One pair, so that a field added to the command is
// added to both.
ladderlcm::command_t command_record(const ladder_msg_Command& c);
CommandFields fields_of(const ladderlcm::command_t& m);

}  // namespace ladder::daemon
