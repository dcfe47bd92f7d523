// ladder-view: the viewer of ladderd. A window by default (SDL2); --png FILE writes one snapshot, --ascii draws in
// the terminal. Exit codes: 0 done, 1 failed (no display, cannot write), 2 bad usage, 3 no server.
#include "app.hpp"
#include "cli_checks.hpp"
#include "ladder/cli_error.hpp"
#include "transport/dds.hpp"
#include "transport/domain_option.hpp"
#include "transport/security.hpp"
#include "transport/version.hpp"

#include <CLI/CLI.hpp>

#include <cmath>
#include <cstdio>
#include <optional>

namespace {

// "W x H" -> two positive integers.
std::string parse_size(const std::string& text, int& w, int& h) {
  char x = 0, rest = 0;
  if (std::sscanf(text.c_str(), "%d%c%d%c", &w, &x, &h, &rest) != 3 || (x != 'x' && x != 'X') || w < 1 || h < 1 ||
      w > 16384 || h > 16384)
    return "'" + text + "' is not a size like 900x700 (1x1 to 16384x16384)";
  return {};
}

// "X,Y,SCALE[,YAW,PITCH]" -> a camera centred on (X, Y) m at SCALE px/m, turned by YAW and PITCH degrees (the 3-D
// view's by default; 0,0 is the side view).
std::string parse_view(const std::string& text, std::optional<ladder::view::Camera>& view) {
  ladder::view::Camera c;
  double yaw = ladder::view::kDefaultYaw * 180 / M_PI, pitch = ladder::view::kDefaultPitch * 180 / M_PI;
  char rest = 0;
  const int n = std::sscanf(text.c_str(), "%lf,%lf,%lf,%lf,%lf%c", &c.cx, &c.cy, &c.scale, &yaw, &pitch, &rest);
  if ((n != 3 && n != 5) || !(std::abs(c.cx) <= 1e9) || !(std::abs(c.cy) <= 1e9) || !(c.scale >= 1e-6) ||
      !(c.scale <= 1e9) || !(std::abs(yaw) <= 80) || !(std::abs(pitch) <= 80))
    return "'" + text + "' is not a view like 0.01,-0.2,1500 or 0.01,-0.2,1500,-50,12 (centre X,Y in m within "
                        "+-1e9, 1e-6 to 1e9 px per m, then yaw and pitch in degrees, each within +-80)";
  c.yaw = yaw * M_PI / 180;
  c.pitch = pitch * M_PI / 180;
  view = c;
  return {};
}

}  // namespace

int main(int argc, char** argv) {
  using namespace ladder::view;
  Options o;
  std::string size, view;
  CLI::App app{"ladder-view: draws a running ladderd's ladder in a window, a PNG file or the terminal"};
  app.set_version_flag("--version", std::string("ladder-view ") + ladder::kVersion);
  app.add_option("--domain", o.domain, "DDS domain id of the server, 0-231 (default 0)")
      ->check(ladder::transport::domain_check());
  app.add_option("--sim-id", o.sim_id, "the server's sim id (default 'ladder')")->check(ladder::client::sim_id_check());
  app.add_option("--timeout", o.timeout, "seconds to wait for the server (--png, --ascii; default 10)")
      ->check(ladder::client::positive(1e6));
  auto* png = app.add_option("--png", o.png, "write one snapshot to FILE and exit");
  app.add_option("--at", o.at, "with --png: the first state at or after this sim time [s]")
      ->needs(png)
      ->check(ladder::client::finite_range(-1e9, 1e9));
  auto* ascii = app.add_flag("--ascii", o.ascii, "draw in the terminal, refreshing in place (q or Ctrl-C stops; t tips)");
  png->excludes(ascii);
  app.add_option("--frames", o.frames, "with --ascii: stop after N frames")
      ->needs(ascii)
      ->check(ladder::client::positive());
  app.add_option("--fps", o.fps, "with --ascii: frames per second at most (default 10)")
      ->needs(ascii)
      ->check(ladder::client::finite_range(0.1, 100));
  app.add_option("--size", size, "WxH: window or PNG pixels (default 900x700); --ascii: characters (default: the "
                                 "terminal's, else 100x40)");
  std::string security;
  app.add_option("--security", security,
                 "DDS Security: this viewer's identity folder DIR/NAME of scripts/make-pki (docs/security.md)");
  app.add_option("--view", view, "X,Y,SCALE[,YAW,PITCH]: centre the view on (X, Y) m at SCALE px/m, turned by YAW "
                                 "and PITCH degrees (default -50,12; 0,0 is the side view), instead of framing the "
                                 "ladder");
  app.add_flag("--side", o.side, "the side view (the model's own plane, as the paper draws it) instead of 3-D");
  app.add_flag("--numbers", o.numbers, "each block's number beside it (the window: key n)");
  if (const std::string empty = ladder::client::empty_argument(argc, argv); !empty.empty()) {
    std::fprintf(stderr, "ladder-view: %s\n", empty.c_str());
    return kUsage;
  }
  try {
    app.parse(argc, argv);
    if (o.ascii) o.width = 100, o.height = 40;
    std::string error = size.empty() ? "" : parse_size(size, o.width, o.height);
    if (error.empty() && !view.empty()) error = parse_view(view, o.view);
    if (!error.empty()) throw CLI::ValidationError(size.empty() || !error.starts_with("'" + size) ? "--view" : "--size",
                                                   error);
  } catch (const CLI::ParseError& e) {
    return ladder::report_parse_error(app, e, "ladder-view") == 0 ? kOk : kUsage;
  }
  // Checked before DDS starts; every participant this process makes then uses it (the viewer only reads).
  std::optional<ladder::transport::Identity> identity;
  if (!security.empty()) {
    try {
      identity = ladder::transport::load_identity(security);
      ladder::transport::require_role(*identity, {ladder::transport::Role::Viewer, ladder::transport::Role::Controller},
                                      "ladder-view");
    } catch (const ladder::transport::SecurityError& e) {
      std::fprintf(stderr, "ladder-view: security: %s\n", e.what());
      return kUsage;
    }
    ladder::transport::set_default_identity(&*identity);
  }
  try {
    if (!o.png.empty()) return run_png(o);
    if (o.ascii) return run_ascii(o);
    return run_window(o);
  } catch (const ladder::transport::DdsError& e) {  // DDS would not start (a bad CYCLONEDDS_URI, say)
    std::fprintf(stderr, "ladder-view: %s\n", e.what());
    return kFailed;
  }
}
