#include "daemon/resimulate.hpp"

#include "transport/dds.hpp"
#include "transport/lcm_log.hpp"

#include <algorithm>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <tuple>

namespace ladder::daemon {

namespace {

using transport::copy_text;

scene::Scene scene_of(const ladderlcm::scene_t& s) {
  scene::Scene sc = scene::remake_scene(s.toml, s.source, s.overrides, s.clear_timeline);
  sc.name = s.name;
  return sc;
}

// No limits in a re-run: only commands the server accepted are applied, and they passed its limits then.
Limits unlimited() {
  constexpr double kBig = std::numeric_limits<double>::max();
  return {kBig, kBig, kBig, kBig, std::numeric_limits<std::uint32_t>::max()};
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

ladderlcm::command_t command_record(const ladder_msg_Command& c) {
  ladderlcm::command_t m;
  m.client_id = transport::text_of(c.client_id);
  m.command_id = static_cast<std::int64_t>(c.command_id);
  m.kind = static_cast<std::int32_t>(c.kind);
  m.block = c.block;
  m.hinge = c.hinge;
  m.count = static_cast<std::int32_t>(c.count);
  m.has_point = c.has_point;
  m.has_target = c.has_target;
  m.has_angle = c.has_angle;
  m.a = c.a, m.b = c.b, m.c = c.c, m.d = c.d, m.e = c.e, m.f = c.f;
  m.text = transport::text_of(c.text);
  return m;
}

ladder_msg_Command command_of(const ladderlcm::command_t& m) {
  ladder_msg_Command c{};
  copy_text(c.client_id, m.client_id);
  c.command_id = static_cast<std::uint64_t>(m.command_id);
  c.kind = static_cast<ladder_msg_CommandKind>(m.kind);
  c.block = m.block;
  c.hinge = m.hinge;
  c.count = static_cast<std::uint32_t>(m.count);
  c.has_point = m.has_point;
  c.has_target = m.has_target;
  c.has_angle = m.has_angle;
  c.a = m.a, c.b = m.b, c.c = m.c, c.d = m.d, c.e = m.e, c.f = m.f;
  copy_text(c.text, m.text);
  return c;
}

SessionLog read_session_log(const std::string& path) {
  transport::LogReader reader(path);
  SessionLog log;
  log.path = path;
  while (auto e = reader.next()) {
    if (e->channel == transport::kSceneChannel) {
      log.scenes.push_back(reader.decode<ladderlcm::scene_t>(*e));
    } else if (e->channel == transport::kCommandChannel) {
      log.commands.push_back(reader.decode<ladderlcm::command_t>(*e));
    } else if (e->channel == transport::kStateChannel) {
      log.states.push_back(reader.decode<ladderlcm::state_t>(*e));
    } else if (e->channel == transport::kCheckpointChannel) {
      log.checkpoints.push_back(reader.decode<ladderlcm::checkpoint_t>(*e));
    } else if (e->channel == transport::kEventChannel) {
      ++log.events;
    }
  }
  log.damage = reader.damage();
  if (log.scenes.empty())
    throw std::runtime_error(path + ": no scene record" +
                             (log.damage.empty() ? std::string(" (not a ladderd session log?)") : ": " + log.damage));
  std::stable_sort(log.commands.begin(), log.commands.end(),
                   [](const auto& a, const auto& b) { return a.command_seq < b.command_seq; });
  return log;
}

Resimulation resimulate(const SessionLog& log, std::unique_ptr<Session>& session, long stop_after_checkpoint,
                        const std::function<void(std::uint64_t, std::uint64_t)>& progress) {
  Resimulation r;
  session = std::make_unique<Session>(scene_of(log.scenes.front()), "", unlimited(), Rates{});
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
      if (!c.accepted) continue;  // refused: it changed nothing
      if (c.kind == ladder_msg_LOAD_SCENE) {
        // The scene text comes from the log (the file may have changed since).
        const auto s = std::find_if(log.scenes.begin(), log.scenes.end(), [&](const ladderlcm::scene_t& x) {
          return x.generation == static_cast<std::int32_t>(session->generation()) + 1;
        });
        if (s == log.scenes.end()) throw std::runtime_error("the log lacks the scene loaded by command " +
                                                            std::to_string(c.command_seq));
        session->restart(scene_of(*s));
        continue;
      }
      const Outcome o = session->apply(command_of(c));
      if (!o.accepted) throw std::runtime_error("command " + std::to_string(c.command_seq) + " (" +
                                                to_string(static_cast<ladder_msg_CommandKind>(c.kind)) +
                                                "), accepted live, is refused in the re-run: " + o.reason);
    }
  };
  // Runs to generation g, step s with `commands` commands taken.
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
      session->step();
      ++r.steps;
      if (progress && r.steps % 10000 == 0) progress(r.steps, r.states);
    }
  };

  // States and checkpoints in the order the run passed them (the log may interleave them differently: the two
  // reach the recorder by different paths); at the same place a checkpoint comes first.
  struct Mark {
    std::int32_t generation;
    std::int64_t step, commands;
    bool is_state;
    std::size_t index;
  };
  std::vector<Mark> marks;
  for (std::size_t i = 0; i < log.checkpoints.size(); ++i) {
    const auto& c = log.checkpoints[i];
    marks.push_back({c.generation, c.step, c.commands_applied, false, i});
  }
  for (std::size_t i = 0; i < log.states.size(); ++i) {
    const auto& st = log.states[i];
    marks.push_back({st.generation, st.step, st.commands_applied, true, i});
  }
  std::stable_sort(marks.begin(), marks.end(), [](const Mark& a, const Mark& b) {
    return std::tie(a.generation, a.step, a.commands, a.is_state) < std::tie(b.generation, b.step, b.commands, b.is_state);
  });
  for (const Mark& m : marks) {
    const double t = m.is_state ? log.states[m.index].sim_time : log.checkpoints[m.index].sim_time;
    if (!reach(m.generation, m.step, m.commands)) {
      r.identical = false;
      r.difference = "could not reach the recorded " + std::string(m.is_state ? "state" : "checkpoint") + " at " +
                     at(m.generation, m.step, t) + " with " + std::to_string(m.commands) + " commands taken";
      break;
    }
    if (m.is_state) {
      if (const std::string d = compare(log.states[m.index], *session); !d.empty()) {
        r.identical = false;
        r.difference = at(m.generation, m.step, t) + ": " + d;
        break;
      }
      ++r.states;
      continue;
    }
    if (static_cast<std::int64_t>(session->state_hash()) != log.checkpoints[m.index].state_hash) {
      r.identical = false;
      r.difference = "the complete state at " + at(m.generation, m.step, t) +
                     " differs from the recorded one (checkpoint hash)";
      break;
    }
    ++r.checkpoints;
    if (static_cast<long>(m.index) == stop_after_checkpoint) break;
  }
  r.sim_time = session->sim().time();
  return r;
}

}  // namespace ladder::daemon
