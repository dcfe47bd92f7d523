// Frame time of the drawing module on a 100 000-block ladder: a window's worth of it (what the viewer shows by
// default), the view far down the ladder, and the whole ladder at once (drawn as a line, the level of detail for
// blocks of a few pixels). `ladder-view-bench` prints the figures.
#include "draw.hpp"

#include <benchmark/benchmark.h>

#include <cmath>

namespace {

using namespace ladder;

struct Ladder {
  client::SceneInfo info;
  client::State state;
  explicit Ladder(int n) {
    info.blocks = static_cast<std::uint32_t>(n);
    info.length = 0.064;
    info.thickness = 0.013;
    const double tilt = std::atan(0.013 / 0.064);
    for (int i = 0; i < n; ++i) {
      state.blocks.push_back({i % 2 ? 0.004 : 0.0, -0.066 * i, i % 2 ? tilt : -tilt});
      state.hinges.push_back({static_cast<std::uint8_t>(i % 2 ? 0 : 3), ladder_msg_HINGED, 0});
    }
  }
};

void frame(benchmark::State& bm, const view::Camera& cam, const Ladder& l) {
  cairo_surface_t* surface = cairo_image_surface_create(CAIRO_FORMAT_ARGB32, cam.width, cam.height);
  cairo_t* cr = cairo_create(surface);
  int drawn = 0;
  for (auto _ : bm) drawn = view::draw(cr, cam, l.info, l.state, view::Hud{});
  bm.counters["blocks_drawn"] = drawn;
  cairo_destroy(cr);
  cairo_surface_destroy(surface);
}

const Ladder& big() {
  static const Ladder l(100000);
  return l;
}

void BM_Top(benchmark::State& bm) { frame(bm, view::fit(big().info, big().state, 1280, 800), big()); }
void BM_FarDown(benchmark::State& bm) {
  view::Camera cam = view::fit(big().info, big().state, 1280, 800);
  cam.cy = -0.066 * 70000;
  frame(bm, cam, big());
}
void BM_Whole(benchmark::State& bm) {
  frame(bm, view::fit(big().info, big().state, 1280, 800, 100000), big());
}
BENCHMARK(BM_Top)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_FarDown)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Whole)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
