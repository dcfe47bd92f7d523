// The window (SDL2): the drawing module paints a Cairo image, which is copied into an SDL texture each frame the
// picture changes. The DDS client is polled, never waited on, so the window stays responsive while the server is
// away; commands are sent at once and their answers picked up in later frames.
#include "app.hpp"
#include "directory.hpp"
#include "plot.hpp"

#include <SDL2/SDL.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <iostream>
#include <memory>
#include <utility>

namespace ladder::view {

namespace {

using Clock = std::chrono::steady_clock;
namespace cmd = client::cmd;

constexpr double kPokeImpulse = 0.005;  // [N s] ladderctl's default poke
constexpr double kDragSlop = 4;         // [px] a press that moves farther is a drag, not a click
constexpr auto kDragPeriod = std::chrono::milliseconds(30);  // drag commands at most ~33 a second

// The overlay's legend and keys, in short lines: the overlay stands down the left side of the picture.
const std::vector<std::string> kHelp = {
    "red hinge: a pair locked straight", "grey x: a broken hinge",  "green ring: a hand's target",
    "click a block: poke it",      "drag a block: grab and move it", "drag elsewhere, middle drag: pan",
    "right drag: orbit  wheel: zoom", "t tip  space pause/resume",    "s step (S: 100)  r reset",
    "f follow the ripple  0 fit",  "v side view / 3-D  n numbers",   "p plots  Tab next ladder",
    "arrows pan  +/- zoom",        "o overlay  q quit"};

double seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

// SDL's window, renderer and streaming texture, and the Cairo image the drawing module paints.
class Screen {
 public:
  Screen(const std::string& title, int w, int h) {
    window_ = SDL_CreateWindow(title.c_str(), SDL_WINDOWPOS_UNDEFINED, SDL_WINDOWPOS_UNDEFINED, w, h,
                               SDL_WINDOW_RESIZABLE);
    if (!window_) throw std::runtime_error(std::string("cannot open a window: ") + SDL_GetError());
    renderer_ = SDL_CreateRenderer(window_, -1, 0);
    if (!renderer_) renderer_ = SDL_CreateRenderer(window_, -1, SDL_RENDERER_SOFTWARE);
    if (!renderer_) throw std::runtime_error(std::string("cannot render: ") + SDL_GetError());
    resize(w, h);
  }
  Screen(const Screen&) = delete;
  Screen& operator=(const Screen&) = delete;
  ~Screen() {
    release();
    SDL_DestroyRenderer(renderer_);
    SDL_DestroyWindow(window_);
  }
  void resize(int w, int h) {
    release();
    width_ = w;
    height_ = h;
    // Cairo's ARGB32 is a native-endian 32-bit ARGB word per pixel: SDL's ARGB8888.
    texture_ = SDL_CreateTexture(renderer_, SDL_PIXELFORMAT_ARGB8888, SDL_TEXTUREACCESS_STREAMING, w, h);
    surface_ = cairo_image_surface_create(CAIRO_FORMAT_ARGB32, w, h);
    cr_ = cairo_create(surface_);
  }
  // The drawing context, made anew if a drawing left it in an error state: cairo ignores every later call on such a
  // context, and the window's picture stopped for good (a heading that was not UTF-8 did it, before sim ids were
  // checked).
  cairo_t* cairo() {
    if (cairo_status(cr_) != CAIRO_STATUS_SUCCESS) {
      cairo_destroy(cr_);
      cr_ = cairo_create(surface_);
    }
    return cr_;
  }
  void present() {
    cairo_surface_flush(surface_);
    SDL_UpdateTexture(texture_, nullptr, cairo_image_surface_get_data(surface_),
                      cairo_image_surface_get_stride(surface_));
    SDL_RenderClear(renderer_);
    SDL_RenderCopy(renderer_, texture_, nullptr, nullptr);
    SDL_RenderPresent(renderer_);
  }
  int width() const { return width_; }
  void title(const std::string& t) { SDL_SetWindowTitle(window_, t.c_str()); }
  int height() const { return height_; }

