// Session logs read back: re-running a recorded session bit for bit (ladderd --offline --resimulate) and resuming
// a live server where a log ends (ladderd --resume).
//
// A log holds the scene as it was started, every command as the simulation took it (with the generation and step
// at which it was applied and its place in the server's order), every published state, periodic checkpoints
// (hashes of the complete dynamic state) and where the session paused itself after a failure. Runs are
// deterministic, so applying the same commands at the same steps from the same scene reproduces every state
// exactly; the re-run compares each recorded state and checkpoint, and fails where the server did.
#pragma once

#include "daemon/recorder.hpp"
#include "daemon/session.hpp"
#include "ladderlcm/checkpoint_t.hpp"
#include "ladderlcm/command_t.hpp"
#include "ladderlcm/scene_t.hpp"
#include "ladderlcm/state_t.hpp"
#include "transport/lcm_log.hpp"

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <span>
#include <string>
#include <utility>
#include <vector>

namespace ladder::daemon {

struct SessionLog {
  std::string path;
  std::vector<ladderlcm::scene_t> scenes;          // in log order
  std::vector<ladderlcm::command_t> commands;      // in log order, which is command_seq's (checked)
  // A state record: where it is in the log and what places it, for the checks and the re-run's order. The state
  // itself is read from the log again when the re-run compares it (state()): a log of 10 000-block states is 300 KB
  // a state, and holding every one decoded took more memory than the file's size.
  struct StateRecord {
    std::int32_t generation = 0, num_blocks = 0;
    std::int64_t step = 0, commands_applied = 0;
    double sim_time = 0;
    std::uint64_t event = 0;  // its number in the log
    std::size_t offset = 0;   // where it starts [bytes]
  };
  std::vector<StateRecord> states;  // in log order
  // State record i, decoded from the log again. Throws std::runtime_error naming the event when the file no longer
  // holds it (another program changed the log since it was read).
  ladderlcm::state_t state(std::size_t i) const;
  std::shared_ptr<transport::LogReader> reader;  // the log's reader, which state() reads with
  std::vector<ladderlcm::checkpoint_t> checkpoints;
  // Where the session paused itself: a step failed (`step`), or the state was found non-finite.
  struct Failure {
    ladderlcm::checkpoint_t at;
    bool step = true;
  };
  std::vector<Failure> failures;  // in log order
  std::uint64_t events = 0;                        // event records (not needed to re-run)
  std::string damage;                              // where a damaged or cut-off log stopped; empty if whole
  std::size_t damage_after = 0;                    // bytes of events after the damage (0: the log is cut off there)
  // Each generation's smallest and largest dt, as its scene records say (a live setting can change dt, and the
  // server then writes a record): the checks take steps and times on their word, and a re-run holds its scene to them.
  std::map<std::int32_t, std::pair<double, double>> dt_range;
};

// Reads a whole log, and checks it: every event decodes with our decoders (transport/lcm_decode.hpp), and the
// records agree with each other (each generation has a scene record, a state has its scene's number of blocks, a
// step fits the time at the scene's dt and lies within two checkpoint intervals of a checkpoint, command_seq
// increases, no two failures at one place), so that a re-run of it always ends. Throws std::runtime_error naming
// the file, the event and what is wrong (not a log, an undecodable or impossible event, no scene record); a damaged
// or cut-off end is not an error: reading stops there and `damage` says where.
SessionLog read_session_log(const std::string& path);
// The same on bytes in memory (a fuzzer's input); `name` stands for the path in messages.
SessionLog read_session_log_bytes(std::span<const std::uint8_t> bytes, const std::string& name = "(bytes)");

struct Resimulation {
  bool identical = true;
  std::string difference;  // the first difference, with its generation, step and what differs
  std::uint64_t steps = 0, states = 0, checkpoints = 0, commands = 0;
  std::uint64_t failures = 0;  // recorded failures the re-run met alike (the step failed, the same state left)
  std::uint64_t accepted = 0, refused = 0;   // of the commands applied, as the server answered them
  std::uint64_t commands_after_checkpoint = 0;  // commands applied after the last checkpoint passed
  std::uint64_t last_command_seq = 0;           // the command_seq of the last command applied
  double sim_time = 0;
};

// How far a re-run goes: to the last recorded state or checkpoint (--resimulate: everything it can compare), or
// on to the last recorded command (--resume: every command the server took, and so every one it acknowledged, is
// applied at its recorded generation and step, after the last state if it came later).
enum class Until { kLastMark, kLastCommand };

// Re-runs `log` from its first scene, comparing every state and checkpoint, until the first difference or the
// end. progress(steps, states) is called now and then. The session is left as the re-run ended. Throws
// std::runtime_error when a recorded command cannot be applied (refused in the re-run, a scene missing).
Resimulation resimulate(const SessionLog& log, std::unique_ptr<Session>& session, Until until = Until::kLastMark,
                        const std::function<void(std::uint64_t, std::uint64_t)>& progress = {});

}  // namespace ladder::daemon
