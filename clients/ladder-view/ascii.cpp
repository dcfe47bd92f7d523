#include "ascii.hpp"

#include "app.hpp"
#include "ladder/printable.hpp"
#include "stop_signals.hpp"

#include <sys/ioctl.h>
#include <termios.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <string_view>
#include <vector>

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
// (The hinges' and grips' marks are not drawn in the picture but put in as characters: marks().)
constexpr Glyph kGlyphs[] = {{kBackground, ' ', 0}, {kDepth, '.', 1},    {kSideEven, ':', 1}, {kSideOdd, ':', 1},
                             {kFaceEven, '#', 2},   {kFaceOdd, '#', 2},  {kRibbon, '+', 3},   {kHand, '%', 3},
                             {kHandShade, '%', 3}};

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
  hud.scale_bar = false;
  hud.marks = false;
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
  // The marks, one character each where the picture would have them (a cell is one pixel across, two down).
  for (const Mark& m : marks(cam, info, state)) {
    const double x = std::floor(m.at.x), y = std::floor(0.5 * m.at.y);
    if (x >= 0 && x < cols && y >= 0 && y < rows)
      lines[static_cast<std::size_t>(y)][static_cast<std::size_t>(x)] = m.ch;
  }
  // Block numbers at the centres, where the whole number lands on a block (its faces, sides or tapes).
  for (std::size_t i = 0; i < state.blocks.size(); ++i) {
    const Point s = cam.to_screen({state.blocks[i].x, state.blocks[i].y});
    if (!(s.x >= 0 && s.x < cols && s.y >= 0 && s.y < 2.0 * rows)) continue;  // (off the page, or not a number)
    const std::string label = std::to_string(i);
    const int y = static_cast<int>(s.y / 2), x0 = static_cast<int>(s.x) - static_cast<int>(label.size() - 1) / 2;
    if (y < 0 || y >= rows || x0 < 0 || x0 + static_cast<int>(label.size()) > cols) continue;
    bool fits = true;
    for (std::size_t k = 0; k < label.size(); ++k)
      fits = fits && std::string_view("#:+").find(lines[y][x0 + k]) != std::string_view::npos;
    if (fits) lines[y].replace(static_cast<std::size_t>(x0), label.size(), label);
  }
  std::string out;
  for (const std::string& l : lines) out += l + "\n";
  return out;
}

namespace {

// The terminal while the view runs: keys one at a time without echo (when standard input is a terminal and the view
// runs in its foreground), the cursor hidden; both restored when the view ends, however it ends (q, a signal, no
// server, an exception). In the background (`timeout`, which runs a program in a process group of its own, or `&`)
// there are no keys: changing the terminal's modes from there stopped the view with SIGTTOU at once, for good.
bool in_foreground() {
  const pid_t group = tcgetpgrp(STDIN_FILENO);
  return group != -1 && group == getpgrp();
}

class Terminal {
 public:
  explicit Terminal(bool tty)
      : tty_(tty), keys_(isatty(STDIN_FILENO) && in_foreground() && tcgetattr(STDIN_FILENO, &saved_) == 0) {
    if (keys_) {
      termios raw = saved_;
      raw.c_lflag &= ~static_cast<tcflag_t>(ICANON | ECHO);
      raw.c_cc[VMIN] = 0;
      raw.c_cc[VTIME] = 0;
      tcsetattr(STDIN_FILENO, TCSANOW, &raw);
    }
    if (tty_) std::fputs("\x1b[?25l\x1b[2J", stdout);  // hide the cursor, clear once; then redraw in place
  }
  ~Terminal() {
    if (keys_) tcsetattr(STDIN_FILENO, TCSANOW, &saved_);
    if (tty_) std::fputs("\x1b[?25h\n", stdout);
    std::fflush(stdout);
  }
  Terminal(const Terminal&) = delete;
  Terminal& operator=(const Terminal&) = delete;
  bool keys() const { return keys_; }
  // The keys typed since the last call.
  std::string typed() const {
    std::string out;
    if (!keys_) return out;
    char buf[64];
    for (ssize_t n; (n = read(STDIN_FILENO, buf, sizeof buf)) > 0;) out.append(buf, static_cast<std::size_t>(n));
    return out;
  }