 private:
  void release() {
    if (cr_) cairo_destroy(cr_);
    if (surface_) cairo_surface_destroy(surface_);
    if (texture_) SDL_DestroyTexture(texture_);
    cr_ = nullptr;
    surface_ = nullptr;
    texture_ = nullptr;
  }
  SDL_Window* window_ = nullptr;
  SDL_Renderer* renderer_ = nullptr;
  SDL_Texture* texture_ = nullptr;
  cairo_surface_t* surface_ = nullptr;
  cairo_t* cr_ = nullptr;
  int width_ = 0, height_ = 0;
};

class Viewer {
 public:
  Viewer(const Options& o, Screen& screen)
      : o_(o), screen_(screen), sim_id_(o.sim_id), link_(std::make_unique<Link>(o.domain, o.sim_id)), side_(o.side) {
    camera_.width = screen.width();
    camera_.height = screen.height();
  }

  void run() {
    while (!quit_) {
      if (link_->feed.update(client::Millis(4))) {
        on_state();
        dirty_ = true;
      }
      SDL_Event ev;
      while (SDL_PollEvent(&ev)) on_event(ev);
      send_drag();
      take_answers();
      note_silence();
      if (follow_) step_follow();
      // Redraw on change, and a few times a second anyway (the waiting banner, the stats).
      if (dirty_ || Clock::now() - drawn_at_ > std::chrono::milliseconds(250)) paint();
    }
    if (mode_ == Mode::Grab) send(cmd::release(block_), "release block " + std::to_string(block_));
  }

 private:
  enum class Mode { None, Pan, Orbit, Press, Grab };

  // A new state: fit the view to a new scene, and note where the ripple is.
  void on_state() {
    if (!link_->feed.state()) return;  // Feed::update() says so only with a state and its SceneInfo; kept safe here too
    const client::State& s = *link_->feed.state();
    const client::SceneInfo& info = *link_->feed.info();
    if (!fitted_ || info.blocks != scene_blocks_ || info.scene_name != scene_name_) {
      camera_ = camera_for(o_, info, s, screen_.width(), screen_.height());
      fitted_ = true;
      scene_blocks_ = info.blocks;
      scene_name_ = info.scene_name;
      screen_.title("ladder-view: " + sim_id_ + "  " + scene_label(info.scene_name));
      std::printf("ladder-view: showing '%s' (%u blocks) in a %dx%d window; %s\n", info.scene_name.c_str(),
                  info.blocks, camera_.width, camera_.height, camera_text(camera_).c_str());
      std::fflush(stdout);
      flips_.clear();
    }
    // The ripple is at the deepest hinge that flipped since the last state.
    if (flips_.size() == s.hinges.size()) {
      for (std::size_t k = s.hinges.size(); k-- > 1;)
        if (s.hinges[k].flips != flips_[k] && k < s.blocks.size()) {
          ripple_ = pivot(info, s, static_cast<int>(k));
          break;
        }
    }
    flips_.resize(s.hinges.size());
    for (std::size_t k = 0; k < s.hinges.size(); ++k) flips_[k] = s.hinges[k].flips;
    history_.add(s.generation, s.sim_time, s.energy, flips_);
  }

  // Says on standard output when the server goes quiet and when it is back (the picture says it too).
  void note_silence() {
    const bool quiet = link_->feed.quiet() > 3;
    if (quiet == silent_) return;
    silent_ = quiet;
    const bool replay = link_->feed.replay();
    std::printf("ladder-view: %s '%s' %s\n", replay ? "the replay" : "ladderd", sim_id_.c_str(),
                quiet ? (replay ? "has sent nothing for 3 s (ended or stopped?); waiting for it"
                                : "is not answering; waiting for it")
                      : "answers again");
    std::fflush(stdout);
    dirty_ = true;
  }

