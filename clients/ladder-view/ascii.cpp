#include "ascii.hpp"

#include "app.hpp"

#include <sys/ioctl.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <csignal>
#include <cstdio>
#include <iostream>

namespace ladder::view {

namespace {

std::atomic<bool> g_stop{false};
extern "C" void on_stop(int) { g_stop = true; }

// The palette entry nearest a pixel (Cairo antialiases edges into blends) and its character, by priority: a
// character cell shows the most telling of the two pixels it covers.
struct Glyph {
  Rgb colour;
  char ch;
  int priority;
};
constexpr Glyph kGlyphs[] = {{kBackground, ' ', 0}, {kDepth, ':', 1},   {kFaceEven, '#', 2}, {kFaceOdd, '#', 2},
                             {kRibbon, '+', 3},     {kHinge, 'o', 4},   {kLocked, '@', 5},   {kBroken, 'x', 5},
                             {kGrip, '*', 5}};

const Glyph& nearest(std::uint32_t argb) {
  const int r = static_cast<int>((argb >> 16) & 0xff), g = static_cast<int>((argb >> 8) & 0xff),
            b = static_cast<int>(argb & 0xff);
  const Glyph* best = &kGlyphs[0];
  int best_d = 1 << 30;
  for (const Glyph& gl : kGlyphs) {
    const int d = (r - gl.colour.r) * (r - gl.colour.r) + (g - gl.colour.g) * (g - gl.colour.g) +
                  (b - gl.colour.b) * (b - gl.colour.b);
    if (d < best_d) {
      best_d = d;
      best = &gl;
    }
  }
  return *best;
}

// The terminal's size in characters, or the fallback.
void terminal_size(int& cols, int& rows) {
  winsize ws{};
  if (ioctl(STDOUT_FILENO, TIOCGWINSZ, &ws) == 0 && ws.ws_col > 0 && ws.ws_row > 0) {
    cols = ws.ws_col;
    rows = ws.ws_row;
  }
}

}  // namespace

std::string render_ascii(const Camera& cam, const client::SceneInfo& info, const client::State& state, int cols,
                         int rows) {
  cairo_surface_t* surface = cairo_image_surface_create(CAIRO_FORMAT_RGB24, cols, 2 * rows);
  cairo_t* cr = cairo_create(surface);
  Hud hud;
  hud.show = false;
  draw(cr, cam, info, state, hud);
  cairo_destroy(cr);
  cairo_surface_flush(surface);
  const unsigned char* data = cairo_image_surface_get_data(surface);
  const int stride = cairo_image_surface_get_stride(surface);
  const auto pixel = [&](int x, int y) {
    return *reinterpret_cast<const std::uint32_t*>(data + static_cast<std::ptrdiff_t>(y) * stride + 4 * x);
  };
  std::vector<std::string> lines(static_cast<std::size_t>(rows), std::string(static_cast<std::size_t>(cols), ' '));
  for (int y = 0; y < rows; ++y)
    for (int x = 0; x < cols; ++x) {
      const Glyph& a = nearest(pixel(x, 2 * y));
      const Glyph& b = nearest(pixel(x, 2 * y + 1));
      lines[y][x] = (a.priority >= b.priority ? a : b).ch;
    }
  cairo_surface_destroy(surface);
  // Block numbers at the centres, where the whole number lands on that block's face.
  for (std::size_t i = 0; i < state.blocks.size(); ++i) {
    const Point s = cam.to_screen({state.blocks[i].x, state.blocks[i].y});
    const std::string label = std::to_string(i);
    const int y = static_cast<int>(s.y / 2), x0 = static_cast<int>(s.x) - static_cast<int>(label.size() - 1) / 2;
    if (y < 0 || y >= rows || x0 < 0 || x0 + static_cast<int>(label.size()) > cols) continue;
    bool fits = true;
    for (std::size_t k = 0; k < label.size(); ++k) fits = fits && lines[y][x0 + k] == '#';
    if (fits) lines[y].replace(static_cast<std::size_t>(x0), label.size(), label);
  }
  std::string out;
  for (const std::string& l : lines) out += l + "\n";
  return out;
}

int run_ascii(const Options& o) {
  client::Client c(o.domain, o.sim_id);
  if (!found_server(o, c)) return kNoServer;
  g_stop = false;
  std::signal(SIGINT, on_stop);
  std::signal(SIGTERM, on_stop);
  const bool tty = isatty(STDOUT_FILENO);
  if (tty) std::fputs("\x1b[?25l\x1b[2J", stdout);  // hide the cursor, clear once; then redraw in place
  Feed feed(c);
  const auto period = client::Millis(static_cast<long>(1000 / std::max(0.1, o.fps)));
  int frames = 0;
  bool fresh = true;
  while (!g_stop && (o.frames == 0 || frames < o.frames)) {
    fresh = feed.update(period) || fresh;
    const client::State* s = feed.state();
    if (!s && feed.undrawable() > o.timeout) {
      if (tty) std::fputs("\x1b[?25h\n", stdout);
      std::cerr << "ladder-view: nothing to draw from ladderd '" << o.sim_id << "' in " << o.timeout
                << " s: " << feed.why_undrawable() << "\n";
      return kNoServer;
    }
    const bool waiting = feed.quiet() > 3;
    if (!s || (!fresh && !waiting)) continue;
    int cols = o.width, rows = o.height;
    if (tty) terminal_size(cols, rows);
    rows = std::max(4, rows - 2);  // two lines of text
    const Camera cam = camera_for(o, *feed.info(), *s, cols, 2 * rows);
    char head[256], rtf[32] = "-";
    if (feed.stats()) std::snprintf(rtf, sizeof rtf, "%.2f", feed.stats()->real_time_factor);
    std::snprintf(head, sizeof head, "%s  t = %.3f s  real-time x%s%s  %u blocks", o.sim_id.c_str(), s->sim_time, rtf,
                  s->paused ? "  PAUSED" : "", feed.info()->blocks);
    std::string frame = tty ? "\x1b[H" : "";
    frame += std::string(head) + (waiting ? "  (waiting for ladderd: no news for a while)" : "") + "\n";
    frame += render_ascii(cam, *feed.info(), *s, cols, rows);
    frame += tty ? "\x1b[J" : "\n";
    std::fputs(frame.c_str(), stdout);
    std::fflush(stdout);
    fresh = false;
    ++frames;
  }
  if (tty) std::fputs("\x1b[?25h\n", stdout);
  return kOk;
}

}  // namespace ladder::view
