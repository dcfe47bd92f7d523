// ladder-view's three ways to show a ladder, one function each, and what they share.
#pragma once

#include "client.hpp"
#include "draw.hpp"

#include <chrono>
#include <optional>
#include <string>

namespace ladder::view {

// Exit codes scripts can rely on (as ladderctl's).
enum Exit : int {
  kOk = 0,
  kFailed = 1,    // could not write the PNG, no display for the window
  kUsage = 2,     // bad command line
  kNoServer = 3,  // no ladderd answered within the timeout
};

struct Options {
  int domain = 0;
  std::string sim_id = "ladder";
  double timeout = 10;  // [s] to find the server (--png, --ascii)
  int width = 900, height = 700;  // [px] window and PNG; --ascii: characters (0 = the terminal's size)
  std::string png;
  std::optional<double> at;       // --png: the first state at or after this sim time
  std::optional<Camera> view;     // --view X,Y,SCALE[,YAW,PITCH]: a fixed camera instead of framing the ladder
  bool side = false;              // --side: the side view (the model's plane) instead of the 3-D one
  bool numbers = false;           // --numbers: each block's number beside it (the window: key n)
  bool ascii = false;
  int frames = 0;                 // --ascii: stop after this many frames (0 = until Ctrl-C)
  double fps = 10;                // --ascii: frames per second at most
};

// What has arrived from the server, polled without blocking (or waiting up to `wait`): a new State, a new Stats,
// and when anything last came, so that a viewer can tell a paused server (Stats keep coming) from a gone one.
class Feed {
 public:
  using Clock = std::chrono::steady_clock;
  explicit Feed(client::Client& c) : client_(c), news_(Clock::now()), drawable_(news_) {}
  // Reads DDS for `wait` (less if Stats come); true when a new state came that state() gives (its SceneInfo too).
  bool update(client::Millis wait = client::Millis(0));
  // The latest state and its scene info, once both are there and belong to the same scene generation.
  const client::State* state() const;
  const client::SceneInfo* info() const;
  // The publisher is a replay (ladderctl replay), as far as the scene info that came says.
  bool replay() const { return info() && info()->replay; }
  const std::optional<ladder_msg_Stats>& stats() const { return stats_; }
  // Seconds since the server last sent a drawable state or stats; a stopped server goes quiet.
  double quiet() const { return std::chrono::duration<double>(Clock::now() - news_).count(); }
  // Seconds since state() last gave a state (since the feed began, if never). States and Stats may keep coming while
  // no state can be drawn: when the SceneInfo is of another generation than every State (another publisher under our
  // sim id, or a broken one), the viewer must give up at its timeout rather than wait for ever.
  double undrawable() const { return std::chrono::duration<double>(Clock::now() - drawable_).count(); }
  // Why no state can be drawn, for the message: what State and SceneInfo say.
  std::string why_undrawable() const;

 private:
  client::Client& client_;
  std::uint64_t seq_ = 0;
  std::uint32_t generation_ = 0;
  double sim_time_ = -1;
  bool any_ = false;
  std::optional<ladder_msg_Stats> stats_;
  Clock::time_point news_, drawable_;
};

// Commands sent from a key or a click, their answers picked up later without waiting (the window and the terminal
// must stay responsive while the server is away).
class Outbox {
 public:
  explicit Outbox(client::Client& c) : client_(c) {}
  // Sends `c` now; `what` names it in the answer ("tip", "poke block 3"). With no server: an answer at once.
  void send(const ladder_msg_Command& c, const std::string& what);
  // The answers that came (or timed out) since the last call, e.g. "tip: accepted at t = 1.234 s"; the latest also
  // stays in recent() for kRecent after it came.
  std::vector<std::string> take();
  // The latest answer while it is news: a picture that shows it for ever showed "tip: accepted" after a `load` from
  // elsewhere, a reset or a server restart, as if it were the news of the ladder on screen.
  static constexpr std::chrono::seconds kRecent{10};
  std::string recent() const { return std::chrono::steady_clock::now() - last_at_ < kRecent ? last_ : std::string(); }

 private:
  struct Pending {
    std::uint64_t id;
    std::string what;
    std::chrono::steady_clock::time_point sent;
  };
  client::Client& client_;
  std::vector<Pending> pending_;
  std::vector<std::string> ready_;
  std::string last_;
  std::chrono::steady_clock::time_point last_at_{};
};

int run_png(const Options& o);
int run_ascii(const Options& o);
int run_window(const Options& o);

// Waits up to --timeout for the server; false (and Client::no_server's message on standard error) if none answered.
bool found_server(const Options& o, client::Client& c);
// The camera for `state`: the fixed --view if given, else the ladder framed in width x height (seen from the
// side with --side).
Camera camera_for(const Options& o, const client::SceneInfo& info, const client::State& state, int width,
                  int height);
// "view centre X,Y m, S px/m, yaw A deg, pitch B deg": how --png and the window report their camera (--view
// takes the same numbers).
std::string camera_text(const Camera& c);
// The scene's name as the headings show it: quoted, and past `max_chars` characters cut with "..." (a name may be
// 1024 bytes long).
std::string scene_label(const std::string& name, std::size_t max_chars = 40);
// The window's overlay (key o) stands down the left side, at most this many characters wide: at the default 900 px
// it then stays clear of the hand that holds the top block (its lines were up to 60 characters, and it covered it).
inline constexpr std::size_t kOverlayColumns = 38;
// `text` in lines of at most `columns` characters, broken at spaces (a longer word cut where it must).
std::vector<std::string> wrap(const std::string& text, std::size_t columns);
// The HUD's overlay lines from the latest Stats and SceneInfo.
std::vector<std::string> stats_lines(const client::SceneInfo& info, const std::optional<ladder_msg_Stats>& stats);

}  // namespace ladder::view