  // The next ladder on the domain (by sim id, round), found by DDS discovery (1.5 s, the window waits): shown from
  // now on, framed anew.
  void switch_ladder() {
    const client::Directory d = client::discover(o_.domain, 1.5);
    std::string next;
    for (const client::LadderEntry& l : d.ladders)
      if (l.sim_id > sim_id_) {
        next = l.sim_id;
        break;
      }
    if (next.empty() && !d.ladders.empty()) next = d.ladders.front().sim_id;
    if (next.empty() || next == sim_id_) {
      std::printf("ladder-view: no other ladder on DDS domain %d than '%s'\n", o_.domain, sim_id_.c_str());
      std::fflush(stdout);
      return;
    }
    if (mode_ == Mode::Grab) send(cmd::release(block_), "release block " + std::to_string(block_));
    mode_ = Mode::None;
    sim_id_ = next;
    link_ = std::make_unique<Link>(o_.domain, sim_id_);
    fitted_ = false;
    history_ = History{};
    screen_.title("ladder-view: " + sim_id_);
    std::printf("ladder-view: switched to sim id '%s' (%zu ladders on DDS domain %d)\n", sim_id_.c_str(),
                d.ladders.size(), o_.domain);
    std::fflush(stdout);
  }

  // Frames the ladder again, seen from the side or in 3-D (key v).
  void refit(const client::State& s) {
    const client::SceneInfo& info = *link_->feed.info();
    camera_ = side_ ? fit(info, s, screen_.width(), screen_.height(), 40, 0, 0)
                    : fit(info, s, screen_.width(), screen_.height());
  }

  // Key f: follow the ripple, or stop. A ladder framed so small that a block is under kFollowPx long on screen (a tall
  // one: 14 px) is zoomed about the centre until it is that long, so that the turning blocks can be told apart.
  void toggle_follow() {
    static constexpr double kFollowPx = 40;
    follow_ = !follow_;
    const client::SceneInfo* info = link_->feed.info();
    if (follow_ && info && info->length > 0 && camera_.scale * info->length < kFollowPx)
      camera_.zoom_about({0.5 * camera_.width, 0.5 * camera_.height}, kFollowPx / (camera_.scale * info->length));
    std::printf("ladder-view: %s; %s\n", follow_ ? "following the ripple" : "no longer following the ripple",
                camera_text(camera_).c_str());
    std::fflush(stdout);
  }

  void step_follow() {
    if (!ripple_) return;
    const double dx = ripple_->x - camera_.cx, dy = ripple_->y - camera_.cy;
    if (std::hypot(dx, dy) * camera_.scale < 0.5) return;
    camera_.cx += 0.1 * dx;
    camera_.cy += 0.1 * dy;
    dirty_ = true;
  }