 private:
  bool tty_;
  termios saved_{};
  bool keys_;
};

// The heading: what is shown, the keys (when they work here), the last command's answer, or until there is one how
// to tip the ladder from elsewhere.
std::vector<std::string> heading(const Options& o, const Feed& feed, const client::State& s, bool keys,
                                 const std::string& answer) {
  char line[512];
  // (paused, the last second's measure is of a clock that has stopped meanwhile: none is shown)
  const std::string rtf = feed.stats() && !s.paused ? client::fixed(feed.stats()->real_time_factor, 2) : "-";
  // What changes first, the sim id last: a narrow terminal cuts the end.
  std::snprintf(line, sizeof line, "t = %s s%s  real-time x%s  %s, %u blocks  sim id '%s'",
                client::fixed(s.sim_time, 3).c_str(), s.paused ? "  PAUSED" : "", rtf.c_str(),
                scene_label(feed.info()->scene_name).c_str(), feed.info()->blocks, o.sim_id.c_str());
  const char* quiet = feed.info()->replay ? "  (the replay has sent nothing for a while: ended or stopped?)"
                                          : "  (waiting for ladderd: no news for a while)";
  std::vector<std::string> out{std::string(line) + (feed.quiet() > 3 ? quiet : "")};
  if (feed.info()->replay) {  // it takes no commands: nothing to tip it with
    const std::string replay = "a replay of a recorded session (ladderctl replay): it takes no commands";
    out.push_back(!keys ? replay : answer.empty() ? replay + "; q quits" : answer);
    return out;
  }
  const std::string elsewhere =
      "from another terminal: ladderctl --sim-id " + o.sim_id + " --domain " + std::to_string(o.domain) + " tip";
  if (keys) {
    out.emplace_back("keys: t tip  space pause/resume  s step  r reset  q quit");
    out.push_back(answer.empty() ? elsewhere : answer);
  } else {
    out.push_back(elsewhere);
  }
  return out;
}

// The hinges beside the picture, "    1  hinged      0" (hinge k joins blocks k-1 and k; its flip-flops), as many as
// fit.
std::vector<std::string> hinge_panel(const client::State& s, int rows) {
  std::vector<std::string> out{"hinge  state   flips"};
  for (std::size_t k = 1; k < s.hinges.size() && static_cast<int>(out.size()) < rows; ++k) {
    const client::Hinge& h = s.hinges[k];
    const char* state = h.status == ladder_msg_BROKEN ? "broken" : h.status == ladder_msg_LOCKED ? "locked" : "hinged";
    char line[64];
    std::snprintf(line, sizeof line, "%5zu  %-6s %6u", k, state, h.flips);
    out.emplace_back(line);
  }
  if (static_cast<int>(out.size()) == rows && s.hinges.size() > static_cast<std::size_t>(rows))
    out.back() = "  ... " + std::to_string(s.hinges.size() - 1) + " hinges";
  return out;
}

constexpr int kPanel = 22;  // [characters] the hinge panel's width, when the terminal is wide enough

// What a key does: q quits; t, space, s and r send a command.
bool on_key(char k, Outbox& out, const client::State* s) {
  namespace cmd = client::cmd;
  switch (k) {
    case 'q': case 'Q': return false;
    case 't': out.send(cmd::tip(), "tip"); break;
    case ' ': if (s && s->paused) out.send(cmd::resume(), "resume"); else out.send(cmd::pause(), "pause"); break;
    case 's': out.send(cmd::step(1), "step 1"); break;
    case 'r': out.send(cmd::reset(), "reset"); break;
    default: break;
  }
  return true;
}

std::string frame_text(const Options& o, const Feed& feed, const client::State& s, bool keys,
                       const std::string& answer, int cols, int rows, bool tty) {
  const std::vector<std::string> head = heading(o, feed, s, keys, answer);
  rows = std::max(4, rows - static_cast<int>(head.size()));
  const bool panel = cols >= 40 + kPanel;
  const int picture = panel ? cols - kPanel : cols;
  const Camera cam = camera_for(o, *feed.info(), s, picture, 2 * rows);
  const std::string art = render_ascii(cam, *feed.info(), s, picture, rows);
  const std::vector<std::string> side = panel ? hinge_panel(s, rows) : std::vector<std::string>{};
  std::string frame = tty ? "\x1b[H" : "";
  // On a terminal a line longer than it is wide would wrap and push the picture down: cut there, at a whole
  // character (one column each: the scene's name may be any printable text).
  for (const std::string& h : head)
    frame += tty ? std::string(first_characters(h, static_cast<std::size_t>(cols))) + "\x1b[K\n" : h + "\n";
  std::size_t at = 0;
  for (int r = 0; r < rows; ++r) {
    const std::size_t nl = art.find('\n', at);
    frame += art.substr(at, nl - at);
    at = nl + 1;
    if (r < static_cast<int>(side.size())) frame += "  " + side[static_cast<std::size_t>(r)];
    frame += r + 1 < rows ? (tty ? "\x1b[K\n" : "\n") : "";
  }
  frame += tty ? "\x1b[J" : "\n";
  return frame;
}

}  // namespace

int run_ascii(const Options& o) {
  client::Client c(o.domain, o.sim_id);
  if (!found_server(o, c)) return kNoServer;
  g_stop = false;
  const client::StopSignals stop(on_stop);
  const bool tty = isatty(STDOUT_FILENO);
  const Terminal term(tty);
  Feed feed(c);
  Outbox out(c);
  const auto period = client::Millis(static_cast<long>(1000 / std::max(0.1, o.fps)));
  const auto tick = std::min(period, client::Millis(50));  // keys are read at least this often
  auto last_frame = std::chrono::steady_clock::now() - period;
  int frames = 0;
  bool fresh = true;
  std::string answer;  // the answer on the heading: it goes after Outbox::kRecent
  while (!g_stop && (o.frames == 0 || frames < o.frames)) {
    fresh = feed.update(tick) || fresh;
    const client::State* s = feed.state();
    for (const char k : term.typed())
      if (!on_key(k, out, s)) g_stop = true;
    out.take();
    if (out.recent() != answer) {  // an answer came (it goes on the heading), or went
      answer = out.recent();
      fresh = true;
    }
    if (!s && feed.undrawable() > o.timeout) {
      std::cerr << "ladder-view: nothing to draw from ladderd '" << o.sim_id << "' in " << o.timeout
                << " s: " << feed.why_undrawable() << "\n";
      return kNoServer;
    }
    const bool waiting = feed.quiet() > 3;
    if (!s || (!fresh && !waiting) || std::chrono::steady_clock::now() - last_frame < period) continue;
    int cols = o.width, rows = o.height;
    if (tty) terminal_size(cols, rows);
    std::fputs(frame_text(o, feed, *s, term.keys(), answer, cols, rows, tty).c_str(), stdout);
    std::fflush(stdout);
    last_frame = std::chrono::steady_clock::now();
    fresh = false;
    ++frames;
  }
  return kOk;
}

}  // namespace ladder::view
