// ladder-ripple: how far one ripple runs down a ladder, and how long each flip takes, against the number of blocks,
// the rounded ends' radius and the drag (docs/ripple.md). Each run is a scene (the classic one by default) with
// those three settings changed, tipped once by its timeline, simulated offline; the ripple's front is the hinges
// whose first flip-flops came one after the other, 1, 2, 3, ..., in time order. Writes ripple.csv, ripple.md and
// ripple.png to --out.
#include "scene/simulation.hpp"

#include <CLI/CLI.hpp>
#include <cairo.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

namespace {

using namespace ladder;

struct Run {
  int blocks = 0;
  double radius_fraction = 0;  // end_radius / thickness
  double drag = 0;             // damping.linear = damping.angular [1/s]
  bool failed = false;
  std::string failure;
  int front = 0;                 // last hinge of the ripple's front
  double front_time = 0;         // when it flip-flopped [s]
  double flip_time = 0;          // mean time from one hinge's first flip-flop to the next one's along the front [s]
  double lost_per_flip = 0;      // energy removed by events and dissipated by drag up to the front's end, per flip [J]
  double released_per_flip = 0;  // m g L: what each flip releases (the toppling block's centre drops by L) [J]
  int flips = 0, locks = 0, unlocks = 0, other_events = 0;
  double wall = 0;
};

std::string fmt(double v, const char* f = "%.3g") {
  char b[64];
  std::snprintf(b, sizeof b, f, v);
  return b;
}

Run run_one(const std::string& text, const std::string& source, int blocks, double radius_fraction, double drag,
            double duration) {
  Run r;
  r.blocks = blocks;
  r.radius_fraction = radius_fraction;
  r.drag = drag;
  const auto t0 = std::chrono::steady_clock::now();
  try {
    std::vector<std::string> set{"ladder.blocks=" + std::to_string(blocks), "damping.linear=" + fmt(drag, "%.17g"),
                                 "damping.angular=" + fmt(drag, "%.17g")};
    scene::Scene base = scene::parse_scene(text, source, set);
    // Both keys every time: the scene may have rolling hinges of its own.
    set.push_back(radius_fraction > 0 ? "ladder.hinge=rolling" : "ladder.hinge=corner");
    set.push_back("ladder.end_radius=" + fmt(radius_fraction * base.ladder.thickness, "%.17g"));
    scene::Simulation sim(scene::parse_scene(text, source, set));
    const model::LadderSpec& spec = sim.ladder().spec();
    r.released_per_flip = spec.mass * sim.scene().options.gravity.norm() * spec.length;
    std::map<int, double> first;
    std::vector<std::pair<double, double>> removed;  // (t, energy) of every event, and the drag's per step
    // A run ends at `duration`, or once the ripple has stalled: no hinge has flip-flopped for the first time in the
    // last 5 s (measured: one flip takes 0.1 to 0.2 s on every ladder of docs/ripple.md).
    double last_new = 0;
    while (sim.time() < duration - 1e-9 && !(first.size() > 0 && sim.time() > last_new + 5)) {
      sim.step();
      const double dissipated = sim.ladder().world().last_step().dissipated;
      if (dissipated != 0) removed.push_back({sim.time(), dissipated});
      for (const model::Event& e : sim.take_events()) {
        switch (e.kind) {
          case model::EventKind::FlipFlop:
            ++r.flips;
            if (first.emplace(e.hinge, e.t).second) last_new = e.t;
            break;
          case model::EventKind::Lock: ++r.locks; break;
          case model::EventKind::Unlock: ++r.unlocks; break;
          default: ++r.other_events; break;
        }
        removed.push_back({e.t, e.energy_removed});
      }
    }
    std::vector<std::pair<double, int>> order;
    for (const auto& [h, t] : first) order.push_back({t, h});
    std::sort(order.begin(), order.end());
    for (const auto& [t, h] : order) {
      if (h != r.front + 1) break;
      r.front = h;
      r.front_time = t;
    }
    if (r.front > 1) r.flip_time = (r.front_time - first[1]) / (r.front - 1);
    if (r.front > 0) {
      double lost = 0;
      for (const auto& [t, e] : removed)
        if (t >= first[1] && t <= r.front_time) lost += e;
      r.lost_per_flip = r.front > 1 ? lost / (r.front - 1) : 0;
    }
  } catch (const std::exception& e) {
    r.failed = true;
    r.failure = e.what();
  }
  r.wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return r;
}

void write_csv(const std::string& path, const std::vector<Run>& runs) {
  std::ofstream out(path);
  out << "blocks,end_radius_over_thickness,drag_per_s,failed,front_hinge,reached_bottom,front_time_s,flip_time_s,"
         "lost_per_flip_J,released_per_flip_J,flip_flops,locks,unlocks,wall_s\n";
  for (const Run& r : runs)
    out << r.blocks << ',' << r.radius_fraction << ',' << r.drag << ',' << (r.failed ? 1 : 0) << ',' << r.front << ','
        << (r.front == r.blocks - 1 ? 1 : 0) << ',' << fmt(r.front_time, "%.6g") << ',' << fmt(r.flip_time, "%.6g")
        << ',' << fmt(r.lost_per_flip, "%.6g") << ',' << fmt(r.released_per_flip, "%.6g") << ',' << r.flips << ','
        << r.locks << ',' << r.unlocks << ',' << fmt(r.wall, "%.3g") << '\n';
}

void write_markdown(const std::string& path, const std::vector<Run>& runs, const std::string& header) {
  std::ofstream out(path);
  out << header << "\n\n";
  std::vector<double> drags, radii;
  std::vector<int> blocks;
  for (const Run& r : runs) {
    if (std::find(drags.begin(), drags.end(), r.drag) == drags.end()) drags.push_back(r.drag);
    if (std::find(radii.begin(), radii.end(), r.radius_fraction) == radii.end()) radii.push_back(r.radius_fraction);
    if (std::find(blocks.begin(), blocks.end(), r.blocks) == blocks.end()) blocks.push_back(r.blocks);
  }
  for (const double d : drags) {
    out << "### Drag " << fmt(d) << " /s\n\nHow far the first ripple ran (the last hinge of its front, of N - 1), "
        << "and the mean time per flip along it:\n\n| N |";
    for (const double f : radii) out << " r = " << (f == 0 ? std::string("0 (corners)") : fmt(f) + " T") << " |";
    out << "\n|---|";
    for (size_t i = 0; i < radii.size(); ++i) out << "---|";
    out << '\n';
    for (const int n : blocks) {
      out << "| " << n << " |";
      for (const double f : radii)
        for (const Run& r : runs)
          if (r.drag == d && r.blocks == n && r.radius_fraction == f)
            out << ' '
                << (r.failed ? std::string("failed")
                             : std::to_string(r.front) + " of " + std::to_string(n - 1) +
                                   (r.front > 1 ? ", " + fmt(r.flip_time * 1e3, "%.0f") + " ms" : std::string()))
                << " |";
      out << '\n';
    }
    out << '\n';
  }
}

// One panel per drag: the fraction of the ladder the ripple ran down, against N, one line per radius.
void write_png(const std::string& path, const std::vector<Run>& runs) {
  std::vector<double> drags, radii;
  int max_n = 2;
  for (const Run& r : runs) {
    if (std::find(drags.begin(), drags.end(), r.drag) == drags.end()) drags.push_back(r.drag);
    if (std::find(radii.begin(), radii.end(), r.radius_fraction) == radii.end()) radii.push_back(r.radius_fraction);
    max_n = std::max(max_n, r.blocks);
  }
  const int panel_w = 420, panel_h = 300, margin = 50;
  const int width = static_cast<int>(drags.size()) * panel_w, height = panel_h + 60;
  cairo_surface_t* surface = cairo_image_surface_create(CAIRO_FORMAT_RGB24, width, height);
  cairo_t* cr = cairo_create(surface);
  cairo_set_source_rgb(cr, 1, 1, 1);
  cairo_paint(cr);
  cairo_select_font_face(cr, "sans-serif", CAIRO_FONT_SLANT_NORMAL, CAIRO_FONT_WEIGHT_NORMAL);
  cairo_set_font_size(cr, 12);
  const double colours[][3] = {{0, 0, 0}, {0.8, 0.1, 0.1}, {0.1, 0.4, 0.8}, {0.1, 0.6, 0.2}, {0.6, 0.3, 0.7}};
  for (size_t p = 0; p < drags.size(); ++p) {
    const double x0 = static_cast<double>(p) * panel_w + margin, y0 = 20, w = panel_w - 1.5 * margin,
                 h = panel_h - margin;
    const auto px = [&](int n) { return x0 + w * std::log(n / 2.0) / std::log(max_n / 2.0); };
    const auto py = [&](double f) { return y0 + h * (1 - f); };
    cairo_set_source_rgb(cr, 0, 0, 0);
    cairo_set_line_width(cr, 1);
    cairo_rectangle(cr, x0, y0, w, h);
    cairo_stroke(cr);
    cairo_move_to(cr, x0, y0 + h + 18);
    cairo_show_text(cr, ("blocks N (log), drag " + fmt(drags[p]) + " /s").c_str());
    cairo_move_to(cr, x0 - 40, y0 - 5);
    cairo_show_text(cr, "front / (N - 1)");
    std::vector<int> ticks;
    for (const Run& r : runs)
      if (std::find(ticks.begin(), ticks.end(), r.blocks) == ticks.end()) ticks.push_back(r.blocks);
    for (const int n : ticks) {
      cairo_move_to(cr, px(n) - 8, y0 + h + 32);
      cairo_show_text(cr, std::to_string(n).c_str());
    }
    for (const double f : {0.0, 0.5, 1.0}) {
      cairo_move_to(cr, x0 - 28, py(f) + 4);
      cairo_show_text(cr, fmt(f).c_str());
    }
    for (size_t i = 0; i < radii.size(); ++i) {
      const double* c = colours[i % 5];
      cairo_set_source_rgb(cr, c[0], c[1], c[2]);
      cairo_set_line_width(cr, 2);
      bool started = false;
      for (const Run& r : runs) {
        if (r.drag != drags[p] || r.radius_fraction != radii[i] || r.failed) continue;
        const double f = static_cast<double>(r.front) / (r.blocks - 1);
        if (started)
          cairo_line_to(cr, px(r.blocks), py(f));
        else
          cairo_move_to(cr, px(r.blocks), py(f));
        started = true;
      }
      cairo_stroke(cr);
      for (const Run& r : runs) {  // a dot per run
        if (r.drag != drags[p] || r.radius_fraction != radii[i] || r.failed) continue;
        cairo_arc(cr, px(r.blocks), py(static_cast<double>(r.front) / (r.blocks - 1)), 3, 0, 2 * M_PI);
        cairo_fill(cr);
      }
      cairo_move_to(cr, x0 + w - 110, y0 + 16 + 14 * static_cast<double>(i));
      cairo_show_text(cr, ("r = " + (radii[i] == 0 ? std::string("0 (corners)") : fmt(radii[i]) + " T")).c_str());
    }
  }
  cairo_destroy(cr);
  cairo_surface_write_to_png(surface, path.c_str());
  cairo_surface_destroy(surface);
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"ladder-ripple: how far one ripple runs down a ladder and how long each flip takes, against the number "
               "of blocks, the rounded ends' radius (rolling hinges; 0 is the corner hinge) and the drag. Each run is "
               "the scene (tipped once by its timeline) with those settings, simulated offline. Writes ripple.csv, "
               "ripple.md and ripple.png to --out (docs/ripple.md)."};
  std::string scene_path = LADDER_SOURCE_DIR "/config/scenes/classic.toml", out = "out/ripple";
  std::vector<int> blocks{6, 16, 64, 256, 1000};
  std::vector<double> radii{0, 0.25, 0.5}, drags{0, 0.1};
  double duration = 0;  // 0: 2 s plus 0.3 s per block
  app.add_option("--scene", scene_path, "the scene to start from")->check(CLI::ExistingFile);
  app.add_option("--blocks", blocks, "ladder.blocks values")->check(CLI::Range(2, 100000));
  app.add_option("--radius", radii, "ladder.end_radius values, as fractions of the thickness (0: corner hinges)")
      ->check(CLI::Range(0.0, 0.5));
  app.add_option("--drag", drags, "damping.linear = damping.angular values [1/s]")->check(CLI::Range(0.0, 100.0));
  app.add_option("--duration", duration,
                 "simulated time per run [s] (default: 2 s + 0.3 s per block); a run whose ripple has stalled, no new "
                 "hinge flip-flopping for 5 s, ends there")
      ->check(CLI::Range(0.0, 1e6));
  app.add_option("--out", out, "output directory");
  CLI11_PARSE(app, argc, argv);