  void paint() {
    const auto t0 = Clock::now();
    Hud hud;
    hud.title = link_->feed.replay() ? sim_id_ + " (REPLAY)" : sim_id_;
    if (const client::SceneInfo* info = link_->feed.info()) hud.title += "  " + scene_label(info->scene_name);
    hud.stats = true;
    hud.numbers = numbers_;
    if (link_->feed.stats()) hud.real_time_factor = link_->feed.stats()->real_time_factor;
    const client::State* s = link_->feed.state();
    if (!s) {
      hud.banner = "waiting for ladderd '" + sim_id_ + "' on DDS domain " + std::to_string(o_.domain) + " ...";
      if (const auto& others = link_->client.other_sim_ids(); !others.empty())
        hud.banner += " (there: '" + *others.begin() + "'" + (others.size() > 1 ? ", ..." : "") + ")";
    } else if (link_->feed.quiet() > 3) {
      char buf[128];
      // A replay that has played to its end (or was stopped) goes quiet as a stopped server does.
      std::snprintf(buf, sizeof buf, "%s (%.0f s): waiting ...",
                    link_->feed.replay() ? "the replay has sent nothing: ended or stopped?"
                                         : "ladderd is not answering",
                    link_->feed.quiet());
      hud.banner = buf;
    }
    // The last answer while it is news, wrapped (a refusal's reason may be long) to the overlay's width.
    std::vector<std::string> answer = wrap(link_->outbox.recent(), kOverlayColumns);
    std::erase(answer, std::string());
    if (overlay_) {
      if (s) hud.lines = stats_lines(*link_->feed.info(), link_->feed.stats());
      char buf[128];
      std::snprintf(buf, sizeof buf, "draw %.1f ms, %d blocks on screen", draw_ms_, drawn_);
      hud.lines.emplace_back(buf);
      if (follow_) hud.lines.emplace_back("following the ripple (f: stop)");
      if (hover_ >= 0) hud.lines.push_back("block " + std::to_string(hover_) + " under the cursor");
      hud.lines.insert(hud.lines.end(), answer.begin(), answer.end());
      hud.lines.insert(hud.lines.end(), kHelp.begin(), kHelp.end());
    } else {
      hud.lines = std::move(answer);
      hud.lines.emplace_back("o: stats, keys and colours");  // the hint, always
    }
    // The banner goes over everything, the plots too: drawn last.
    const std::string banner = std::exchange(hud.banner, {});
    if (s)
      drawn_ = draw(screen_.cairo(), camera_, *link_->feed.info(), *s, hud);
    else
      draw_empty(screen_.cairo(), camera_, hud);
    // The plots lower right, clear of the ladder the view centres (the overlay is on the left).
    if (plots_)
      draw_plots(screen_.cairo(), history_, 0.64 * screen_.width(), 0.45 * screen_.height(),
                 0.35 * screen_.width(), 0.5 * screen_.height());
    draw_banner(screen_.cairo(), camera_, banner);
    screen_.present();
    draw_ms_ = 1e3 * seconds(Clock::now() - t0);
    drawn_at_ = Clock::now();
    dirty_ = false;
  }

  // --- commands ---
  void send(const ladder_msg_Command& c, const std::string& what) { link_->outbox.send(c, what); }

  void take_answers() {
    for (const std::string& a : link_->outbox.take()) {
      std::printf("ladder-view: %s\n", a.c_str());
      std::fflush(stdout);
      dirty_ = true;
    }
  }

  void send_drag() {
    if (mode_ != Mode::Grab || !drag_to_ || Clock::now() - dragged_at_ < kDragPeriod) return;
    send(cmd::drag(block_, drag_to_->x, drag_to_->y), "drag block " + std::to_string(block_));
    drag_to_.reset();
    dragged_at_ = Clock::now();
  }

  // --- input ---
  void on_event(const SDL_Event& ev) {
    switch (ev.type) {
      case SDL_QUIT:
        quit_ = true;
        break;
      case SDL_WINDOWEVENT:
        if (ev.window.event == SDL_WINDOWEVENT_SIZE_CHANGED) {
          screen_.resize(ev.window.data1, ev.window.data2);
          camera_.width = ev.window.data1;
          camera_.height = ev.window.data2;
        }
        dirty_ = true;
        break;
      case SDL_KEYDOWN:
        on_key(ev.key.keysym);
        break;
      case SDL_MOUSEWHEEL: {
        int x = 0, y = 0;
        SDL_GetMouseState(&x, &y);
        camera_.zoom_about({double(x), double(y)}, std::pow(1.2, ev.wheel.y));
        dirty_ = true;
        break;
      }
      case SDL_MOUSEBUTTONDOWN:
        on_press(ev.button);
        break;
      case SDL_MOUSEMOTION:
        on_motion(ev.motion);
        break;
      case SDL_MOUSEBUTTONUP:
        on_release(ev.button);
        break;
      default:
        break;
    }
  }

