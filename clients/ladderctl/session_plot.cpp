#include "session_plot.hpp"

#include "ladderlcm/state_t.hpp"
#include "transport/lcm_log.hpp"
#include "plot.hpp"  // the viewer's plots (clients/ladder-view)

#include <chrono>
#include <cstdio>
#include <iostream>

namespace ladder::ctl {

namespace {

// "wrote out.png (900x600 px): 5 flip-flops at hinges 1 to 5 over t = 0.000 to 4.000 s, energy -0.2787 to
// -0.2769 J" (or why it was not written).
// `empty_code`: the exit code when there is no state (2 for a log, bad input; 1 for a server that sent none).
// The plot shows the last run of the history (a reset or a load starts it again), and says so when there were more.
int finish(const view::History& h, const PlotOptions& o, const std::string& from, int empty_code) {
  if (h.energy().empty()) {
    std::cerr << "ladderctl: plot: no state in " << from << "; nothing written\n";
    return empty_code;
  }
  if (const std::string why = view::write_plots_png(h, o.png, o.width, o.height); !why.empty()) {
    std::cerr << "ladderctl: plot: cannot write " << o.png << ": " << why << "\n";
    return 1;
  }
  double lo = h.energy().front().y, hi = lo, first = 0, last = 0;
  for (const view::Point& e : h.energy()) lo = std::min(lo, e.y), hi = std::max(hi, e.y);
  if (!h.flips().empty()) {
    first = h.flips().front().y;
    last = first;
    for (const view::Point& f : h.flips()) first = std::min(first, f.y), last = std::max(last, f.y);
  }
  std::printf("wrote %s (%dx%d px) from %s: %zu flip-flops", o.png.c_str(), o.width, o.height, from.c_str(),
              h.flips().size());
  if (!h.flips().empty()) std::printf(" at hinges %.0f to %.0f", first, last);
  std::printf(" over t = %.3f to %.3f s, energy %.6g to %.6g J", h.energy().front().x, h.energy().back().x, lo, hi);
  if (h.runs() > 1)
    std::printf(" (the last of %d runs: each reset or load, or a state earlier than the one before it, starts the "
                "plot again)",
                h.runs());
  std::printf("\n");
  return 0;
}

}  // namespace

int plot_log(const PlotOptions& o) {
  view::History h;
  try {
    transport::LogReader reader(o.log);
    while (const auto e = reader.next()) {
      if (e->channel != transport::kStateChannel) continue;
      const auto s = reader.decode<ladderlcm::state_t>(*e);
      std::vector<std::uint32_t> flips(s.flips.begin(), s.flips.end());
      h.add(static_cast<std::uint32_t>(s.generation), s.sim_time, s.energy, flips);
    }
    if (!reader.damage().empty()) std::cerr << "ladderctl: " << o.log << ": " << reader.damage() << "\n";
  } catch (const std::exception& e) {
    std::cerr << "ladderctl: " << e.what() << "\n";
    return 2;
  }
  return finish(h, o, o.log, 2);
}

int plot_live(client::Client& c, const PlotOptions& o) {
  view::History h;
  std::uint64_t seen = 0;
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(o.seconds);
  while (std::chrono::steady_clock::now() < end) {
    const auto s = c.wait_state([&](const client::State& st) { return st.seq > seen; }, client::Millis(100));
    if (!s || s->seq <= seen) continue;
    seen = s->seq;
    std::vector<std::uint32_t> flips;
    for (const client::Hinge& k : s->hinges) flips.push_back(k.flips);
    h.add(s->generation, s->sim_time, s->energy, flips);
  }
  char from[64];
  std::snprintf(from, sizeof from, "%g s of the running server", o.seconds);
  return finish(h, o, from, 1);
}

}  // namespace ladder::ctl