  std::ifstream in(scene_path);
  std::stringstream text;
  text << in.rdbuf();
  std::filesystem::create_directories(out);
  std::vector<Run> runs;
  const size_t total = blocks.size() * radii.size() * drags.size();
  const auto start = std::chrono::steady_clock::now();
  for (const double d : drags)
    for (const double f : radii)
      for (const int n : blocks) {
        const double t = duration > 0 ? duration : 2 + 0.3 * n;
        runs.push_back(run_one(text.str(), scene_path, n, f, d, t));
        const Run& r = runs.back();
        std::fprintf(stderr, "[%zu/%zu %4.0f s] N = %d, r = %g T, drag %g /s: %s\n", runs.size(), total,
                     std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(), n, f, d,
                     r.failed ? ("failed: " + r.failure).c_str()
                              : ("front at hinge " + std::to_string(r.front) + " of " + std::to_string(n - 1)).c_str());
      }
  write_csv(out + "/ripple.csv", runs);
  write_markdown(out + "/ripple.md", runs,
                 "Generated by `ladder-ripple` from " + std::filesystem::path(scene_path).filename().string() + ".");
  write_png(out + "/ripple.png", runs);
  std::cout << "wrote " << out << "/ripple.csv, ripple.md and ripple.png (" << runs.size() << " runs)\n";
  return 0;
}