  void on_key(const SDL_Keysym& k) {
    const bool shift = (k.mod & KMOD_SHIFT) != 0;
    const double pan = 0.1 * std::min(camera_.width, camera_.height) / camera_.scale;
    const client::State* s = link_->feed.state();
    switch (k.sym) {
      case SDLK_q:
      case SDLK_ESCAPE: quit_ = true; break;
      case SDLK_t: send(cmd::tip(), "tip"); break;
      case SDLK_SPACE:
        if (s && s->paused)
          send(cmd::resume(), "resume");
        else
          send(cmd::pause(), "pause");
        break;
      case SDLK_s: send(cmd::step(shift ? 100 : 1), shift ? "step 100" : "step 1"); break;
      case SDLK_r: send(cmd::reset(), "reset"); break;
      case SDLK_f: toggle_follow(); break;
      case SDLK_n: numbers_ = !numbers_; break;
      case SDLK_p: plots_ = !plots_; break;
      case SDLK_TAB: switch_ladder(); break;
      case SDLK_v:
        side_ = !side_;
        if (s) refit(*s);
        break;
      case SDLK_o: overlay_ = !overlay_; break;
      case SDLK_0:
      case SDLK_HOME:
        if (s) refit(*s);
        follow_ = false;
        break;
      case SDLK_PLUS:
      case SDLK_EQUALS:
      case SDLK_KP_PLUS: camera_.scale *= 1.25; break;
      case SDLK_MINUS:
      case SDLK_KP_MINUS: camera_.scale /= 1.25; break;
      case SDLK_LEFT: camera_.cx -= pan; break;
      case SDLK_RIGHT: camera_.cx += pan; break;
      case SDLK_UP: camera_.cy += pan; break;
      case SDLK_DOWN: camera_.cy -= pan; break;
      default: return;
    }
    dirty_ = true;
  }

  void on_press(const SDL_MouseButtonEvent& b) {
    press_ = {double(b.x), double(b.y)};
    mode_ = b.button == SDL_BUTTON_RIGHT ? Mode::Orbit : Mode::Pan;
    const client::State* s = link_->feed.state();
    if (b.button != SDL_BUTTON_LEFT || !s) return;
    // The block under the cursor in the picture as drawn: the ray through it, against every block's box.
    const Pick p = pick(camera_, *link_->feed.info(), *s, press_);
    block_ = p.block;
    if (block_ < 0) return;
    mode_ = Mode::Press;
    grab_point_ = to_block_frame(s->blocks[block_], p.world);
    press_world_ = p.world;
    // A drag moves the grabbed point as the plane z = 0 under the cursor moves.
    const Point plane = camera_.to_world(press_);
    drag_offset_ = {p.world.x - plane.x, p.world.y - plane.y};
  }

  Point drag_target(Point at) const {
    const Point w = camera_.to_world(at);
    return {w.x + drag_offset_.x, w.y + drag_offset_.y};
  }

  void on_motion(const SDL_MouseMotionEvent& m) {
    const Point at{double(m.x), double(m.y)};
    if (const client::State* s = link_->feed.state()) {
      const int h = pick(camera_, *link_->feed.info(), *s, at).block;
      if (h != hover_) dirty_ = overlay_;
      hover_ = h;
    }
    if (mode_ == Mode::Pan || mode_ == Mode::Orbit) {
      const Point from{at.x - m.xrel, at.y - m.yrel};
      if (mode_ == Mode::Pan)
        camera_.pan(from, at);
      else
        camera_.orbit(0.01 * m.xrel, 0.01 * m.yrel);
      follow_ = mode_ == Mode::Orbit && follow_;
      side_ = side_ && mode_ == Mode::Pan;
      dirty_ = true;
    } else if (mode_ == Mode::Press && std::hypot(at.x - press_.x, at.y - press_.y) > kDragSlop) {
      // Hold the block by the point that was pressed, pulled toward the cursor.
      ladder_msg_Command c = cmd::grab_to(block_, press_world_.x, press_world_.y);
      c.has_point = true;
      c.c = grab_point_.x;
      c.d = grab_point_.y;
      send(c, "grab block " + std::to_string(block_));
      mode_ = Mode::Grab;
      drag_to_ = drag_target(at);
    } else if (mode_ == Mode::Grab) {
      drag_to_ = drag_target(at);
    }
  }

