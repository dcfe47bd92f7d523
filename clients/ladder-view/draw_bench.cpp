// Frame time of the drawing module on a hanging ladder of 6, 1000 and 100 000 blocks, 1280x800 pixels: the window's
// default view (the top 40 blocks in 3-D, with the hand, tapes, hinges, numbers and scale bar), the same seen from
// the side, the view far down the ladder, and the whole ladder at once (its blocks a few pixels or less: boxes
// without tapes, then one line); the first two again with rolling hinges (rounded ends). `ladder-view-bench` prints
// the figures (docs/viewer.md).
#include "draw.hpp"

#include <benchmark/benchmark.h>

#include <cmath>
#include <map>
#include <utility>

namespace {

using namespace ladder;

struct Ladder {
  client::SceneInfo info;
  client::State state;
  // rolling: fully rounded ends (rolling hinges, end radius half the thickness), which hang in a straight column.
  Ladder(int n, bool rolling) {
    info.blocks = static_cast<std::uint32_t>(n);
    info.length = 0.064;
    info.thickness = 0.013;
    info.top = "held";
    if (rolling) info.options = "ladder.hinge=rolling\nladder.end_radius=0.0065\n";
    const double tilt = rolling ? 0 : std::atan(0.013 / 0.064);
    for (int i = 0; i < n; ++i) {
      state.blocks.push_back({i % 2 && !rolling ? 0.004 : 0.0, (rolling ? -0.064 : -0.066) * i, i % 2 ? tilt : -tilt});
      state.hinges.push_back({static_cast<std::uint8_t>(i % 2 ? 0 : 3), ladder_msg_HINGED, 0});
    }
  }
};

const Ladder& ladder(int n, bool rolling = false) {
  static std::map<std::pair<int, bool>, Ladder> made;
  return made.try_emplace({n, rolling}, n, rolling).first->second;
}

void frame(benchmark::State& bm, const view::Camera& cam, const Ladder& l) {
  cairo_surface_t* surface = cairo_image_surface_create(CAIRO_FORMAT_ARGB32, cam.width, cam.height);
  cairo_t* cr = cairo_create(surface);
  view::Hud hud;
  hud.numbers = true;
  int drawn = 0;
  for (auto _ : bm) drawn = view::draw(cr, cam, l.info, l.state, hud);
  bm.counters["blocks_drawn"] = drawn;
  cairo_destroy(cr);
  cairo_surface_destroy(surface);
}

void BM_Default(benchmark::State& bm) {
  const Ladder& l = ladder(static_cast<int>(bm.range(0)));
  frame(bm, view::fit(l.info, l.state, 1280, 800), l);
}
void BM_Side(benchmark::State& bm) {
  const Ladder& l = ladder(static_cast<int>(bm.range(0)));
  frame(bm, view::fit(l.info, l.state, 1280, 800, 40, 0, 0), l);
}
void BM_FarDown(benchmark::State& bm) {
  const Ladder& l = ladder(static_cast<int>(bm.range(0)));
  view::Camera cam = view::fit(l.info, l.state, 1280, 800);
  cam.cy = -0.066 * 0.7 * static_cast<double>(bm.range(0));
  frame(bm, cam, l);
}
void BM_Whole(benchmark::State& bm) {
  const Ladder& l = ladder(static_cast<int>(bm.range(0)));
  frame(bm, view::fit(l.info, l.state, 1280, 800, static_cast<int>(bm.range(0))), l);
}
// The same two views of a ladder with rolling hinges: rounded ends, their tapes, the tapes as lines in the side view.
void BM_DefaultRolling(benchmark::State& bm) {
  const Ladder& l = ladder(static_cast<int>(bm.range(0)), true);
  frame(bm, view::fit(l.info, l.state, 1280, 800), l);
}
void BM_SideRolling(benchmark::State& bm) {
  const Ladder& l = ladder(static_cast<int>(bm.range(0)), true);
  frame(bm, view::fit(l.info, l.state, 1280, 800, 40, 0, 0), l);
}
BENCHMARK(BM_Default)->Arg(6)->Arg(1000)->Arg(100000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_DefaultRolling)->Arg(6)->Arg(1000)->Arg(100000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Side)->Arg(6)->Arg(1000)->Arg(100000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_SideRolling)->Arg(6)->Arg(1000)->Arg(100000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_FarDown)->Arg(1000)->Arg(100000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Whole)->Arg(6)->Arg(1000)->Arg(100000)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
