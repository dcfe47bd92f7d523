#include "daemon/resimulate.hpp"

#include "daemon/config.hpp"
#include "daemon/frames.hpp"

#include "transport/dds.hpp"
#include "transport/lcm_log.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <map>
#include <set>
#include <stdexcept>
#include <tuple>

namespace ladder::daemon {

namespace {

using transport::copy_text;

// The scene a record describes, made again from its text; its states were checked against its `blocks`, so the
// text must make that many.
scene::Scene scene_of(const ladderlcm::scene_t& s) {
  scene::Scene sc;
  try {
    sc = scene::remake_scene(s.toml, s.source, s.overrides, s.clear_timeline);
  } catch (const std::exception& e) {  // (its place is in the text the log holds, which came from that source)
    throw std::runtime_error("the scene record of generation " + std::to_string(s.generation) +
                             " holds a scene text (recorded from " + s.source + ") that does not make a scene: " +
                             e.what());
  }
  sc.name = s.name;
  if (sc.ladder.blocks != s.blocks)
    throw std::runtime_error("the scene record of generation " + std::to_string(s.generation) + " says " +
                             std::to_string(s.blocks) + " blocks, but its text makes " +
                             std::to_string(sc.ladder.blocks));
  return sc;
}

std::string at(std::int64_t generation, std::int64_t step, double t) {
  char buf[96];
  std::snprintf(buf, sizeof buf, "generation %lld, step %lld (t = %.6f s)", static_cast<long long>(generation),
                static_cast<long long>(step), t);
  return buf;
}

// The first difference between a recorded state and the session's, or empty.
std::string compare(const ladderlcm::state_t& r, const Session& s) {
  const model::Ladder& l = s.sim().ladder();
  if (r.num_blocks != l.blocks())
    return "the log has " + std::to_string(r.num_blocks) + " blocks, the re-run " + std::to_string(l.blocks());
  if (r.sim_time != s.sim().time()) return "sim time differs";
  const auto differs = [](double a, double b) { return std::memcmp(&a, &b, sizeof a) != 0; };
  for (int i = 0; i < r.num_blocks; ++i) {
    const auto k = static_cast<std::size_t>(i);
    const core::Vec2 c = l.block_centre(i);
    const double mine[3] = {c.x(), c.y(), l.block_angle(i)}, theirs[3] = {r.x[k], r.y[k], r.theta[k]};
    static const char* kWhat[3] = {"x", "y", "theta"};
    for (int j = 0; j < 3; ++j)
      if (differs(mine[j], theirs[j])) {
        char buf[160];
        std::snprintf(buf, sizeof buf, "block %d %s: recorded %.17g, re-simulated %.17g", i, kWhat[j], theirs[j],
                      mine[j]);
        return buf;
      }
    const model::HingeInfo& h = l.hinges()[k];
    if (h.corner != r.corner[k] || static_cast<int>(h.status) != r.status[k] || h.flips != r.flips[k])
      return "hinge " + std::to_string(i) + " differs (corner, status or flips)";
  }
  return {};
}

}  // namespace

namespace {

// Where each record came from, for messages: "<path>: event 12 (LADDER_STATE at byte 4096): ...".
struct Origin {
  std::uint64_t event;
  std::size_t offset;
};
[[noreturn]] void refuse(const SessionLog& log, const char* channel, const Origin& o, const std::string& why) {
  throw std::runtime_error(log.path + ": event " + std::to_string(o.event) + " (" + channel + " at byte " +
                           std::to_string(o.offset) + "): " + why);
}

// What the scene records of one generation allow: its number of blocks and the range of its dt (a live setting
// can change dt within a generation).
struct GenerationInfo {
  std::int32_t blocks = 0;
  double min_dt = 0, max_dt = 0;
  std::vector<std::int64_t> checkpoint_steps;  // sorted
  std::vector<std::int64_t> failed_steps;      // sorted: where a step failed (its time moved on, its count did not)
};

// The server writes a checkpoint at each scene's start and every checkpoint_every of sim time; a recorded step
// more than two intervals (and a step) past the last checkpoint before it is one no run of the server makes, and
// would let a few bytes of log ask a re-run for 2^62 steps. (Not constexpr: clang does not take a ServerConfig, with
// its std::string members, in a constant expression.)
const double kCheckpointGap = 2 * ServerConfig{}.checkpoint_every + transport::kLogMaxDt;

std::string place(std::int32_t generation, std::int64_t step) {
  return "generation " + std::to_string(generation) + ", step " + std::to_string(step);
}

// A step (and, for states and checkpoints, its time) fits generation g's scene.
std::string check_step(const std::map<std::int32_t, GenerationInfo>& gens, const char* what, std::int32_t g,
                       std::int64_t step, const double* t) {
  const auto it = gens.find(g);
  if (it == gens.end())
    return std::string("a ") + what + " of generation " + std::to_string(g) + ", which no scene record starts";
  const GenerationInfo& info = it->second;
  if (t) {
    // Time is the sum of the steps' dt: between step * min_dt and step * max_dt (with rounding to spare), and a step
    // that failed may have taken part of its dt without being counted.
    const auto failed = std::upper_bound(info.failed_steps.begin(), info.failed_steps.end(), step) -
                        info.failed_steps.begin();
    const double lo = static_cast<double>(step) * info.min_dt, hi = static_cast<double>(step) * info.max_dt;
    const double failed_time = static_cast<double>(failed) * info.max_dt;
    if (*t < lo * (1 - 1e-6) - info.max_dt || *t > (hi + failed_time) * (1 + 1e-6) + info.max_dt) {
      char buf[200], more[80] = "";
      if (failed)
        std::snprintf(more, sizeof more, ", and %lld failed before it at most %g s", static_cast<long long>(failed),
                      failed_time);
      std::snprintf(buf, sizeof buf, "a %s at %s with t = %g s: %lld steps of dt = %g .. %g s take %g .. %g s%s", what,
                    place(g, step).c_str(), *t, static_cast<long long>(step), info.min_dt, info.max_dt, lo, hi, more);
      return buf;
    }
  }
  const auto& cps = info.checkpoint_steps;
  const auto after = std::upper_bound(cps.begin(), cps.end(), step);
  const std::int64_t anchor = after == cps.begin() ? 0 : *(after - 1);
  const auto most = static_cast<std::int64_t>(std::ceil(kCheckpointGap / info.min_dt)) + 2;
  if (step - anchor > most) {
    char buf[240];
    std::snprintf(buf, sizeof buf,
                  "a %s at %s, %lld steps after the checkpoint before it (step %lld): the server writes one every "
                  "%g s of sim time, so a step lies at most %lld steps past one at this scene's dt",
                  what, place(g, step).c_str(), static_cast<long long>(step - anchor),
                  static_cast<long long>(anchor), ServerConfig{}.checkpoint_every, static_cast<long long>(most));
    return buf;
  }
  return {};
}

struct Origins {
  std::vector<Origin> scenes, commands, states, checkpoints, failures;
};

// The checks across records (each record's own values were checked as it was decoded). Records each generation's dt
// range in `log`.
void check_session(SessionLog& log, const Origins& at) {
  std::map<std::int32_t, GenerationInfo> gens;
  for (std::size_t i = 0; i < log.scenes.size(); ++i) {
    const ladderlcm::scene_t& s = log.scenes[i];
    if (i == 0 && s.generation != 0)
      refuse(log, transport::kSceneChannel, at.scenes[i],
             "the first scene record has generation " + std::to_string(s.generation) + " (a log starts at 0)");
    auto [it, fresh] = gens.try_emplace(s.generation, GenerationInfo{s.blocks, s.dt, s.dt, {}, {}});
    if (!fresh && it->second.blocks != s.blocks)
      refuse(log, transport::kSceneChannel, at.scenes[i],
             "generation " + std::to_string(s.generation) + " has " + std::to_string(s.blocks) +
                 " blocks here, " + std::to_string(it->second.blocks) + " in its first scene record");
    it->second.min_dt = std::min(it->second.min_dt, s.dt);
    it->second.max_dt = std::max(it->second.max_dt, s.dt);
  }
  for (const auto& [g, info] : gens) log.dt_range[g] = {info.min_dt, info.max_dt};
  for (std::size_t i = 0; i < log.checkpoints.size(); ++i) {
    const ladderlcm::checkpoint_t& c = log.checkpoints[i];
    const auto it = gens.find(c.generation);
    if (it == gens.end())
      refuse(log, transport::kCheckpointChannel, at.checkpoints[i],
             "a checkpoint of generation " + std::to_string(c.generation) + ", which no scene record starts");
    it->second.checkpoint_steps.push_back(c.step);
  }
  std::set<std::tuple<std::int32_t, std::int64_t, std::int64_t>> failed_at;
  for (std::size_t i = 0; i < log.failures.size(); ++i) {
    const SessionLog::Failure& f = log.failures[i];
    const auto it = gens.find(f.at.generation);
    if (it == gens.end())
      refuse(log, f.step ? transport::kFailureChannel : transport::kNonFiniteChannel, at.failures[i],
             "a failure of generation " + std::to_string(f.at.generation) + ", which no scene record starts");
    if (f.step) it->second.failed_steps.push_back(f.at.step);
    // The server pauses at a failure: the next is at another place (a command resumes or steps it).
    if (!failed_at.emplace(f.at.generation, f.at.step, f.at.commands_applied).second)
      refuse(log, f.step ? transport::kFailureChannel : transport::kNonFiniteChannel, at.failures[i],
             "a second failure at " + place(f.at.generation, f.at.step) + " with " +
                 std::to_string(f.at.commands_applied) + " commands taken (the server pauses at the first)");
  }
  for (auto& [g, info] : gens) {
    std::sort(info.checkpoint_steps.begin(), info.checkpoint_steps.end());
    std::sort(info.failed_steps.begin(), info.failed_steps.end());
  }
  for (std::size_t i = 0; i < log.checkpoints.size(); ++i) {
    const ladderlcm::checkpoint_t& c = log.checkpoints[i];
    if (const auto why = check_step(gens, "checkpoint", c.generation, c.step, &c.sim_time); !why.empty())
      refuse(log, transport::kCheckpointChannel, at.checkpoints[i], why);
  }
  for (std::size_t i = 0; i < log.failures.size(); ++i) {
    const ladderlcm::checkpoint_t& f = log.failures[i].at;
    if (const auto why = check_step(gens, "failure", f.generation, f.step, &f.sim_time); !why.empty())
      refuse(log, log.failures[i].step ? transport::kFailureChannel : transport::kNonFiniteChannel, at.failures[i],
             why);
  }
  for (std::size_t i = 0; i < log.states.size(); ++i) {
    const SessionLog::StateRecord& s = log.states[i];
    if (const auto why = check_step(gens, "state", s.generation, s.step, &s.sim_time); !why.empty())
      refuse(log, transport::kStateChannel, at.states[i], why);
    if (s.num_blocks != gens.at(s.generation).blocks)
      refuse(log, transport::kStateChannel, at.states[i],
             "a state of " + std::to_string(s.num_blocks) + " blocks in a scene of " +
                 std::to_string(gens.at(s.generation).blocks));
  }
  for (std::size_t i = 0; i < log.commands.size(); ++i) {
    const ladderlcm::command_t& c = log.commands[i];
    if (const auto why = check_step(gens, "command", c.generation, c.step, nullptr); !why.empty())
      refuse(log, transport::kCommandChannel, at.commands[i], why);
    // A kind beyond the enum cannot come over DDS (Cyclone refuses it) and may not come from a file: held in the
    // enum it would be undefined behaviour before any check could see it.
    if (c.kind < 0 || c.kind > kind::kLast)
      refuse(log, transport::kCommandChannel, at.commands[i],
             "kind " + std::to_string(c.kind) + " is no command kind (0 to " + std::to_string(kind::kLast) +
                 ")");
    // The server logs its commands in the order it applied them.
    if (i > 0 && c.command_seq <= log.commands[i - 1].command_seq)
      refuse(log, transport::kCommandChannel, at.commands[i],
             "command_seq " + std::to_string(c.command_seq) + " after " +
                 std::to_string(log.commands[i - 1].command_seq) + " (the server logs them in increasing order)");
  }
}

SessionLog read_events(std::shared_ptr<transport::LogReader> from) {
  transport::LogReader& reader = *from;
  SessionLog log;
  log.path = reader.path();
  log.reader = std::move(from);
  Origins at;
  while (auto e = reader.next()) {
    const Origin o{e->number, e->offset};
    if (e->channel == transport::kSceneChannel) {
      log.scenes.push_back(reader.decode<ladderlcm::scene_t>(*e));
      at.scenes.push_back(o);
    } else if (e->channel == transport::kCommandChannel) {
      log.commands.push_back(reader.decode<ladderlcm::command_t>(*e));
      at.commands.push_back(o);
    } else if (e->channel == transport::kStateChannel) {
      const auto s = reader.decode<ladderlcm::state_t>(*e);
      log.states.push_back({s.generation, s.num_blocks, s.step, s.commands_applied, s.sim_time, e->number, e->offset});
      at.states.push_back(o);
    } else if (e->channel == transport::kCheckpointChannel) {
      log.checkpoints.push_back(reader.decode<ladderlcm::checkpoint_t>(*e));
      at.checkpoints.push_back(o);
    } else if (e->channel == transport::kFailureChannel || e->channel == transport::kNonFiniteChannel) {
      log.failures.push_back({reader.decode<ladderlcm::checkpoint_t>(*e), e->channel == transport::kFailureChannel});
      at.failures.push_back(o);
    } else if (e->channel == transport::kEventChannel) {
      reader.decode<ladderlcm::event_t>(*e);  // not needed to re-run, but a log with a bad one is a bad log
      ++log.events;
    }
  }
  log.damage = reader.damage();
  log.damage_after = reader.damage_after();
  if (log.scenes.empty())
    throw std::runtime_error(log.path + ": no scene record" +
                             (log.damage.empty() ? std::string(" (not a ladderd session log?)") : ": " + log.damage));
  check_session(log, at);
  return log;
}

}  // namespace

SessionLog read_session_log(const std::string& path) {
  return read_events(std::make_shared<transport::LogReader>(path));
}

SessionLog read_session_log_bytes(std::span<const std::uint8_t> bytes, const std::string& name) {
  return read_events(
      std::make_shared<transport::LogReader>(std::vector<std::uint8_t>(bytes.begin(), bytes.end()), name));
}

ladderlcm::state_t SessionLog::state(std::size_t i) const {
  const StateRecord& r = states.at(i);
  std::string why;
  const auto e = reader->event_at(r.offset, r.event, why);
  const auto changed = [&](const std::string& what) {
    return std::runtime_error(path + ": event " + std::to_string(r.event) + " (" + transport::kStateChannel +
                              " at byte " + std::to_string(r.offset) + ") changed since the log was read: " + what);
  };
  if (!e) throw changed(why);
  if (e->channel != transport::kStateChannel) throw changed("it is now a " + e->channel + " record");
  ladderlcm::state_t s = reader->decode<ladderlcm::state_t>(*e);
  if (s.generation != r.generation || s.num_blocks != r.num_blocks || s.step != r.step ||
      s.commands_applied != r.commands_applied || std::memcmp(&s.sim_time, &r.sim_time, sizeof s.sim_time) != 0)
    throw changed("its generation, blocks, step, commands or time are not the ones read");
  return s;
}

Resimulation resimulate(const SessionLog& log, std::unique_ptr<Session>& session, Until until,
                        const std::function<void(std::uint64_t, std::uint64_t)>& progress) {
  Resimulation r;
  // Only commands the server accepted are applied, and they passed its limits then; which limits those were the
  // log does not say, so a re-run holds them to the widest any configuration allows: a logged poke of 1e300 N s,
  // which no ladderd accepts, is refused here rather than made into a state nobody can publish.
  session = std::make_unique<Session>(scene_of(log.scenes.front()), "", kWidestLimits, Rates{});
  std::size_t next_command = 0;
  std::int64_t applied = 0;  // commands taken, as the server counted them

  // Applies the recorded commands due at the session's current place, up to command number `up_to`.
  const auto apply_due = [&](std::int64_t up_to) {
    while (next_command < log.commands.size()) {
      const ladderlcm::command_t& c = log.commands[next_command];
      if (c.command_seq > up_to || c.generation != static_cast<std::int32_t>(session->generation()) ||
          c.step != static_cast<std::int64_t>(session->sim().steps()))
        return;
      ++next_command;
      applied = c.command_seq;
      ++r.commands;
      ++r.commands_after_checkpoint;
      ++(c.accepted ? r.accepted : r.refused);
      if (!c.accepted) continue;  // refused: it changed nothing
      if (c.kind == kind::kLoad) {
        // The scene text comes from the log (the file may have changed since).
        const auto s = std::find_if(log.scenes.begin(), log.scenes.end(), [&](const ladderlcm::scene_t& x) {
          return x.generation == static_cast<std::int32_t>(session->generation()) + 1;
        });
        if (s == log.scenes.end()) throw std::runtime_error("the log lacks the scene loaded by command " +
                                                            std::to_string(c.command_seq));
        session->restart(scene_of(*s));
        continue;
      }
      const Outcome o = session->apply(fields_of(c));
      if (!o.accepted) throw std::runtime_error("command " + std::to_string(c.command_seq) + " (" +
                                                kind_name(c.kind) +
                                                "), accepted live, is refused in the re-run: " + o.reason);
    }
  };
  // Runs to generation g, step s with `commands` commands taken; false when the run passes it or a step fails that
  // did not fail live (`failed_here` then says which).
  std::string failed_here;
  const auto reach = [&](std::int32_t g, std::int64_t s, std::int64_t commands) {
    while (true) {
      apply_due(commands);
      const auto gen = static_cast<std::int32_t>(session->generation());
      const auto step = static_cast<std::int64_t>(session->sim().steps());
      if (gen == g && step == s && applied == commands) return true;
      if (gen > g || (gen == g && step >= s)) return false;  // passed it: the log and the re-run disagree
      // Only a command (reset, load) leads to the next generation: one must lie ahead in this one.
      if (gen < g && (next_command >= log.commands.size() || log.commands[next_command].generation != gen ||
                      log.commands[next_command].step < step))
        return false;
      // As the server does: paused, a step is one that a step command ordered (so that a resumed session keeps
      // only the ordered steps not yet taken where the log ends).
      if (session->paused() && session->pending_steps() > 0) session->take_pending_step();
      // Held to its records' dt (SessionLog::dt_range): a record that claimed dt = 1e-7 s for a scene that steps
      // 1e-3 s let a few bytes of log order 2e7 steps.
      if (const auto range = log.dt_range.find(gen); range != log.dt_range.end()) {
        const double dt = session->sim().dt();
        if (!(dt >= range->second.first && dt <= range->second.second)) {
          char buf[200];
          std::snprintf(buf, sizeof buf, "the scene records of generation %d say dt = %g .. %g s, but its scene steps "
                        "%g s (at step %lld)", gen, range->second.first, range->second.second, dt,
                        static_cast<long long>(step));
          failed_here = buf;
          return false;
        }
      }
      try {
        session->step();
      } catch (const std::runtime_error& e) {
        failed_here = "the step at " + at(gen, step, session->sim().time()) + " failed in the re-run, not live: " +
                      e.what();
        return false;
      }
      ++r.steps;
      if (progress && r.steps % 10000 == 0) progress(r.steps, r.states);
    }
  };

  // States, checkpoints and failures in the order the run passed them (the log may interleave them differently:
  // they reach the recorder by different paths). At one place a checkpoint comes first, then states, then a failure;
  // but a failed step may leave the state inside the step (its last part the watchdog accepted), and a state or
  // checkpoint at the same place may then have been taken after the failure: one that differs is compared again
  // after it.
  enum Kind { kCheckpointMark, kStateMark, kFailureMark };
  struct Mark {
    std::int32_t generation;
    std::int64_t step, commands;
    Kind kind;
    std::size_t index;
  };
  std::vector<Mark> marks;
  for (std::size_t i = 0; i < log.checkpoints.size(); ++i) {
    const auto& c = log.checkpoints[i];
    marks.push_back({c.generation, c.step, c.commands_applied, kCheckpointMark, i});
  }
  for (std::size_t i = 0; i < log.states.size(); ++i) {
    const auto& st = log.states[i];
    marks.push_back({st.generation, st.step, st.commands_applied, kStateMark, i});
  }
  for (std::size_t i = 0; i < log.failures.size(); ++i) {
    const auto& f = log.failures[i].at;
    marks.push_back({f.generation, f.step, f.commands_applied, kFailureMark, i});
  }
  std::stable_sort(marks.begin(), marks.end(), [](const Mark& a, const Mark& b) {
    return std::tie(a.generation, a.step, a.commands, a.kind) < std::tie(b.generation, b.step, b.commands, b.kind);
  });
  const auto time_of = [&](const Mark& m) {
    return m.kind == kStateMark ? log.states[m.index].sim_time
           : m.kind == kCheckpointMark ? log.checkpoints[m.index].sim_time
                                       : log.failures[m.index].at.sim_time;
  };
  // A state or checkpoint: the first difference from the re-run's, or "".
  const auto differs = [&](const Mark& m) -> std::string {
    if (m.kind == kStateMark) {
      const std::string d = compare(log.state(m.index), *session);
      return d.empty() ? d : at(m.generation, m.step, time_of(m)) + ": " + d;
    }
    if (static_cast<std::int64_t>(session->state_hash()) == log.checkpoints[m.index].state_hash) return {};
    return "the complete state at " + at(m.generation, m.step, time_of(m)) +
           " differs from the recorded one (checkpoint hash)";
  };
  // A recorded failure: the server's next step failed (and it paused at the state the step's watchdog left), or it
  // found the state non-finite and paused. The re-run does the same, and must end where the server did.
  std::vector<bool> failed(log.failures.size(), false);
  const auto fail_as_recorded = [&](const Mark& m) -> std::string {
    failed[m.index] = true;
    const SessionLog::Failure& f = log.failures[m.index];
    const std::string where = at(m.generation, m.step, time_of(m));
    if (f.step) {
      if (session->paused() && session->pending_steps() > 0) session->take_pending_step();
      try {
        session->step();
        ++r.steps;
        return "the step at " + where + " failed live, and not in the re-run";
      } catch (const std::runtime_error&) {  // as it did live: the session paused itself
      }
    } else {
      if (non_finite_in(*session).empty())
        return "the state at " + where + " was not finite live, and is finite in the re-run";
      session->fail();
    }
    if (static_cast<std::int64_t>(session->state_hash()) != f.at.state_hash)
      return "the state the failure at " + where + " left differs from the recorded one (failure hash)";
    ++r.failures;
    return {};
  };
  const auto same_place = [](const Mark& a, const Mark& b) {
    return a.generation == b.generation && a.step == b.step && a.commands == b.commands;
  };
  for (std::size_t k = 0; k < marks.size() && r.identical; ++k) {
    const Mark& m = marks[k];
    if (m.kind == kFailureMark && failed[m.index]) continue;  // met early, below
    if (!reach(m.generation, m.step, m.commands)) {
      static const char* kWhat[] = {"checkpoint", "state", "failure"};
      r.identical = false;
      r.difference = !failed_here.empty() ? failed_here
                                          : "could not reach the recorded " + std::string(kWhat[m.kind]) + " at " +
                                                at(m.generation, m.step, time_of(m)) + " with " +
                                                std::to_string(m.commands) + " commands taken";
      break;
    }
    std::string d = m.kind == kFailureMark ? fail_as_recorded(m) : differs(m);
    if (!d.empty() && m.kind != kFailureMark) {
      // Taken after the failure at this place? Compared again after it; a difference either way is the first one.
      for (std::size_t j = k + 1; j < marks.size() && same_place(marks[j], m); ++j)
        if (marks[j].kind == kFailureMark && !failed[marks[j].index]) {
          if (fail_as_recorded(marks[j]).empty() && differs(m).empty()) d.clear();
          break;
        }
    }
    if (!d.empty()) {
      r.identical = false;
      r.difference = d;
      break;
    }
    if (m.kind == kStateMark) ++r.states;
    if (m.kind == kCheckpointMark) {
      ++r.checkpoints;
      r.commands_after_checkpoint = 0;
    }
  }
  // On past the last state or checkpoint: each command at its recorded place (only a command leads to another
  // generation, and every step taken lies before a recorded command, so this too ends).
  while (until == Until::kLastCommand && r.identical && next_command < log.commands.size()) {
    const ladderlcm::command_t& c = log.commands[next_command];
    if (!reach(c.generation, c.step, applied) || (apply_due(c.command_seq), applied != c.command_seq)) {
      r.identical = false;
      r.difference = !failed_here.empty() ? failed_here
                                          : "could not reach command " + std::to_string(c.command_seq) + " (" +
                                                kind_name(c.kind) + ") at its recorded " + place(c.generation, c.step) +
                                                "; the re-run stands at " +
                                                place(static_cast<std::int32_t>(session->generation()),
                                                      static_cast<std::int64_t>(session->sim().steps()));
    }
  }
  r.last_command_seq = static_cast<std::uint64_t>(applied);
  r.sim_time = session->sim().time();
  return r;
}

}  // namespace ladder::daemon