  void on_release(const SDL_MouseButtonEvent&) {
    if (mode_ == Mode::Press) {
      // A click pokes the block at that point, away from the side it was clicked on.
      const client::State* s = link_->feed.state();
      // (the ladder may have been replaced by a smaller one since the press: then the block is gone)
      const bool known = s && static_cast<std::size_t>(block_) < s->blocks.size();
      const double dir = known && press_world_.x > s->blocks[static_cast<std::size_t>(block_)].x ? -1 : 1;
      send(cmd::poke_at(block_, dir * kPokeImpulse, 0, press_world_.x, press_world_.y),
           "poke block " + std::to_string(block_));
    } else if (mode_ == Mode::Grab) {
      dragged_at_ = {};
      send_drag();
      send(cmd::release(block_), "release block " + std::to_string(block_));
    }
    mode_ = Mode::None;
  }

  const Options& o_;
  Screen& screen_;
  // The connection to the ladder shown; replaced when the user switches to another ladder (key Tab).
  struct Link {
    client::Client client;
    Feed feed;
    Outbox outbox;
    Link(int domain, const std::string& sim_id) : client(domain, sim_id), feed(client), outbox(client) {}
  };
  std::string sim_id_;
  std::unique_ptr<Link> link_;
  Camera camera_;
  bool fitted_ = false, follow_ = false, overlay_ = false, dirty_ = true, quit_ = false, silent_ = false;
  bool side_ = false, numbers_ = true, plots_ = false;  // keys v, n and p
  History history_;  // what the plots show
  std::uint32_t scene_blocks_ = 0;
  std::string scene_name_;
  std::vector<std::uint32_t> flips_;
  std::optional<Point> ripple_;
  Clock::time_point drawn_at_{}, dragged_at_{};
  double draw_ms_ = 0;
  int drawn_ = 0, hover_ = -1;
  // The mouse: what a left press started, on which block, where.
  Mode mode_ = Mode::None;
  int block_ = -1;
  Point press_, press_world_, grab_point_, drag_offset_;
  std::optional<Point> drag_to_;
};

}  // namespace

int run_window(const Options& o) {
  // Without a Wayland display, X11 only: SDL tried Wayland after an X server it could not reach, and libwayland
  // printed "error: XDG_RUNTIME_DIR is invalid or not set in the environment." before the viewer's own words.
  const char* asked = std::getenv("SDL_VIDEODRIVER");
  const char* wayland = std::getenv("WAYLAND_DISPLAY");
  const bool x11_only = (asked == nullptr || *asked == '\0') && (wayland == nullptr || *wayland == '\0');
  if (x11_only) SDL_SetHint(SDL_HINT_VIDEODRIVER, "x11");
  if (SDL_Init(SDL_INIT_VIDEO) != 0) {
    const char* display = std::getenv("DISPLAY");
    std::cerr << "ladder-view: no display ("
              << (!x11_only                              ? ""
                  : display == nullptr || *display == '\0' ? "DISPLAY and WAYLAND_DISPLAY are not set; "
                                                           : "no X server answers at DISPLAY; ")
              << "SDL: " << SDL_GetError() << "); use --png FILE or --ascii\n";
    return kFailed;
  }
  // With no display SDL falls back to its "offscreen" (or "dummy") driver, whose window nobody can see: a viewer
  // that would run for ever showing nothing. Those drivers are taken only when asked for by name (SDL_VIDEODRIVER).
  const char* driver = SDL_GetCurrentVideoDriver();
  if (driver != nullptr && (asked == nullptr || *asked == '\0') &&
      (std::strcmp(driver, "offscreen") == 0 || std::strcmp(driver, "dummy") == 0)) {
    std::cerr << "ladder-view: no display (DISPLAY and WAYLAND_DISPLAY are not set or not reachable; SDL offered only "
                 "its invisible '"
              << driver << "' driver); use --png FILE or --ascii\n";
    SDL_Quit();
    return kFailed;
  }
  int code = kOk;
  try {
    Screen screen("ladder-view: " + o.sim_id, o.width, o.height);
    Viewer(o, screen).run();
  } catch (const std::exception& e) {
    std::cerr << "ladder-view: " << e.what() << "\n";
    code = kFailed;
  }
  SDL_Quit();
  return code;
}

}  // namespace ladder::view
