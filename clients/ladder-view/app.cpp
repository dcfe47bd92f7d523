#include "app.hpp"

#include "ladder/printable.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <utility>

namespace ladder::view {

bool Feed::update(client::Millis wait) {
  // Waits on Stats: the client counts only those that arrive during the call, and the same polls take states.
  if (auto st = client_.wait_stats([](const ladder_msg_Stats&) { return true; }, wait)) {
    stats_ = st;
    news_ = Clock::now();
  }
  // Only a state that can be drawn is news: one whose SceneInfo (same generation) has come too. The two topics are
  // delivered independently, so a late joiner or a reset can see the State first.
  const client::State* s = state();
  if (s) drawable_ = Clock::now();
  if (!s || (any_ && s->seq == seq_ && s->generation == generation_ && s->sim_time == sim_time_)) return false;
  any_ = true;
  seq_ = s->seq;
  generation_ = s->generation;
  sim_time_ = s->sim_time;
  news_ = Clock::now();
  return true;
}

const client::State* Feed::state() const {
  const auto& s = client_.latest_state();
  const auto& i = client_.scene_info();
  return s && i && s->generation == i->generation ? &*s : nullptr;
}

const client::SceneInfo* Feed::info() const { return state() ? &*client_.scene_info() : nullptr; }

std::string Feed::why_undrawable() const {
  const auto& s = client_.latest_state();
  const auto& i = client_.scene_info();
  if (!s && client_.states_malformed() > 0)
    return std::to_string(client_.states_malformed()) + " States came, none drawable (not a ladderd's: sequences of " +
           "different lengths, a number that is not finite, a negative sim time, or more grips than blocks)";
  if (!s) return "no State has come";
  if (!i) return "no SceneInfo has come";
  return "the States are of scene generation " + std::to_string(s->generation) + " but the SceneInfo of generation " +
         std::to_string(i->generation) + " (is another program publishing under this sim id?)";
}

void Outbox::send(const ladder_msg_Command& c, const std::string& what) {
  if (!client_.wait_for_server(client::Millis(0))) {
    ready_.push_back(what + ": not sent, no server");
    return;
  }
  pending_.push_back({client_.send(c), what, std::chrono::steady_clock::now()});
}

std::vector<std::string> Outbox::take() {
  constexpr auto kAnswerTimeout = std::chrono::seconds(5);
  for (auto it = pending_.begin(); it != pending_.end();) {
    const auto a = client_.wait_ack(it->id, client::Millis(0));
    if (!a && std::chrono::steady_clock::now() - it->sent < kAnswerTimeout) {
      ++it;
      continue;
    }
    char buf[96];
    if (a && a->accepted) std::snprintf(buf, sizeof buf, "accepted at t = %s s", client::fixed(a->sim_time, 3).c_str());
    ready_.push_back(it->what + ": " + (a ? (a->accepted ? std::string(buf) : "refused: " + a->reason) : "no answer"));
    it = pending_.erase(it);
  }
  if (!ready_.empty()) {
    last_ = ready_.back();
    last_at_ = std::chrono::steady_clock::now();
  }
  return std::exchange(ready_, {});
}

bool found_server(const Options& o, client::Client& c) {
  if (c.wait_for_server(client::Millis(static_cast<long>(o.timeout * 1000)))) return true;
  std::cerr << "ladder-view: " << c.no_server(o.timeout) << "\n";
  return false;
}

Camera camera_for(const Options& o, const client::SceneInfo& info, const client::State& state, int width,
                  int height) {
  if (!o.view) return o.side ? fit(info, state, width, height, 40, 0, 0) : fit(info, state, width, height);
  Camera c = *o.view;
  c.width = width;
  c.height = height;
  return c;
}

std::string camera_text(const Camera& c) {
  char buf[160];
  std::snprintf(buf, sizeof buf, "view centre %.9g,%.9g m, %.9g px/m, yaw %.9g deg, pitch %.9g deg", c.cx, c.cy,
                c.scale, c.yaw * 180 / M_PI, c.pitch * 180 / M_PI);
  return buf;
}

std::string scene_label(const std::string& name, std::size_t max_chars) {
  const std::string_view head = first_characters(name, max_chars);
  std::string out(1, '\'');
  out.append(head);
  out.append(head.size() < name.size() ? "...'" : "'");
  return out;
}

std::vector<std::string> stats_lines(const client::SceneInfo& info, const std::optional<ladder_msg_Stats>& stats) {
  std::vector<std::string> lines{"scene " + scene_label(info.scene_name, kOverlayColumns - 12)};
  char buf[160];
  std::snprintf(buf, sizeof buf, "%u blocks, top %.12s, dt %g ms", info.blocks, info.top.c_str(), info.dt * 1e3);
  lines.emplace_back(buf);
  if (stats) {
    std::snprintf(buf, sizeof buf, "step p50 %.3g us, p99 %.3g us", stats->step_p50_us, stats->step_p99_us);
    lines.emplace_back(buf);
    std::snprintf(buf, sizeof buf, "missed ticks %llu", static_cast<unsigned long long>(stats->missed_deadlines));
    lines.emplace_back(buf);
    std::snprintf(buf, sizeof buf, "solver %u it, residual %.2g m", stats->solver_iterations, stats->solver_residual);
    lines.emplace_back(buf);
    std::snprintf(buf, sizeof buf, "largest hinge error %.2g m", stats->max_hinge_error);
    lines.emplace_back(buf);
    std::snprintf(buf, sizeof buf, "energy %.6g J", stats->energy);
    lines.emplace_back(buf);
    std::snprintf(buf, sizeof buf, "commands %llu accepted, %llu refused",
                  static_cast<unsigned long long>(stats->commands_accepted),
                  static_cast<unsigned long long>(stats->commands_refused));
    lines.emplace_back(buf);
  }
  std::vector<std::string> out;  // (a peer's figures may be long: 20 digits of a count)
  for (const std::string& l : lines)
    for (std::string& w : wrap(l, kOverlayColumns)) out.push_back(std::move(w));
  return out;
}

std::vector<std::string> wrap(const std::string& text, std::size_t columns) {
  columns = std::max<std::size_t>(columns, 1);  // (0 would cut a word into empty lines for ever)
  const auto starts = [](char c) { return (static_cast<unsigned char>(c) & 0xC0) != 0x80; };  // a character
  const auto count = [&](const std::string& w) {
    return static_cast<std::size_t>(std::count_if(w.begin(), w.end(), starts));
  };
  std::vector<std::string> out;
  std::string line;
  for (std::size_t at = 0; at <= text.size();) {
    const std::size_t space = std::min(text.find(' ', at), text.size());
    std::string word = text.substr(at, space - at);
    at = space + 1;
    if (!line.empty() && count(line) + 1 + count(word) > columns) out.push_back(std::exchange(line, {}));
    while (count(word) > columns) {  // a word longer than a line (a path): cut into lines of its own
      const std::size_t cut = first_characters(word, columns).size();
      if (!line.empty()) out.push_back(std::exchange(line, {}));
      out.push_back(word.substr(0, cut));
      word.erase(0, cut);
    }
    if (!line.empty()) line += ' ';
    line += word;
  }
  out.push_back(line);
  return out;
}

}  // namespace ladder::view
