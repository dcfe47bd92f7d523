// --png FILE [--at SIMTIME]: one snapshot of the first state at or after SIMTIME (the latest state without --at).
#include "app.hpp"

#include <chrono>
#include <cstdio>
#include <iostream>
#include <string>

namespace ladder::view {

namespace {
std::string fixed3(double t) { return client::fixed(t, 3); }
}  // namespace

int run_png(const Options& o) {
  // Before any waiting: a snapshot that cannot be written is known now, not after the server is found.
  if (const std::string why = client::unwritable(o.png); !why.empty()) {
    std::cerr << "ladder-view: cannot write " << o.png << ": " << why << "\n";
    return 1;
  }
  client::Client c(o.domain, o.sim_id);
  if (!found_server(o, c)) return kNoServer;
  // Wait for the state as long as the server keeps talking (a far --at may take a while).
  Feed feed(c);
  bool told = false, first = true;
  bool was_paused = false;
  std::chrono::steady_clock::time_point paused_since{};
  client::State state;
  client::SceneInfo info;
  while (true) {
    feed.update(client::Millis(50));
    const client::State* s = feed.state();
    if (s && (!o.at || s->sim_time >= *o.at)) {
      state = *s;  // this state and its scene, whatever comes while the Stats are awaited below
      info = *feed.info();
      // The first state seen is already later than --at: the server was past it when the viewer came.
      if (o.at && first && s->sim_time > *o.at)
        std::cerr << "ladder-view: ladderd '" << o.sim_id << "' was already at t = " << fixed3(s->sim_time)
                  << " s, past --at " << *o.at << " s; the snapshot is of t = " << fixed3(s->sim_time) << " s\n";
      break;
    }
    first = first && !s;
    if (feed.undrawable() > o.timeout) {
      std::cerr << "ladder-view: nothing to draw from ladderd '" << o.sim_id << "' in " << o.timeout
                << " s: " << feed.why_undrawable() << "\n";
      return kNoServer;
    }
    if (feed.quiet() > o.timeout) {
      std::cerr << "ladder-view: ladderd '" << o.sim_id << "' stopped talking before t = " << o.at.value_or(0)
                << " s\n";
      return kNoServer;
    }
    if (s && s->paused && !told) {
      std::cerr << "ladder-view: waiting for t >= " << *o.at << " s; the simulation is paused at t = " << s->sim_time
                << " s\n";
      told = true;
    }
    // Paused for --timeout on end, short of --at: a script waiting on the snapshot would wait for ever.
    if (s && s->paused) {
      if (!was_paused) paused_since = std::chrono::steady_clock::now();
      was_paused = true;
      if (std::chrono::duration<double>(std::chrono::steady_clock::now() - paused_since).count() > o.timeout) {
        std::cerr << "ladder-view: the simulation stayed paused at t = " << fixed3(s->sim_time) << " s for "
                  << o.timeout << " s (--timeout), short of --at " << *o.at
                  << " s; resume it (ladderctl resume) or give a longer --timeout\n";
        return kNoServer;
      }
    } else {
      was_paused = false;
    }
  }
  // The real-time factor is measured once a second; give it that long to arrive.
  for (int i = 0; i < 24 && !feed.stats(); ++i) feed.update(client::Millis(50));

  const Camera cam = camera_for(o, info, state, o.width, o.height);
  Hud hud;
  hud.title = (info.replay ? o.sim_id + " (REPLAY)" : o.sim_id) + "  " + scene_label(info.scene_name);
  if (feed.stats()) hud.real_time_factor = feed.stats()->real_time_factor;
  hud.numbers = o.numbers;
  cairo_surface_t* surface = cairo_image_surface_create(CAIRO_FORMAT_ARGB32, o.width, o.height);
  cairo_t* cr = cairo_create(surface);
  draw(cr, cam, info, state, hud);
  // (A drawing that failed, e.g. on text that was not UTF-8, leaves the context in an error state and the rest of
  // the picture undrawn: not a snapshot to write.)
  const cairo_status_t drawn = cairo_status(cr);
  cairo_destroy(cr);
  const std::string why = drawn == CAIRO_STATUS_SUCCESS
                              ? write_png(surface, o.png)
                              : std::string("drawing failed: ") + cairo_status_to_string(drawn);
  cairo_surface_destroy(surface);
  if (!why.empty()) {
    std::cerr << "ladder-view: cannot write " << o.png << ": " << why << "\n";
    return kFailed;
  }
  char buf[320];
  std::snprintf(buf, sizeof buf, "ladder-view: wrote %s (%dx%d px): t = %.6f s, seq %llu, %zu blocks; ", o.png.c_str(),
                o.width, o.height, state.sim_time, static_cast<unsigned long long>(state.seq), state.blocks.size());
  std::cout << buf << camera_text(cam) << "\n";
  return kOk;
}

}  // namespace ladder::view
