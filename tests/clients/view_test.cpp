// ladder-view: the drawing module on its own, then the real binary against a real ladderd over Cyclone DDS:
// PNG snapshots checked pixel by pixel against the state, the terminal rendering, the window under Xvfb with a
// synthetic click (xdotool) that the server must accept, and a viewer in another network namespace.
#include "naming.hpp"
#include "app.hpp"
#include "ascii.hpp"
#include "client.hpp"
#include "draw.hpp"
#include "netns.hpp"
#include "plot.hpp"
#include "process.hpp"
#include "pty.hpp"
#include "rounded.hpp"
#include "transport/default_config.hpp"
#include "transport/dds.hpp"
#include "transport/topics.hpp"

#include <gtest/gtest.h>

#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <regex>
#include <thread>

namespace ladder::test {
namespace {

using client::Client;
using client::Millis;
using view::Camera;
using view::Point;
using view::Rgb;
namespace cmd = client::cmd;
using Clock = std::chrono::steady_clock;

constexpr Millis kStart{15000};  // generous: CI runs two tests at once on two cores
constexpr Millis kAnswer{5000};
const std::string kBin = LADDER_BINARY_DIR;
const std::string kViewer = kBin + "/clients/ladder-view";

// Polls `done` until it holds or the deadline passes.
bool eventually(const std::function<bool()>& done, Millis timeout) {
  const auto deadline = Clock::now() + timeout;
  while (!done()) {
    if (Clock::now() > deadline) return false;
    std::this_thread::sleep_for(Millis(50));
  }
  return true;
}

// Colours: a block's face must be its own parity's face colour (Cairo paints a polygon's inside exactly).
int distance(Rgb a, Rgb b) { return std::abs(a.r - b.r) + std::abs(a.g - b.g) + std::abs(a.b - b.b); }
bool is_face(Rgb c) {
  for (const Rgb wood : {view::kFaceEven, view::kFaceOdd, view::kSideEven, view::kSideOdd})
    if (distance(c, wood) < 12) return true;
  return false;
}

// An RGB picture: a PNG (Cairo reads it) or an X screen (XWD, as Xvfb -fbdir keeps it).
struct Image {
  int width = 0, height = 0;
  std::vector<Rgb> pixels;
  Rgb at(Point p) const {
    const int x = static_cast<int>(std::floor(p.x)), y = static_cast<int>(std::floor(p.y));
    if (x < 0 || y < 0 || x >= width || y >= height) return {-1000, -1000, -1000};
    return pixels[static_cast<std::size_t>(y) * width + x];
  }
};

Image read_png(const std::string& path) {
  Image img;
  cairo_surface_t* s = cairo_image_surface_create_from_png(path.c_str());
  if (cairo_surface_status(s) == CAIRO_STATUS_SUCCESS) {
    img.width = cairo_image_surface_get_width(s);
    img.height = cairo_image_surface_get_height(s);
    const unsigned char* data = cairo_image_surface_get_data(s);
    const int stride = cairo_image_surface_get_stride(s);
    for (int y = 0; y < img.height; ++y)
      for (int x = 0; x < img.width; ++x) {
        const auto v = *reinterpret_cast<const std::uint32_t*>(data + y * stride + 4 * x);
        img.pixels.push_back({int((v >> 16) & 0xff), int((v >> 8) & 0xff), int(v & 0xff)});
      }
  }
  cairo_surface_destroy(s);
  return img;
}

void write_png(const Image& img, const std::string& path) {
  cairo_surface_t* s = cairo_image_surface_create(CAIRO_FORMAT_RGB24, img.width, img.height);
  unsigned char* data = cairo_image_surface_get_data(s);
  const int stride = cairo_image_surface_get_stride(s);
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) {
      const Rgb c = img.pixels[static_cast<std::size_t>(y) * img.width + x];
      *reinterpret_cast<std::uint32_t*>(data + y * stride + 4 * x) = std::uint32_t(c.r << 16 | c.g << 8 | c.b);
    }
  cairo_surface_mark_dirty(s);
  cairo_surface_write_to_png(s, path.c_str());
  cairo_surface_destroy(s);
}

// XWD: a header of big-endian 32-bit words, a colour map, then the pixels (32 bits, 0x00RRGGBB at depth 24).
Image read_xwd(const std::string& path) {
  Image img;
  std::ifstream in(path, std::ios::binary);
  std::vector<unsigned char> b((std::istreambuf_iterator<char>(in)), {});
  const auto word = [&](int i) {
    const std::size_t o = 4 * static_cast<std::size_t>(i);
    return std::uint32_t(b[o]) << 24 | std::uint32_t(b[o + 1]) << 16 | std::uint32_t(b[o + 2]) << 8 | b[o + 3];
  };
  if (b.size() < 100 || word(11) != 32) return img;
  const std::size_t start = word(0) + 12 * std::size_t(word(19)), line = word(12);
  img.width = int(word(4));
  img.height = int(word(5));
  const bool msb = word(7) == 1;
  if (b.size() < start + line * img.height) return {};
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) {
      const unsigned char* p = &b[start + line * y + 4 * x];
      const std::uint32_t v = msb ? (std::uint32_t(p[0]) << 24 | p[1] << 16 | p[2] << 8 | p[3])
                                  : (std::uint32_t(p[3]) << 24 | p[2] << 16 | p[1] << 8 | p[0]);
      img.pixels.push_back({int((v >> 16) & 0xff), int((v >> 8) & 0xff), int(v & 0xff)});
    }
  return img;
}

// "view centre X,Y m, S px/m, yaw A deg, pitch B deg" in ladder-view's output -> its camera.
std::optional<Camera> camera_in(const std::string& output, int width, int height) {
  std::smatch m;
  if (!std::regex_search(output, m, std::regex(R"(view centre ([-0-9.e+]+),([-0-9.e+]+) m, ([0-9.e+]+) px/m, )"
                                               R"(yaw ([-0-9.e+]+) deg, pitch ([-0-9.e+]+) deg)")))
    return std::nullopt;
  Camera c;
  c.cx = std::stod(m[1]);
  c.cy = std::stod(m[2]);
  c.scale = std::stod(m[3]);
  c.yaw = std::stod(m[4]) * M_PI / 180;
  c.pitch = std::stod(m[5]) * M_PI / 180;
  c.width = width;
  c.height = height;
  return c;
}

// Which wide face of a block faces the camera: +1 its +x face, -1 its -x face (the model's geometry, draw.hpp).
int facing_side(const Camera& cam, const client::Pose& p) {
  const view::Vec3 n = cam.to_view({cam.cx + std::cos(p.theta), cam.cy + std::sin(p.theta), 0});
  return n.z > 0 ? 1 : -1;
}

// A point on block i's wide face toward the camera, at `y` along its length and `z` across its depth (fractions:
// 0 is the middle), projected.
Point on_wide_face(const Camera& cam, const client::SceneInfo& info, const client::Pose& p, double y, double z) {
  const double x = 0.5 * info.thickness * facing_side(cam, p);
  const double c = std::cos(p.theta), s = std::sin(p.theta), ly = y * info.length;
  return cam.project({p.x + c * x - s * ly, p.y + s * x + c * ly, z * view::depth_of(info)});
}

// Every block's wide face is where the state puts it: a point of it clear of its tapes (z = -0.16 of the depth lies
// between the central tape and an outer one) and of the hand (block 0: low on the face) shows that block's face
// colour. `offset` is the picture's place on the image.
void expect_blocks_at_centres(const Image& img, const Camera& cam, const client::SceneInfo& info,
                              const client::State& s, Point offset = {}) {
  ASSERT_GT(img.width, 0) << "no picture";
  for (std::size_t i = 0; i < s.blocks.size(); ++i) {
    const Point p = on_wide_face(cam, info, s.blocks[i], i == 0 ? -0.35 : 0, -0.16);
    const Rgb c = img.at({p.x + offset.x, p.y + offset.y}), want = view::face_colour(static_cast<int>(i));
    EXPECT_LT(distance(c, want), 12) << "block " << i << " at pixel (" << p.x + offset.x << ", " << p.y + offset.y
                                     << "): rgb " << c.r << "," << c.g << "," << c.b << ", want " << want.r << ","
                                     << want.g << "," << want.b;
  }
}

// The tapes each block shows on its face toward the camera: 'o' two outer ones, 'c' one central one, '-' none,
// read off the picture at the middle of the depth and at an outer tape's place.
std::string tapes_seen(const Image& img, const Camera& cam, const client::SceneInfo& info, const client::State& s,
                       Point offset = {}) {
  std::string out;
  for (std::size_t i = 0; i < s.blocks.size(); ++i) {
    const double y = i == 0 ? -0.35 : 0;
    const Point mid = on_wide_face(cam, info, s.blocks[i], y, 0), outer = on_wide_face(cam, info, s.blocks[i], y, 0.32);
    const bool central = distance(img.at({mid.x + offset.x, mid.y + offset.y}), view::kRibbon) < 12;
    const bool outers = distance(img.at({outer.x + offset.x, outer.y + offset.y}), view::kRibbon) < 12;
    out += central ? (outers ? '?' : 'c') : (outers ? 'o' : '-');
  }
  return out;
}

bool is_hand(Rgb c) { return c.b > c.r + 40 && c.b > c.g + 20; }

// ---------------------------------------------------------------------------------------------------------------
// The drawing module alone.

client::SceneInfo classic_info(std::uint32_t blocks) {
  client::SceneInfo info;
  info.blocks = blocks;
  info.length = 0.064;
  info.thickness = 0.013;
  return info;
}

// A hanging zigzag of n blocks (each tilted by +-atan(thickness / length), as the real one at rest).
client::State zigzag(int n) {
  client::State s;
  const double tilt = std::atan(0.013 / 0.064);
  for (int i = 0; i < n; ++i) {
    s.blocks.push_back({i % 2 ? 0.004 : 0.0, -0.066 * i, i % 2 ? tilt : -tilt});
    s.hinges.push_back({static_cast<std::uint8_t>(i % 2 ? 0 : 3), ladder_msg_HINGED, 0});
  }
  if (n > 3) s.hinges[3].status = ladder_msg_LOCKED;
  return s;
}

Image render(const Camera& cam, const client::SceneInfo& info, const client::State& s, const std::string& name,
             int* drawn = nullptr, const view::Hud& hud = {}) {
  cairo_surface_t* surface = cairo_image_surface_create(CAIRO_FORMAT_ARGB32, cam.width, cam.height);
  cairo_t* cr = cairo_create(surface);
  const int n = view::draw(cr, cam, info, s, hud);
  if (drawn) *drawn = n;
  cairo_destroy(cr);
  const std::string path = kBin + "/tests/" + name + ".png";
  cairo_surface_write_to_png(surface, path.c_str());
  cairo_surface_destroy(surface);
  return read_png(path);
}

// The blocks with their numbers only (no heading, scale bar or marks): what the labels' tests read.
view::Hud numbers_only() {
  view::Hud hud;
  hud.show = hud.scale_bar = hud.marks = false;
  hud.numbers = true;
  return hud;
}

// The ladder's right edge on screen [px].
double right_edge(const Camera& cam, const client::SceneInfo& info, const client::State& s) {
  double right = -1e300;
  for (const client::Pose& p : s.blocks)
    for (const Point& c : view::outline(info, p)) right = std::max(right, cam.to_screen(c).x);
  return right;
}

// How many runs of pixels other than the background (labels' boxes) the n pixels from `from` by `step` cross.
int boxes_along(const Image& img, Point from, Point step, int n) {
  int boxes = 0;
  bool in_box = false;
  for (int k = 0; k < n; ++k) {
    const bool box = distance(img.at({from.x + k * step.x, from.y + k * step.y}), view::kBackground) > 20;
    boxes += box && !in_box ? 1 : 0;
    in_box = box;
  }
  return boxes;
}

// The 3-D view of a known state: each block's wide face where the state puts it, the tapes each face carries (two
// outer ones on the even blocks, a central one on the odd ones, as the hanging toy shows them), the hand on the
// held top block; a click (pick) finds the block under it. Then block 2 turned over, as a flip-flop leaves it: its
// other face, with the other tapes, is the one seen.
TEST(Draw, BlocksRibbonsAndTheHandWhereTheStateHasThem) {
  client::SceneInfo info = classic_info(6);
  info.top = "held";
  info.options = "sim.dt=0.001\nladder.depth=0.04\n";
  EXPECT_EQ(view::depth_of(info), 0.04);
  client::State s = zigzag(6);
  const Camera cam = view::fit(info, s, 400, 600);
  EXPECT_FALSE(cam.side());
  int drawn = 0;
  const Image img = render(cam, info, s, "Draw3d", &drawn);
  EXPECT_EQ(drawn, 6);
  expect_blocks_at_centres(img, cam, info, s);
  for (std::size_t i = 0; i < s.blocks.size(); ++i) EXPECT_EQ(facing_side(cam, s.blocks[i]), 1) << i;
  EXPECT_EQ(tapes_seen(img, cam, info, s), "ocococ");
  EXPECT_TRUE(is_hand(img.at(cam.project(view::hand_centre(info, s.blocks[0])))));
  EXPECT_EQ(distance(img.at({399, 0}), view::kBackground), 0);
  // The scale bar, bottom left: its line 18 px above the bottom, nothing just above it.
  EXPECT_LT(distance(img.at({30, 600 - 18}), view::kText), 40);
  EXPECT_EQ(distance(img.at({30, 600 - 30}), view::kBackground), 0);
  // Picking: the block under each face point, and a point of it inside its rectangle; nothing on the background.
  for (int i = 0; i < 6; ++i) {
    const view::Pick p = view::pick(cam, info, s, on_wide_face(cam, info, s.blocks[i], 0.2, -0.16));
    EXPECT_EQ(p.block, i);
    EXPECT_EQ(view::block_at(info, s, p.world), i);
  }
  EXPECT_EQ(view::pick(cam, info, s, {5, 300}).block, -1);

  // Block 2 turned over about its centre: its -x face (hinge 2's central tape) now faces the camera.
  s.blocks[2].theta += M_PI;
  const Image flipped = render(cam, info, s, "Draw3d-flipped");
  EXPECT_EQ(facing_side(cam, s.blocks[2]), -1);
  EXPECT_EQ(tapes_seen(flipped, cam, info, s), "occcoc");
  // A broken hinge has no tapes: hinge 1's (the outer ones on block 0, the central one on block 1) are gone.
  s.hinges[1].status = ladder_msg_BROKEN;
  EXPECT_EQ(tapes_seen(render(cam, info, s, "Draw3d-broken"), cam, info, s), "--ccoc");
}

// The side view (the model's plane): each block's narrow side at its centre, the locked hinge's red dot on its
// particle; and the text rendering, every block numbered.
TEST(Draw, SideViewAndAscii) {
  const client::SceneInfo info = classic_info(6);
  const client::State s = zigzag(6);
  const Camera cam = view::fit(info, s, 300, 500, 40, 0, 0);
  EXPECT_TRUE(cam.side());
  const Image img = render(cam, info, s, "DrawSide");
  for (std::size_t i = 0; i < s.blocks.size(); ++i)
    EXPECT_LT(distance(img.at(cam.to_screen({s.blocks[i].x, s.blocks[i].y})), view::side_colour(int(i))), 12) << i;
  EXPECT_EQ(distance(img.at({299, 0}), view::kBackground), 0);
  const Point h = cam.to_screen(view::hinge_particle(info, 3, s.hinges[3].corner, s.blocks[3]));
  EXPECT_LT(distance(img.at(h), view::kLocked), 12);
  for (int i = 0; i < 6; ++i) EXPECT_EQ(view::block_at(info, s, {s.blocks[i].x, s.blocks[i].y}), i);
  EXPECT_EQ(view::block_at(info, s, {0.5, 0.5}), -1);
  // Text: one cell row per two pixel rows; every block's number at its centre.
  const std::string text = view::render_ascii(view::fit(info, s, 60, 60), info, s, 60, 30);
  for (char d = '0'; d <= '5'; ++d) EXPECT_NE(text.find(d), std::string::npos) << text;
  EXPECT_GT(std::count(text.begin(), text.end(), '#'), 30) << text;
}

// The terminal's marks are characters where the hinges and grips are, not pixels read back: with hinge 3 locked,
// hinge 5 broken and a grip, exactly one '@', two 'x' (the broken hinge's two ends, apart), one '*', an 'o' for each
// of the three plain hinges, and none of them anywhere else (an antialiased edge of the hand or a side was read as
// 'x' or 'o' before).
TEST(Draw, AsciiMarksAreWhereTheHingesAndGripsAre) {
  const client::SceneInfo info = classic_info(6);
  client::State s = zigzag(6);
  s.hinges[5].status = ladder_msg_BROKEN;
  s.blocks[5].x += 0.03;  // fallen away: its hinge corner 3 cm from block 4's
  ladder_msg_Grip g{};
  g.block = 2;
  g.target_x = 0.05;
  g.target_y = -0.13;
  s.grips.push_back(g);
  const int cols = 80, rows = 60;
  const Camera cam = view::fit(info, s, cols, 2 * rows);
  const std::string text = view::render_ascii(cam, info, s, cols, rows);
  EXPECT_EQ(std::count(text.begin(), text.end(), '@'), 1) << text;
  EXPECT_EQ(std::count(text.begin(), text.end(), 'x'), 2) << text;
  EXPECT_EQ(std::count(text.begin(), text.end(), '*'), 1) << text;
  EXPECT_EQ(std::count(text.begin(), text.end(), 'o'), 3) << text;
  // Each where the picture has it.
  const auto cell = [&](Point p) {
    return text[static_cast<std::size_t>(std::floor(0.5 * p.y)) * (cols + 1) + static_cast<std::size_t>(std::floor(p.x))];
  };
  EXPECT_EQ(cell(cam.to_screen({g.target_x, g.target_y})), '*') << text;
  for (const view::Mark& m : view::marks(cam, info, s)) EXPECT_EQ(cell(m.at), m.ch) << text;
}

// Rolling hinges (docs/model.md section 9), computed here apart from the viewer's own geometry: corner c of block i
// has an arc of radius r centred r in from both edges (corners 0 and 1 on the +x side; corner 0 at the low end of
// even blocks and the high end of odd ones), and a hinge's contact point is halfway between its two arc centres.
struct Rolling {
  double length = 0.064, thickness = 0.013, r = 0;
  // Block frame -> world.
  static Point world(const client::Pose& p, Point l) {
    const double c = std::cos(p.theta), s = std::sin(p.theta);
    return {p.x + c * l.x - s * l.y, p.y + s * l.x + c * l.y};
  }
  // The centre of the arc at the corner on side sx (+1: +x) and end sy (+1: the high end), in the block's frame.
  Point centre(int sx, int sy) const { return {sx * (0.5 * thickness - r), sy * (0.5 * length - r)}; }
  // Corner c's side and end.
  static int side(int c) { return (c & 2) ? -1 : 1; }
  static int end(int block, int c) { return ((c & 1) == 0) == (block % 2 == 0) ? -1 : 1; }
  Point corner_centre(int block, int c) const { return centre(side(c), end(block, c)); }
  // The point of that arc whose outward normal is turned by `angle` from (sx, 0) toward (0, sy), `out` beyond it
  // along the normal.
  Point on_arc(int sx, int sy, double angle, double out = 0) const {
    const Point c = centre(sx, sy);
    return {c.x + (r + out) * sx * std::cos(angle), c.y + (r + out) * sy * std::sin(angle)};
  }
};

client::SceneInfo rolling_info(std::uint32_t blocks, double r) {
  client::SceneInfo info = classic_info(blocks);
  char options[160];
  std::snprintf(options, sizeof options, "sim.dt=0.001\nladder.depth=0.045\nladder.hinge=rolling\nladder.end_radius=%.17g\n",
                r);
  info.options = options;
  info.top = "free";
  return info;
}

// Blocks 0 and 1 joined by hinge 1 on their +x arcs (block 0's low end, block 1's high end): block 0 upright at the
// origin, block 1 turned by `bend` toward the +x side, rolled on block 0 without slipping, so that the contact's
// direction from block 0's arc centre has turned from straight down by half the bend. Returns the contact point too.
client::State rolling_pair(const Rolling& g, double bend, Point& contact) {
  client::State s;
  s.blocks.push_back({0, 0, 0});
  const Point ca = Rolling::world(s.blocks[0], g.corner_centre(0, 0));
  const Point u{std::sin(0.5 * bend), -std::cos(0.5 * bend)};
  const Point cb{ca.x + 2 * g.r * u.x, ca.y + 2 * g.r * u.y};
  const Point lb = g.corner_centre(1, 0);
  const double c = std::cos(bend), sn = std::sin(bend);
  s.blocks.push_back({cb.x - (c * lb.x - sn * lb.y), cb.y - (sn * lb.x + c * lb.y), bend});
  s.hinges = {{0, ladder_msg_HINGED, 0}, {0, ladder_msg_HINGED, 0}};
  contact = {ca.x + g.r * u.x, ca.y + g.r * u.y};
  return s;
}

bool is_ribbon(Rgb c) { return distance(c, view::kRibbon) < 12; }
// Any of the blocks' colours (the palette's wood: red well above green, green well above blue).
bool is_wood(Rgb c) { return c.r > c.g + 30 && c.g > c.b + 20; }

// The outline the viewer draws and picks rolling-hinge blocks by, for a pair bent by 30, 90 and 150 degrees: its
// area is the rounded rectangle's, L T - (4 - pi) r^2, less at most what 8 chords a quarter arc leave out (a cut at
// a contact point leaves out less); on each
// block, the hinge arc's tapes change hands (its own to the other block's) exactly at the contact point, halfway
// between the arc centres, which moves along the arcs as the pair bends.
TEST(Draw, RoundedOutlineSplitsEachHingeArcAtTheContactPoint) {
  Rolling g;
  g.r = 0.013 / 4;
  const client::SceneInfo info = rolling_info(2, g.r);
  for (const double bend_deg : {30.0, 90.0, 150.0}) {
    SCOPED_TRACE("bend " + std::to_string(bend_deg) + " deg");
    Point p;
    const client::State s = rolling_pair(g, bend_deg * M_PI / 180, p);
    const Point pv = view::pivot(info, s, 1);
    EXPECT_NEAR(pv.x, p.x, 1e-15);
    EXPECT_NEAR(pv.y, p.y, 1e-15);
    std::vector<view::Facet> f;
    for (const int block : {0, 1}) {
      view::rounded_outline(info, s, block, g.r, 8, f);
      double area = 0;
      for (const view::Facet& e : f) area += 0.5 * (e.a.x * e.b.y - e.b.x * e.a.y);
      const double exact = g.length * g.thickness - (4 - M_PI) * g.r * g.r;
      const double chords = 4 * 8 * 0.5 * g.r * g.r * (M_PI / 16 - std::sin(M_PI / 16));  // the segments cut off
      EXPECT_GE(area, exact - chords - 1e-15) << "block " << block;
      EXPECT_LE(area, exact) << "block " << block;
      const Point local = view::to_block_frame(s.blocks[block], p);
      int handovers = 0;
      for (std::size_t k = 0; k < f.size(); ++k) {
        const view::Facet& a = f[k];
        const view::Facet& b = f[(k + 1) % f.size()];
        if (a.hinge != 1 || b.hinge != 1 || a.owner == b.owner) continue;
        ++handovers;
        EXPECT_NEAR(a.b.x, local.x, 1e-12) << "block " << block;
        EXPECT_NEAR(a.b.y, local.y, 1e-12) << "block " << block;
      }
      EXPECT_EQ(handovers, 1) << "block " << block;
    }
  }
}

// The side view of a rolling pair bent by 90 degrees, with ends rounded by a quarter and by half the thickness: each
// corner's arc is where the radius puts it (3 px outside it the background, 4 px inside the block's colour), on the
// ends' flat part too; the tapes, drawn as lines along the outline in this view, run along the hinge's side (+x) and
// cross at the contact point: on each block's hinge arc its own tapes up to the contact, the other block's beyond
// it, then over the rest of that end; the -x side, which no hinge uses here, has none. A click finds the block in
// its arc, and nothing at the cut-off corner.
TEST(Draw, RoundedEndsAndTheTapesCrossingAtTheContactInTheSideView) {
  for (const double r : {0.013 / 4, 0.013 / 2}) {
    SCOPED_TRACE("end radius " + std::to_string(r));
    Rolling g;
    g.r = r;
    const client::SceneInfo info = rolling_info(2, r);
    EXPECT_EQ(view::end_radius_of(info), r);
    Point p;
    const client::State s = rolling_pair(g, M_PI / 2, p);
    Camera cam;
    cam.width = cam.height = 700;
    cam.cx = p.x;
    cam.cy = p.y;
    cam.scale = 12000;  // the radius 39 or 78 px
    const double px = 1 / cam.scale;
    const std::string name = r < 0.005 ? "DrawRollingSide-quarter" : "DrawRollingSide-half";
    const Image img = render(cam, info, s, name);
    const auto at = [&](int block, Point local) { return img.at(cam.to_screen(Rolling::world(s.blocks[block], local))); };
    // The arcs at the ends that meet at the hinge, both corners of each.
    for (const auto& [block, sy] : {std::pair{0, -1}, std::pair{1, 1}})
      for (const int sx : {-1, 1})
        for (const double deg : {15.0, 45.0, 75.0}) {
          const double a = deg * M_PI / 180;
          if (sx == 1 && deg == 45.0) continue;  // the contact, under the hinge's dot
          // Block 1's arcs on the hinge's side face block 0 across the contact: only the other side's show a gap.
          if (!(block == 1 && sx == 1)) {
            const Rgb outside = at(block, g.on_arc(sx, sy, a, 3 * px));
            EXPECT_EQ(distance(outside, view::kBackground), 0)
                << "block " << block << " arc (" << sx << ", " << sy << ") at " << deg << " deg, 3 px out: rgb "
                << outside.r << "," << outside.g << "," << outside.b;
          }
          const Rgb inside = at(block, g.on_arc(sx, sy, a, -4 * px));
          EXPECT_LT(distance(inside, view::side_colour(block)), 12)
              << "block " << block << " arc (" << sx << ", " << sy << ") at " << deg << " deg, 4 px in: rgb "
              << inside.r << "," << inside.g << "," << inside.b;
        }
    if (r < 0.5 * g.thickness) {  // the flat middle of block 0's low end
      EXPECT_EQ(distance(at(0, {0, -0.5 * g.length - 4 * px}), view::kBackground), 0);
      EXPECT_LT(distance(at(0, {0, -0.5 * g.length + 4 * px}), view::side_colour(0)), 12);
    }
    // The tapes. Hinge 1's arcs: block 0's from its +x face (0 deg) to its low end (90), block 1's from its +x face
    // to its high end; the contact is at 45 deg on both. Its own tapes before the contact, the other's after it, so
    // on every arm of the crossing; and the other corner of each end, wrapped by the crossed tapes.
    for (const int block : {0, 1})
      for (const double deg : {12.0, 30.0, 60.0, 78.0}) {
        const Rgb c = at(block, g.on_arc(1, block == 0 ? -1 : 1, deg * M_PI / 180));
        EXPECT_TRUE(is_ribbon(c)) << "block " << block << " hinge arc at " << deg << " deg: rgb " << c.r << "," << c.g
                                  << "," << c.b;
        EXPECT_TRUE(is_ribbon(at(block, g.on_arc(-1, block == 0 ? -1 : 1, deg * M_PI / 180))))
            << "block " << block << " the end's other arc at " << deg << " deg";
      }
    EXPECT_LT(distance(img.at(cam.to_screen(p)), view::kHinge), 12) << "the hinge's dot at the contact";
    for (const int block : {0, 1}) {
      const double y = (block == 0 ? -1 : 1) * (0.5 * g.length - r - 80 * px);  // along the face, 80 px from the arc
      EXPECT_TRUE(is_ribbon(at(block, {0.5 * g.thickness, y}))) << "block " << block << ": its +x face has tapes";
      const Rgb none = at(block, {-0.5 * g.thickness + 1 * px, y});
      EXPECT_LT(distance(none, view::side_colour(block)), 12) << "block " << block << ": its -x face has none";
    }
    // Picking: in the arc, block 0; at its cut-off corner, nothing (the ray passes the rounded box).
    const Point in = Rolling::world(s.blocks[0], g.on_arc(-1, -1, M_PI / 4, -4 * px));
    const Point out = Rolling::world(s.blocks[0], g.on_arc(-1, -1, M_PI / 4, 3 * px));
    EXPECT_EQ(view::block_at(info, s, in), 0);
    EXPECT_EQ(view::block_at(info, s, out), -1);
    EXPECT_EQ(view::pick(cam, info, s, cam.to_screen(in)).block, 0);
    EXPECT_EQ(view::pick(cam, info, s, cam.to_screen(out)).block, -1);
    // The terminal: the same picture read back cell by cell (one pixel a column, two a row). Near block 0's -x low
    // corner (1.5 px in from it), the rounded block leaves the cell empty where the square one has its side (':');
    // its +x face's cell is a tape ('+') where the square one, whose tapes are edge-on, has none.
    Camera small = cam;
    small.scale = 4000;
    small.cx = 0;  // block 0's centre line: its -x corner in the picture
    small.width = 80;
    small.height = 120;
    const auto cell = [&](Point local) {
      const Point q = small.to_screen(Rolling::world(s.blocks[0], local));
      return static_cast<std::size_t>(q.y / 2) * 81 + static_cast<std::size_t>(q.x);
    };
    const std::size_t corner = cell({-0.5 * g.thickness + 1.5 / small.scale, -0.5 * g.length + 1.5 / small.scale});
    const std::size_t face = cell({0.5 * g.thickness - 0.3 / small.scale, -0.5 * g.length + r + 12 / small.scale});
    const std::string text = view::render_ascii(small, info, s, 80, 60);
    EXPECT_EQ(text.at(corner), ' ') << text;
    EXPECT_EQ(text.at(face), '+') << text;
    client::SceneInfo square = info;
    square.options = "ladder.hinge=corner\nladder.end_radius=0\n";
    EXPECT_EQ(view::end_radius_of(square), 0);
    const std::string text0 = view::render_ascii(small, square, s, 80, 60);
    EXPECT_EQ(text0.at(corner), ':') << text0;
    EXPECT_NE(text0.at(face), '+') << text0;
  }
}

// The same pair in 3-D. Seen from the front right and above (the default view), block 0's hinge arc carries its two
// outer tapes from its +x face round toward the contact, and its front narrow side is cut off at its rounded corner.
// Seen from the left, below, into the wedge the bend opens between the two ends, each end carries the other block's
// tapes that crossed at the contact: block 1's end the outer pair of block 0, block 0's end the central tape of
// block 1.
TEST(Draw, RoundedEndsIn3dTheTapesWrapThemAndCross) {
  Rolling g;
  g.r = 0.013 / 4;
  const client::SceneInfo info = rolling_info(2, g.r);
  Point p;
  const client::State s = rolling_pair(g, M_PI / 2, p);
  const double d = view::depth_of(info), hw = 0.5 * g.thickness, hl = 0.5 * g.length;
  const auto world3 = [&](int block, Point l, double z) {
    const Point w = Rolling::world(s.blocks[block], l);
    return view::Vec3{w.x, w.y, z};
  };
  Camera cam;
  cam.width = cam.height = 700;
  cam.cx = p.x;
  cam.cy = p.y;
  cam.scale = 8000;
  cam.yaw = view::kDefaultYaw;
  cam.pitch = view::kDefaultPitch;
  const Image front = render(cam, info, s, "DrawRolling3d-front");
  const auto at = [&](const Image& img, const Camera& c, int block, Point l, double z) {
    return img.at(c.project(world3(block, l, z)));
  };
  const Point arc = g.on_arc(1, -1, 0.25 * M_PI / 2, -0.5 / cam.scale);  // a quarter of the way from face to end
  EXPECT_TRUE(is_ribbon(at(front, cam, 0, arc, 0.32 * d)));
  EXPECT_TRUE(is_ribbon(at(front, cam, 0, arc, -0.32 * d)));
  EXPECT_LT(distance(at(front, cam, 0, arc, 0), view::face_colour(0)), 12);
  EXPECT_LT(distance(at(front, cam, 0, arc, 0.16 * d), view::face_colour(0)), 12);
  // The front narrow side's corner: nothing of the block there; inside the arc, the narrow side.
  EXPECT_EQ(distance(at(front, cam, 0, {-hw, -hl}, 0.5 * d), view::kBackground), 0);
  EXPECT_LT(distance(at(front, cam, 0, g.on_arc(-1, -1, M_PI / 4, -4 / cam.scale), 0.5 * d), view::side_colour(0)),
            12);

  Camera wedge = cam;
  wedge.yaw = 50 * M_PI / 180;
  wedge.pitch = -20 * M_PI / 180;
  const Image img = render(wedge, info, s, "DrawRolling3d-wedge");
  // Block 1's high end faces the camera (it is turned by 90 degrees), block 0's low end faces down.
  EXPECT_TRUE(is_ribbon(at(img, wedge, 1, {0, hl}, 0.32 * d)));
  EXPECT_TRUE(is_ribbon(at(img, wedge, 1, {0, hl}, -0.32 * d)));
  EXPECT_LT(distance(at(img, wedge, 1, {0, hl}, 0), view::kDepth), 12);
  EXPECT_TRUE(is_ribbon(at(img, wedge, 0, {0, -hl}, 0)));
  EXPECT_LT(distance(at(img, wedge, 0, {0, -hl}, 0.32 * d), view::kDepth), 12);
  // On the arcs: block 1's hinge arc beyond the contact (67.5 deg from its face, the contact at 45) and the arc at
  // its end's other corner carry block 0's outer pair; the arc at block 0's end's other corner, block 1's central
  // tape.
  const auto tapes_at = [&](int block, Point l) {
    std::string out;
    for (const double z : {-0.32, 0.0, 0.32}) {
      const Rgb c = at(img, wedge, block, l, z * d);
      out += is_ribbon(c) ? '+' : is_wood(c) ? '#' : '?';
    }
    return out;
  };
  EXPECT_EQ(tapes_at(1, g.on_arc(1, 1, 67.5 * M_PI / 180, -0.5 / wedge.scale)), "+#+");
  EXPECT_EQ(tapes_at(1, g.on_arc(-1, 1, M_PI / 4, -0.5 / wedge.scale)), "+#+");
  EXPECT_EQ(tapes_at(0, g.on_arc(-1, -1, M_PI / 4, -0.5 / wedge.scale)), "#+#");
  // A click on block 1's end picks block 1.
  EXPECT_EQ(view::pick(wedge, info, s, wedge.project(world3(1, {0, hl}, 0.2 * d))).block, 1);
}

TEST(Draw, OnlyWhatIsOnScreenOfAHundredThousandBlocks) {
  const client::SceneInfo info = classic_info(100000);
  const client::State s = zigzag(100000);
  Camera cam = view::fit(info, s, 800, 600);  // the top 40 blocks
  cairo_surface_t* surface = cairo_image_surface_create(CAIRO_FORMAT_ARGB32, 800, 600);
  cairo_t* cr = cairo_create(surface);
  const int drawn = view::draw(cr, cam, info, s, view::Hud{});
  EXPECT_GE(drawn, 40);
  EXPECT_LT(drawn, 60);
  cam.cy = -0.066 * 70000;  // far down the ladder: the blocks there, none of the others
  const int far = view::draw(cr, cam, info, s, view::Hud{});
  EXPECT_GE(far, 40);
  EXPECT_LT(far, 60);
  cairo_destroy(cr);
  cairo_surface_destroy(surface);
}

// The plots' history: a flip-flop where a hinge's count goes up, at that state's time; a reset starts again. The
// picture has each flip-flop's dot and the energy's line where the axes put them.
// A peer's state whose blocks lie beyond what a double spans (1e308 m either way): the view still has a finite,
// positive scale (it was 0 or NaN, and the drawing cast NaN to int), and the terminal view draws it. A grip's line to
// a target far off the image is clipped to the image (cairo took about 30 ms a grip to stroke a dashed line of
// millions of pixels): what is inside it is kept, what is not is refused, and a point that is not a number too.
TEST(Draw, NumbersBeyondADoublesSpanAndFarGripsStayDrawable) {
  const client::SceneInfo info = classic_info(6);
  client::State s = zigzag(6);
  s.blocks[0] = {1e308, -1e308, 0};
  s.blocks[5] = {-1e308, 1e308, 0};
  const Camera cam = view::fit(info, s, 400, 600);
  EXPECT_TRUE(std::isfinite(cam.scale) && cam.scale > 0) << cam.scale;
  EXPECT_TRUE(std::isfinite(cam.cx) && std::isfinite(cam.cy)) << cam.cx << " " << cam.cy;
  const std::string text = view::render_ascii(cam, info, s, 40, 20);
  EXPECT_EQ(std::count(text.begin(), text.end(), '\n'), 20) << text;

  Camera c;
  c.width = 400;
  c.height = 300;
  Point a{200, 150}, b{200 + 1e9, 150};  // to the right, a billion pixels on
  ASSERT_TRUE(view::clip_to_image(c, 6, a, b));
  EXPECT_EQ(a.x, 200);
  EXPECT_NEAR(b.x, 406, 1e-6);
  EXPECT_NEAR(b.y, 150, 1e-6);
  Point p{-1e9, -1e9}, q{-1e9, 1e9};  // wholly left of the image
  EXPECT_FALSE(view::clip_to_image(c, 6, p, q));
  Point u{-1e9, 150}, w{1e9, 150};  // across it
  ASSERT_TRUE(view::clip_to_image(c, 6, u, w));
  EXPECT_NEAR(u.x, -6, 1e-6);
  EXPECT_NEAR(w.x, 406, 1e-6);
  Point n{NAN, 0}, m{10, 10};
  EXPECT_FALSE(view::clip_to_image(c, 6, n, m));
}

// A heading or overlay line that snprintf cut inside a character (a scene named in a script other than Latin): cairo
// put the context in an error state at that line and drew nothing more of the frame, the scale bar after it among
// what was lost. The line is now drawn without the broken character, and the frame goes on.
TEST(Draw, ALineCutInsideACharacterDoesNotStopTheFrame) {
  const client::SceneInfo info = classic_info(6);
  const client::State s = zigzag(6);
  Camera cam = view::fit(info, s, 400, 300);
  view::Hud hud;
  hud.stats = true;
  hud.title = "ladder  'Лестница Иакова'";
  const std::string cut = std::string("Лестница").substr(0, 7);  // 3 whole letters and half of the 4th
  hud.lines = {cut, "after it"};
  hud.banner = cut;
  cairo_surface_t* surface = cairo_image_surface_create(CAIRO_FORMAT_RGB24, 400, 300);
  cairo_t* cr = cairo_create(surface);
  view::draw(cr, cam, info, s, hud);
  EXPECT_EQ(cairo_status(cr), CAIRO_STATUS_SUCCESS) << cairo_status_to_string(cairo_status(cr));
  cairo_surface_flush(surface);
  // The scale bar, drawn after the overlay: its left tick, 2 px wide at x = 16, from y = height - 23 to height - 18.
  const auto* px = reinterpret_cast<const std::uint32_t*>(cairo_image_surface_get_data(surface));
  const int stride = cairo_image_surface_get_stride(surface) / 4;
  const std::uint32_t tick = px[(300 - 20) * stride + 16];
  const Rgb got{int((tick >> 16) & 0xff), int((tick >> 8) & 0xff), int(tick & 0xff)};
  EXPECT_LT(distance(got, view::kText), 40) << got.r << "," << got.g << "," << got.b;
  cairo_destroy(cr);
  cairo_surface_destroy(surface);
}

// Block numbers on a ladder framed small: every 2nd one at 14 px a block, so that no two labels overlap (45 labels
// lay on top of each other on a 64-block ladder in 700 px). The labels down a column just right of the ladder are
// counted as separate boxes.
TEST(Draw, BlockNumbersOfASmallLadderDoNotOverlap) {
  EXPECT_EQ(view::number_stride(60), 1);
  EXPECT_EQ(view::number_stride(24), 1);
  EXPECT_EQ(view::number_stride(14), 2);
  EXPECT_EQ(view::number_stride(5), 5);
  EXPECT_EQ(view::number_stride(2), 20);
  EXPECT_EQ(view::number_stride(0), 1000000);  // (a block of no size: the numbers are not drawn below 12 px anyway)
  const client::SceneInfo info = classic_info(64);
  const client::State s = zigzag(64);
  Camera cam;
  cam.width = 300;
  cam.height = 1000;
  cam.scale = 14 / info.length;  // 14 px a block
  cam.cy = s.blocks[32].y;
  const Image img = render(cam, info, s, "Draw.BlockNumbersOfASmallLadder", nullptr, numbers_only());
  // Down the column just right of the ladder: blocks 0, 2, ..., 62, each its own box.
  EXPECT_EQ(boxes_along(img, {std::floor(right_edge(cam, info, s)) + 6, 0}, {0, 1}, cam.height), 32);
}

// A folded pair's two blocks lie side by side at one height: their numbers were drawn on top of each other. The
// second is moved right, past the first: along the labels' row, right of the ladder, two boxes.
TEST(Draw, TheNumbersOfAFoldedPairDoNotOverlap) {
  const client::SceneInfo info = classic_info(4);
  client::State s = zigzag(4);
  s.blocks[3] = {s.blocks[2].x + info.thickness, s.blocks[2].y, s.blocks[2].theta + M_PI};  // folded onto block 2
  Camera cam;
  cam.width = 300;
  cam.height = 300;
  cam.scale = 500;  // the pair's right edges 6.5 px apart: their labels' boxes (15 px wide) overlapped
  cam.cy = s.blocks[1].y;
  const Image img = render(cam, info, s, "Draw.TheNumbersOfAFoldedPair", nullptr, numbers_only());
  // Along the row of the boxes' top margin (above the digits, whose antialiased edges come near the background),
  // from just right of the ladder.
  const double x = std::floor(right_edge(cam, info, s)) + 2;
  const double y = std::floor(cam.to_screen({s.blocks[2].x, s.blocks[2].y}).y) - 9;
  EXPECT_EQ(boxes_along(img, {x, y}, {1, 0}, cam.width - static_cast<int>(x)), 2);
}

// The headings name the scene, cut with "..." past 40 characters (not bytes: never inside a character).
TEST(Draw, SceneLabelIsQuotedAndCutAtWholeCharacters) {
  EXPECT_EQ(view::scene_label("classic (at rest)"), "'classic (at rest)'");
  EXPECT_EQ(view::scene_label(std::string(40, 'a')), "'" + std::string(40, 'a') + "'");
  EXPECT_EQ(view::scene_label(std::string(41, 'a')), "'" + std::string(40, 'a') + "...'");
  std::string cyrillic;  // 50 letters of 2 bytes each
  for (int i = 0; i < 50; ++i) cyrillic += "Ж";
  EXPECT_EQ(view::scene_label(cyrillic), "'" + cyrillic.substr(0, 80) + "...'");
  EXPECT_EQ(view::scene_label(cyrillic, 3), "'ЖЖЖ...'");
  EXPECT_EQ(view::scene_label(""), "''");
}

// The plots' axes are ticked at 1, 2 or 5 times a power of ten, at most a few ticks each, hinges at whole numbers;
// the time axis's tick at 1 s is drawn under the frame where the axes put 1 s.
TEST(Plot, AxesAreTickedAtRoundValues) {
  using V = std::vector<double>;
  EXPECT_EQ(view::nice_ticks(0, 1, 5), (V{0, 0.2, 0.4, 0.6000000000000001, 0.8, 1}));
  EXPECT_EQ(view::nice_ticks(193.9, 203.4, 6), (V{194, 196, 198, 200, 202}));
  const V energy = view::nice_ticks(-0.283, -0.18, 5);  // a step of 0.02 would make 6 ticks: 0.05
  ASSERT_EQ(energy.size(), 2u);
  EXPECT_NEAR(energy[0], -0.25, 1e-15);
  EXPECT_NEAR(energy[1], -0.2, 1e-15);
  EXPECT_EQ(view::nice_ticks(0, 5.5, 8, true), (V{0, 1, 2, 3, 4, 5}));
  EXPECT_EQ(view::nice_ticks(0, 0.6, 8, true), (V{0}));  // whole: never a step below 1
  EXPECT_EQ(view::nice_ticks(0, 63.5, 8, true), (V{0, 10, 20, 30, 40, 50, 60}));
  EXPECT_TRUE(view::nice_ticks(1, 1, 5).empty());
  EXPECT_TRUE(view::nice_ticks(0, NAN, 5).empty());
  EXPECT_TRUE(view::nice_ticks(-1e308, 1e308, 5).empty());  // (the range itself is not finite)

  view::History h;
  h.add(1, 0.0, -1.0, {0, 0, 0});
  h.add(1, 2.0, -0.5, {0, 1, 0});
  cairo_surface_t* surface = cairo_image_surface_create(CAIRO_FORMAT_RGB24, 600, 400);
  cairo_t* cr = cairo_create(surface);
  view::draw_plots(cr, h, 0, 0, 600, 400);
  cairo_destroy(cr);
  cairo_surface_flush(surface);
  const auto axes = view::plot_axes(h, 0, 0, 600, 400);
  const auto* px = reinterpret_cast<const std::uint32_t*>(cairo_image_surface_get_data(surface));
  const int stride = cairo_image_surface_get_stride(surface) / 4;
  const auto at = [&](double x, double y) {
    const std::uint32_t p = px[static_cast<int>(y) * stride + static_cast<int>(x)];
    return Rgb{int((p >> 16) & 0xff), int((p >> 8) & 0xff), int(p & 0xff)};
  };
  for (const view::Axes& a : axes) {
    const double x = std::round(a.at(1.0, a.v0).x), below = a.y + a.h + 2;
    EXPECT_LT(distance(at(x, below), view::kFrame), 30) << "no tick at 1 s";
    EXPECT_GT(distance(at(x - 3, below), view::kFrame), 60) << "a tick beside 1 s";
  }
  cairo_surface_destroy(surface);
}

// Energies a log may hold, finite but at the ends of a double (+-1.7e308 J): the energy line is drawn inside its
// frame, from its bottom to its top. (Before, the range overflowed to infinity and the line was left out.)
TEST(Plot, EnergiesAtTheEndsOfADoubleAreDrawnInsideTheFrame) {
  view::History h;
  const double most = 1.7e308;
  h.add(1, 0.0, -most, {0, 0});
  h.add(1, 1.0, most, {0, 0});
  const auto axes = view::plot_axes(h, 0, 0, 600, 400);
  const view::Axes& e = axes[1];
  EXPECT_TRUE(std::isfinite(e.v0) && std::isfinite(e.v1));
  for (const double v : {-most, most}) {
    const view::Point p = e.at(1.0, v);
    EXPECT_TRUE(std::isfinite(p.y)) << v;
    EXPECT_GE(p.y, e.y) << v;
    EXPECT_LE(p.y, e.y + e.h) << v;
  }
  EXPECT_GT(e.at(0.0, -most).y - e.at(0.0, most).y, 0.8 * e.h);  // the line spans the frame
}

TEST(Plot, FlipFlopsAreDotsAtTheirHingeAndTime) {
  view::History h;
  h.add(1, 0.0, -1.0, {0, 0, 0});
  h.add(1, 1.0, -0.5, {0, 1, 0});
  h.add(1, 2.0, -0.8, {0, 1, 2});  // hinge 2 twice in one state: one dot (the two would be the same point)
  ASSERT_EQ(h.flips().size(), 2u);
  EXPECT_EQ(h.flips()[0].x, 1.0);
  EXPECT_EQ(h.flips()[0].y, 1.0);
  EXPECT_EQ(h.flips()[1].x, 2.0);
  EXPECT_EQ(h.flips()[1].y, 2.0);
  EXPECT_EQ(h.energy().size(), 3u);
  EXPECT_EQ(h.hinges(), 2);
  const std::string path = kBin + "/tests/Plot.png";
  ASSERT_EQ(view::write_plots_png(h, path, 600, 400), "");
  const Image img = read_png(path);
  const auto axes = view::plot_axes(h, 0, 0, 600, 400);
  EXPECT_EQ(distance(img.at(axes[0].at(1.0, 1.0)), view::kFlipDot), 0);
  EXPECT_EQ(distance(img.at(axes[0].at(2.0, 2.0)), view::kFlipDot), 0);
  EXPECT_NE(distance(img.at(axes[0].at(1.0, 2.0)), view::kFlipDot), 0);  // no flip-flop of hinge 2 at t = 1
  EXPECT_LT(distance(img.at(axes[1].at(1.0, -0.5)), view::kEnergyLine), 60);
  // A count that jumps by 4e9 (a peer's State: ladder-view and ladderctl plot grew to gigabytes, a point a flip) is one
  // dot too.
  view::History big;
  big.add(1, 0.0, -1.0, {0, 0, 0});
  big.add(1, 0.1, -1.0, {0, 4'000'000'000u, 0});
  big.add(1, 0.2, -1.0, {0, 0, 4'000'000'000u});
  EXPECT_EQ(big.flips().size(), 2u);
  h.add(1, 0.5, -1.0, {0, 0, 0});  // back in time: a reset
  EXPECT_TRUE(h.flips().empty());
  EXPECT_EQ(h.energy().size(), 1u);
  EXPECT_EQ(view::write_plots_png(h, "/nonexistent/dir/p.png", 600, 400).empty(), false);
}

// ---------------------------------------------------------------------------------------------------------------
// The real binary against a real server.

class View : public ::testing::Test {
 protected:
  // What the test's ladderd runs besides the built-in scene: --set options.
  virtual std::vector<std::string> scene_args() const { return {}; }

  void SetUp() override {
    const std::string name = test_name();
    sim_id_ = sim_id_for(name);
    domain_ = domain_for(name);
    log_path_ = kBin + "/tests/" + name + ".log";
    out_ = kBin + "/tests/" + name;
    std::vector<std::string> args{kBin + "/server/ladderd", "--domain", std::to_string(domain_), "--sim-id", sim_id_,
                                  "--log-level", "debug"};
    const std::vector<std::string> extra = scene_args();
    args.insert(args.end(), extra.begin(), extra.end());
    server_.emplace(args, log_path_);
    client_.emplace(domain_, sim_id_, "test");
    ASSERT_TRUE(client_->wait_for_server(kStart)) << "no ladderd on domain " << domain_ << "; its log:\n"
                                                  << server_->log();
  }

  std::string where() const { return " --domain " + std::to_string(domain_) + " --sim-id " + sim_id_; }
  Result viewer(const std::string& args) { return shell(kViewer + where() + " --timeout 30 " + args); }

  client::State pause() {
    const client::Ack a = client_->call(cmd::pause(), kAnswer);
    EXPECT_TRUE(a.accepted) << a.reason;
    auto s = client_->wait_state([&](const client::State& st) { return st.commands_applied >= a.command_seq; },
                                 kAnswer);
    EXPECT_TRUE(s && s->paused);
    return s.value_or(client::State{});
  }

  int domain_ = 0;
  std::string sim_id_, log_path_, out_;
  std::optional<Process> server_;
  std::optional<Client> client_;
};

// Before and after a tip (the server paused for each, so that the state drawn is the state the test holds): every
// block is where the state puts it, the hand holds the top block, and the ripple has turned every block over, so the
// face toward the camera is each block's other one, with the other tapes: outer and central swap all down the
// ladder (the paper's Figure 3); the top block's new face has none (its hinge there is hinge 0, the hand's hold), nor
// has the bottom block's (no hinge below it).
TEST_F(View, PngBeforeAndAfterATipShowsEveryBlockAndItsTapesWhereTheStateHasThem) {
  const client::State before = pause();
  const client::SceneInfo info = *client_->scene_info();
  ASSERT_EQ(info.top, "held");
  const Result a = viewer("--png " + out_ + "-before.png --size 500x700");
  ASSERT_EQ(a.code, 0) << a.output;
  const auto cam = camera_in(a.output, 500, 700);
  ASSERT_TRUE(cam) << a.output;
  const Image img0 = read_png(out_ + "-before.png");
  expect_blocks_at_centres(img0, *cam, info, before);
  EXPECT_EQ(tapes_seen(img0, *cam, info, before), "ocococ");
  EXPECT_TRUE(is_hand(img0.at(cam->project(view::hand_centre(info, before.blocks[0])))));

  ASSERT_TRUE(client_->call(cmd::resume(), kAnswer).accepted);
  ASSERT_TRUE(client_->call(cmd::tip(), kAnswer).accepted);
  // The ripple has reached the bottom hinge; then let it settle a little.
  const auto rippled = client_->wait_state(
      [](const client::State& s) { return s.hinges.size() == 6 && s.hinges[5].flips >= 1; }, Millis(30000));
  ASSERT_TRUE(rippled) << "no flip-flop at hinge 5";
  // Every block has turned over (the bottom one last, and it swings on for a while).
  const auto turned = [](const client::State& st) {
    return std::all_of(st.blocks.begin(), st.blocks.end(),
                       [](const client::Pose& p) { return std::cos(p.theta) < -0.7; });
  };
  ASSERT_TRUE(client_->wait_state(turned, Millis(30000))) << "the blocks did not all turn over";
  const client::State after = pause();
  char at[64];
  std::snprintf(at, sizeof at, "%.17g", after.sim_time);
  char view[160];
  std::snprintf(view, sizeof view, "%.17g,%.17g,%.17g,%.17g,%.17g", cam->cx, cam->cy, cam->scale,
                cam->yaw * 180 / M_PI, cam->pitch * 180 / M_PI);
  const Result b = viewer("--png " + out_ + "-after.png --size 500x700 --at " + at + " --view " + view);
  ASSERT_EQ(b.code, 0) << b.output;
  const Image img1 = read_png(out_ + "-after.png");
  expect_blocks_at_centres(img1, *cam, info, after);
  for (std::size_t i = 0; i < 6; ++i)
    EXPECT_EQ(facing_side(*cam, after.blocks[i]), -facing_side(*cam, before.blocks[i])) << "block " << i;
  EXPECT_EQ(tapes_seen(img1, *cam, info, after), "-ococ-");
  EXPECT_TRUE(is_hand(img1.at(cam->project(view::hand_centre(info, after.blocks[0])))));
  // Framed by the viewer itself, the ladder after the tip is framed at the scale it was before (a handout's two
  // snapshots were not, 1653 and 1436 px/m: the frame followed the blocks' bounds, which a tip changes), its centre
  // within a block's thickness (9 mm here).
  const Result c = viewer("--png " + out_ + "-after-framed.png --size 500x700 --at " + at);
  ASSERT_EQ(c.code, 0) << c.output;
  const auto framed = camera_in(c.output, 500, 700);
  ASSERT_TRUE(framed) << c.output;
  EXPECT_NEAR(framed->scale, cam->scale, 1e-6 * cam->scale) << a.output << c.output;
  EXPECT_LE(std::hypot(framed->cx - cam->cx, framed->cy - cam->cy), info.thickness) << a.output << c.output;
}

TEST_F(View, AsciiShowsTheSixBlocksNumbered) {
  const Result r = viewer("--ascii --frames 1 --size 60x40");
  ASSERT_EQ(r.code, 0) << r.output;
  // The heading: what is shown, then (no terminal to type in) how to tip it from elsewhere.
  const std::size_t picture = r.output.find("tip\n");
  ASSERT_NE(picture, std::string::npos) << r.output;
  const std::string scene = client_->scene_info()->scene_name;
  ASSERT_FALSE(scene.empty());
  EXPECT_NE(r.output.find("  '" + scene + "', 6 blocks  sim id '" + sim_id_ + "'\n"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("from another terminal: ladderctl --sim-id " + sim_id_ + " --domain " +
                          std::to_string(domain_) + " tip\n"),
            std::string::npos)
      << r.output;
  const std::string art = r.output.substr(picture);
  for (char d = '0'; d <= '5'; ++d) EXPECT_NE(art.find(d), std::string::npos) << "no block " << d << "\n" << art;
  EXPECT_EQ(art.find('6'), std::string::npos) << art;
  EXPECT_GT(std::count(art.begin(), art.end(), '#'), 40) << art;
}

// The terminal view as a user at an 80x24 terminal sees it (a pty): the heading names the keys, each block's number
// and every hinge's state are on screen; t tips (the server accepts it), space pauses, q ends it with status 0 and
// the cursor shown again.
TEST_F(View, TerminalAt80x24NamesTheKeysTipsPausesAndQuits) {
  Pty term({kViewer, "--ascii", "--domain", std::to_string(domain_), "--sim-id", sim_id_, "--timeout", "30"}, 80, 24);
  ASSERT_TRUE(term.started());
  ASSERT_TRUE(term.read_until("keys: t tip  space pause/resume  s step  r reset  q quit", 30)) << term.screen();
  // (cut at the terminal's width: the test's sim id is long)
  ASSERT_TRUE(term.read_until("from another terminal: ladderctl --sim-id " + sim_id_.substr(0, 30), 5))
      << term.screen();
  ASSERT_TRUE(term.read_until("hinge  state   flips", 5)) << term.screen();
  for (int k = 1; k <= 5; ++k)
    EXPECT_TRUE(term.read_until("    " + std::to_string(k) + "  hinged      0", 5)) << "hinge " << k << "\n"
                                                                                  << term.screen();
  // Every frame fits the terminal: no line longer than 80 characters between the cursor moves.
  const std::string& screen = term.screen();
  std::size_t longest = 0;
  for (std::size_t at = 0, nl; (nl = screen.find('\n', at)) != std::string::npos; at = nl + 1) {
    std::string line = std::regex_replace(screen.substr(at, nl - at), std::regex("\x1b\\[[0-9;?]*[A-Za-z]"), "");
    if (!line.empty() && line.back() == '\r') line.pop_back();
    longest = std::max(longest, line.size());
  }
  EXPECT_LE(longest, 80u) << screen;
  for (char d = '0'; d <= '5'; ++d) EXPECT_NE(screen.find(d), std::string::npos);

  term.type("t");
  EXPECT_TRUE(term.read_until("tip: accepted at t = ", 20)) << term.screen();
  EXPECT_TRUE(
      eventually([&] { return server_->log().find("tip (command 1) from ") != std::string::npos; }, kAnswer))
      << server_->log();
  const std::size_t before_pause = term.screen().size();
  term.type(" ");
  EXPECT_TRUE(term.read_until("pause: accepted at t = ", 20, before_pause)) << term.screen();
  EXPECT_TRUE(term.read_until("PAUSED", 10, before_pause)) << term.screen();
  // Paused, no real-time factor is shown (the last second's measure was of a clock that has since stopped).
  EXPECT_TRUE(term.read_until("  PAUSED  real-time x-  ", 10, before_pause)) << term.screen();
  EXPECT_TRUE(client_->wait_state([](const client::State& st) { return st.paused; }, kAnswer).has_value());
  // The answer is news for 10 s, then the heading says again how to tip from elsewhere (paused, no state comes to
  // redraw the frame: the answer's going does).
  const std::size_t answered = term.screen().size();
  EXPECT_TRUE(term.read_until("from another terminal: ladderctl --sim-id ", 30, answered)) << term.screen();

  term.type("q");
  const auto status = term.wait_exit(20);
  ASSERT_TRUE(status.has_value()) << "q did not end the view\n" << term.screen();
  EXPECT_TRUE(WIFEXITED(*status) && WEXITSTATUS(*status) == 0) << *status;
  // The cursor, hidden while drawing, is shown again after the last frame.
  const std::string& all = term.screen();
  ASSERT_NE(all.rfind("\x1b[?25l"), std::string::npos);
  EXPECT_GT(all.rfind("\x1b[?25h"), all.rfind("\x1b[?25l")) << all.substr(all.size() > 200 ? all.size() - 200 : 0);
}

// A hang-up (a closed SSH session), SIGTERM or Ctrl-C ends the terminal view with status 0 and the cursor shown.
TEST_F(View, TerminalRestoresTheCursorOnEverySignal) {
  for (const int sig : {SIGHUP, SIGTERM, SIGINT}) {
    Pty term({kViewer, "--ascii", "--domain", std::to_string(domain_), "--sim-id", sim_id_, "--timeout", "30"}, 80,
             24);
    ASSERT_TRUE(term.read_until("keys: t tip", 30)) << term.screen();
    kill(term.pid(), sig);
    const auto status = term.wait_exit(20);
    ASSERT_TRUE(status.has_value()) << strsignal(sig) << " did not end the view";
    EXPECT_TRUE(WIFEXITED(*status) && WEXITSTATUS(*status) == 0) << strsignal(sig) << ": status " << *status;
    const std::string& all = term.screen();
    EXPECT_GT(all.rfind("\x1b[?25h"), all.rfind("\x1b[?25l")) << strsignal(sig);
  }
}

// Under `timeout` (which runs the view in a process group of its own, in the terminal's background) the view draws
// without keys, saying how to tip from elsewhere, and ends on timeout's signal: changing the terminal's modes from
// the background had stopped it with SIGTTOU at once, for good, and `timeout` then waited for ever.
TEST_F(View, TerminalUnderTimeoutDrawsWithoutKeysAndEnds) {
  // (Through a shell, the terminal's session leader, as from a prompt: `timeout` then makes its own group.)
  const std::string view = kViewer + " --ascii --domain " + std::to_string(domain_) + " --sim-id " + sim_id_;
  Pty term({"/bin/sh", "-c", "timeout -k 3 60 " + view + " --timeout 30"}, 80, 24);
  ASSERT_TRUE(term.read_until("from another terminal: ladderctl --sim-id ", 30)) << term.screen();
  EXPECT_EQ(term.screen().find("keys: t tip"), std::string::npos);
  // SIGTERM to `timeout` (the shell's child), which passes it on: the view ends, then `timeout`, then the shell.
  const std::string shell = std::to_string(term.pid());
  std::ifstream children("/proc/" + shell + "/task/" + shell + "/children");
  pid_t timeout_pid = 0;
  ASSERT_TRUE(children >> timeout_pid) << "the shell has no child";
  kill(timeout_pid, SIGTERM);
  EXPECT_TRUE(term.wait_exit(20).has_value()) << "the view under timeout did not end";
}

// --at a time the server has already passed: the snapshot is of the state it has, and the viewer says so.
TEST_F(View, PngAtATimeAlreadyPastSaysSo) {
  ASSERT_TRUE(client_->wait_state([](const client::State& st) { return st.sim_time > 0.2; }, Millis(30000)));
  const Result r = viewer("--png " + out_ + ".png --at 0.1");
  ASSERT_EQ(r.code, 0) << r.output;
  std::smatch m;
  ASSERT_TRUE(std::regex_search(r.output, m, std::regex(R"(ladderd '[^']+' was already at t = ([0-9.]+) s, past --at )"
                                                         R"(0\.1 s; the snapshot is of t = ([0-9.]+) s)")))
      << r.output;
  EXPECT_GT(std::stod(m[1]), 0.2);
  EXPECT_EQ(m[1], m[2]);
  // Asked for a time still ahead (the server paused just before it, so that it stays ahead however slowly the viewer
  // starts), it waits, says why, and once resumed draws it, with nothing of the kind said.
  const client::State paused = pause();
  char at[32];
  std::snprintf(at, sizeof at, "%.3f", paused.sim_time + 0.05);
  std::remove((out_ + "-ahead.log").c_str());  // a log of an earlier run would answer the wait below at once
  Process ahead({kViewer, "--domain", std::to_string(domain_), "--sim-id", sim_id_, "--timeout", "30", "--png",
                 out_ + "-ahead.png", "--at", at},
                out_ + "-ahead.log");
  ASSERT_TRUE(eventually([&] { return ahead.log().find("the simulation is paused at t = ") != std::string::npos; },
                         kStart))
      << ahead.log();
  ASSERT_TRUE(client_->call(cmd::resume(), kAnswer).accepted);
  const auto status = ahead.wait_exit(kStart);
  ASSERT_TRUE(status.has_value()) << ahead.log();
  EXPECT_TRUE(WIFEXITED(*status) && WEXITSTATUS(*status) == 0) << ahead.log();
  EXPECT_NE(ahead.log().find("ladder-view: wrote "), std::string::npos) << ahead.log();
  EXPECT_EQ(ahead.log().find("already"), std::string::npos) << ahead.log();
  // Paused short of --at for --timeout on end: code 3 and why, not a wait for ever.
  const client::State still = pause();
  std::snprintf(at, sizeof at, "%.3f", still.sim_time + 100);
  const Result stuck = shell(kViewer + where() + " --timeout 2 --png " + out_ + "-stuck.png --at " + at);
  EXPECT_EQ(stuck.code, 3) << stuck.output;
  EXPECT_NE(stuck.output.find("ladder-view: the simulation stayed paused at t = "), std::string::npos)
      << stuck.output;
  EXPECT_NE(stuck.output.find(" s for 2 s (--timeout), short of --at "), std::string::npos) << stuck.output;
}

// A snapshot that cannot be written says why, exits 1 and leaves no half-written file; but only a file is removed:
// `--png /dev/full` run as root removed the device, and a later write made /dev/full a plain file. (Through a link
// here, so that a viewer that still removed what it had opened would take the link, not the machine's device.)
TEST_F(View, APngThatCannotBeWrittenSaysWhyAndLeavesADeviceInPlace) {
  const std::string link = out_ + "-full.png";
  std::remove(link.c_str());
  ASSERT_EQ(::symlink("/dev/full", link.c_str()), 0) << std::strerror(errno);
  const Result r = viewer("--png " + link);
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("ladder-view: cannot write " + link + ": No space left on device"), std::string::npos)
      << r.output;
  struct stat st {};
  EXPECT_EQ(::lstat(link.c_str(), &st), 0) << "the link was removed";
  EXPECT_TRUE(S_ISLNK(st.st_mode));
  std::remove(link.c_str());
}

TEST_F(View, NoServerGivesTheTimeoutMessageAndCodeThree) {
  const Result r = shell(kViewer + " --domain " + std::to_string(domain_) + " --sim-id nobody-here --timeout 1 --png " +
                         out_ + ".png");
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_NE(r.output.find("no ladderd with sim id 'nobody-here'"), std::string::npos) << r.output;
  EXPECT_EQ(shell(kViewer + " --size 12").code, 2);
  EXPECT_EQ(shell(kViewer + " --at 1").code, 2);  // --at needs --png
  // DDS that will not start (a configuration file that is not there) is a failure with its reason, not an abort.
  const Result no_dds = shell("CYCLONEDDS_URI=file:///no/such/cyclonedds.xml " + kViewer + " --domain " +
                              std::to_string(domain_) + " --ascii --frames 1");
  EXPECT_EQ(no_dds.code, 1) << no_dds.output;
  EXPECT_NE(no_dds.output.find("ladder-view: create DDS participant on domain "), std::string::npos) << no_dds.output;
  EXPECT_NE(no_dds.output.find("CYCLONEDDS_URI"), std::string::npos) << no_dds.output;
  const Result zero = shell(kViewer + " --timeout 0 --png " + out_ + ".png");
  EXPECT_EQ(zero.code, 2) << zero.output;
  EXPECT_NE(zero.output.find("--timeout: must be a number greater than 0, not 0"), std::string::npos) << zero.output;
}

// Options that would hang the viewer or draw nonsense are refused, each with its reason and exit code 2: a timeout
// past a million seconds (1e10 overflowed the deadline and gave up at once), NaN frame rates and sim times (they
// passed the range checks and waited for ever), a view centred on NaN, an empty argument (an unset variable: it was
// taken as "not given", and --security "" ran without DDS Security), a domain that is a word.
TEST_F(View, BadOptionsAreRefusedWithTheirReason) {
  struct Case { std::string args, words; };
  const std::string png = " --png " + out_ + "-bad.png";
  for (const Case& c : {Case{png + " --timeout 1e10", "--timeout: must be at most 1e+06, not 1e10"},
                        Case{" --ascii --fps nan", "--fps: 'nan' is not a number from 0.1 to 100"},
                        Case{png + " --at nan", "--at: 'nan' is not a number from -1e+09 to 1e+09"},
                        Case{png + " --at inf", "--at: 'inf' is not a number from"},
                        Case{png + " --view nan,0,100", "--view: 'nan,0,100' is not a view like"},
                        Case{png + " --view 0,0,1e308", "1e-6 to 1e9 px per m"},
                        Case{png + " --size 16385x16385", "is not a size like 900x700 (1x1 to 16384x16384)"},
                        Case{png + " --security ''", "argument 4 is empty (after '--security')"},
                        Case{" --png ''", "argument 2 is empty (after '--png')"},
                        Case{png + " --security /etc/passwd", "/etc/passwd: a file, not an identity folder"},
                        Case{png + " --domain text", "--domain: 'text' is not a DDS domain id (0 to 231)"},
                        // (CLI11: "--domain: At Most 1 required but received 2")
                        Case{png + " --domain 3 --domain=4", "ladder-view: --domain is given 2 times; give it once\n"},
                        // A sim id no server can have (a heading that was not UTF-8 stopped the window's picture).
                        Case{png + " --sim-id 'a b'", "--sim-id: may hold only letters, digits, '-', '_' and '.'"},
                        Case{png + " --sim-id " + std::string(65, 'a'), "--sim-id: must be 1 to 64 characters"},
                        // A mistyped option: named, with the nearest one (CLI11 had said "The following arguments
                        // were not expected: 230 --domian", without the program's name).
                        Case{png + " --domian 230", "ladder-view: unknown option '--domian' (did you mean '--domain'?)\n"
                                                    "Run with --help"}}) {
    const Result r = shell(kViewer + c.args);
    EXPECT_EQ(r.code, 2) << c.args << "\n" << r.output;
    EXPECT_NE(r.output.find(c.words), std::string::npos) << c.args << "\n" << r.output;
  }
}

// No display: SDL would fall back to its invisible "offscreen" driver and the window would run for ever, unseen, on a
// live server. The viewer says there is no display and exits 1 at once (`timeout` turns a viewer still running after
// 20 s into code 124); asked for by name (SDL_VIDEODRIVER), the offscreen driver is taken.
TEST_F(View, WithoutADisplayTheWindowSaysSoAndExitsOne) {
  const std::string args = " --domain " + std::to_string(domain_) + " --sim-id " + sim_id_ + " --timeout 10";
  const Result r = shell("env -u DISPLAY -u WAYLAND_DISPLAY timeout 20 " + kViewer + args);
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("ladder-view: no display"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("use --png FILE or --ascii"), std::string::npos) << r.output;
  // Nothing before the viewer's own words: SDL tried Wayland after X and libwayland printed "error: XDG_RUNTIME_DIR is
  // invalid or not set in the environment." first.
  EXPECT_EQ(r.output.rfind("ladder-view: no display (DISPLAY and WAYLAND_DISPLAY are not set; ", 0), 0u) << r.output;
  // An X server that does not answer is named as such (display :731: the tests' own Xvfb take :100 to :499).
  const Result gone = shell("env -u WAYLAND_DISPLAY -u XDG_RUNTIME_DIR DISPLAY=:731 timeout 20 " + kViewer + args);
  EXPECT_EQ(gone.code, 1) << gone.output;
  EXPECT_EQ(gone.output.rfind("ladder-view: no display (no X server answers at DISPLAY; ", 0), 0u) << gone.output;
  const Result asked = shell("env -u DISPLAY -u WAYLAND_DISPLAY SDL_VIDEODRIVER=offscreen timeout 3 " + kViewer + args);
  EXPECT_EQ(asked.code, 124) << asked.output;  // still showing the ladder when `timeout` stopped it
  EXPECT_NE(asked.output.find("ladder-view: showing "), std::string::npos) << asked.output;
}

// Another participant publishing a SceneInfo of another generation under the server's sim id, again and again (so
// that it is always the latest the viewer has). The client takes SceneInfo only from its server's participant
// (docs/security.md), so the viewer ignores it and draws the server's ladder within its --timeout. (It used to wait
// for ever; then to give up at --timeout with code 3, the forged SceneInfo being the latest it had; then, under load,
// to miss the server's one SceneInfo, pushed out of the reader's history by the forger's: the reader now keeps
// several and the server writes its SceneInfo again every second, transport/dds.hpp and daemon/io.hpp.)
TEST_F(View, AForgedSceneInfoCannotHoldTheViewerPastItsTimeout) {
  const client::SceneInfo info = *client_->wait_scene_info(kAnswer);
  const transport::Entity participant = transport::make_participant(static_cast<dds_domainid_t>(domain_));
  const transport::Topics topics(participant);
  const transport::Writer<ladder_msg_SceneInfo> scene_w(participant, topics.scene_info, transport::Profile::SceneInfo);
  std::atomic<bool> stop{false};
  std::thread forger([&] {
    ladder_msg_SceneInfo m{};
    transport::copy_text(m.sim_id, sim_id_);
    m.generation = info.generation + 1000;
    m.blocks = info.blocks;
    transport::lend(m.masses, info.masses);
    while (!stop) {
      scene_w.write(m);
      std::this_thread::sleep_for(Millis(5));
    }
  });
  for (const std::string& mode : {"--png " + out_ + ".png", std::string("--ascii --frames 1")}) {
    const auto t0 = std::chrono::steady_clock::now();
    const Result r = shell(kViewer + where() + " --timeout 10 " + mode);
    const double took = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    EXPECT_EQ(r.code, 0) << mode << ": " << r.output;
    EXPECT_NE(r.output.find("6 blocks"), std::string::npos) << mode << ": " << r.output;
    EXPECT_EQ(r.output.find("generation " + std::to_string(info.generation + 1000)), std::string::npos)
        << mode << ": " << r.output;
    EXPECT_LT(took, 20) << mode << " waited " << took << " s with --timeout 10";
  }
  stop = true;
  forger.join();
}

// Cyclone's lines on a client's standard error (client::route_cyclone_log, with transport::LineLimiter, as ladderd's
// log): three in ten seconds, then how many were not shown. A peer whose samples Cyclone cannot decode made it print one a sample, 33 a second.
TEST(ForgedPeer, CyclonesLinesAreLimitedToThreeInTenSecondsAndTheRestCounted) {
  transport::LineLimiter limit(3, std::chrono::seconds(10));
  const Clock::time_point t0 = Clock::now();
  bool shown = false;
  std::vector<bool> seen;
  for (int i = 0; i < 40; ++i) {  // 40 lines in 4 s
    EXPECT_EQ(limit.admit(t0 + Millis(100 * i), shown), 0u);
    seen.push_back(shown);
  }
  EXPECT_EQ(std::count(seen.begin(), seen.end(), true), 3);
  EXPECT_TRUE(seen[0] && seen[1] && seen[2]);
  EXPECT_EQ(limit.admit(t0 + Millis(10'000), shown), 37u);  // the next period: the 37 not shown, and this one shown
  EXPECT_TRUE(shown);
  EXPECT_EQ(limit.admit(t0 + Millis(20'000), shown), 0u);
  EXPECT_TRUE(shown);
}

// With no ladderd on the domain, a peer publishing a State and a SceneInfo under a sim id is taken as its server
// (without DDS Security, anyone can: docs/security.md). Its text comes out printable (an escape sequence, a newline
// and bytes that are not UTF-8 escaped as \xNN: they reached the terminal and, in the window, left cairo unable to
// draw), and a State with a pose that is not a finite number is not taken (the view cast NaN to int).
TEST(ForgedPeer, TextIsMadePrintableAndAStateThatIsNotFiniteIsNotTaken) {
  const std::string name = "ForgedPeer.TextIsMadePrintable";
  const int domain = domain_for(name);
  const std::string id = sim_id_for(name);
  transport::use_default_config(transport::kDefaultCycloneConfig);  // the programs' loopback configuration (below)
  const transport::Entity participant = transport::make_participant(static_cast<dds_domainid_t>(domain));
  const transport::Topics topics(participant);
  const transport::Writer<ladder_msg_State> state_w(participant, topics.state, transport::Profile::State);
  const transport::Writer<ladder_msg_SceneInfo> scene_w(participant, topics.scene_info, transport::Profile::SceneInfo);
  ladder_msg_SceneInfo info{};
  transport::copy_text(info.sim_id, id);
  info.generation = 7;
  transport::copy_text(info.scene_name, "\x1b[2Jevil\nforged \xff\xfe\xc3( caf\xc3\xa9 \xc2\x9b");
  transport::copy_text(info.options, "sim.dt=0.001\nbad=\x1b]0;title\x07\n");
  info.blocks = 2;
  info.length = 0.064;
  info.thickness = 0.013;
  const std::vector<double> masses(100, 0.025);  // not one a block: not kept
  transport::lend(info.masses, masses);
  std::vector<double> poses{0, 0, 0, 0, -0.066, 0};
  const std::vector<std::uint8_t> corner{0, 0};
  const std::vector<ladder_msg_HingeStatus> status{ladder_msg_HINGED, ladder_msg_HINGED};
  const std::vector<std::uint32_t> flips{0, 0};
  ladder_msg_State st{};
  transport::copy_text(st.sim_id, id);
  st.generation = 7;
  st.seq = 1;
  transport::lend_blocks(st, poses, corner, status, flips);
  scene_w.write(info);
  state_w.write(st);

  Client c(domain, id, "forged-peer-test");
  ASSERT_TRUE(eventually([&] { return c.poll(), c.latest_state() && c.scene_info(); }, kStart));
  EXPECT_EQ(c.scene_info()->scene_name, "\\x1b[2Jevil\\x0aforged \\xff\\xfe\\xc3( caf\xc3\xa9 \\xc2\\x9b");
  EXPECT_EQ(c.scene_info()->options, "sim.dt=0.001\nbad=\\x1b]0;title\\x07\n");
  EXPECT_TRUE(c.scene_info()->masses.empty());
  EXPECT_EQ(c.latest_state()->seq, 1u);

  poses[4] = NAN;
  st.seq = 2;
  transport::lend_blocks(st, poses, corner, status, flips);
  state_w.write(st);
  ASSERT_TRUE(eventually([&] { return c.poll(), c.states_malformed() > 0; }, kStart));
  EXPECT_EQ(c.latest_state()->seq, 1u);  // the last finite one
  poses[4] = -0.066;
  st.seq = 3;
  transport::lend_blocks(st, poses, corner, status, flips);
  state_w.write(st);
  EXPECT_TRUE(eventually([&] { return c.poll(), c.latest_state()->seq == 3; }, kStart));

  // The other numbers of a State: an energy that is not finite (the plot took it for no state), a sim time of
  // -1e300 (the summary lines printed 300 digits, cut), a grip's target that is not finite.
  const std::vector<ladder_msg_Grip> grip{ladder_msg_Grip{.block = 1, .target_x = NAN, .target_y = 0, .hold_angle = false, .angle = 0}};
  const auto refused = [&](std::uint64_t seq, auto&& spoil) {
    ladder_msg_State bad = st;
    bad.seq = seq;
    transport::lend_blocks(bad, poses, corner, status, flips);
    spoil(bad);
    const std::uint64_t before = c.states_malformed();
    state_w.write(bad);
    EXPECT_TRUE(eventually([&] { return c.poll(), c.states_malformed() == before + 1; }, kStart)) << "seq " << seq;
    EXPECT_EQ(c.latest_state()->seq, 3u) << "seq " << seq;
  };
  refused(4, [](ladder_msg_State& m) { m.energy = NAN; });
  refused(5, [](ladder_msg_State& m) { m.sim_time = -1e300; });
  refused(6, [](ladder_msg_State& m) { m.sim_time = INFINITY; });
  refused(7, [&](ladder_msg_State& m) { transport::lend(m.grips, grip); });
  st.seq = 8;
  st.sim_time = 1e300;  // finite and not negative: taken (the texts print it in %g beyond 1e9 s)
  st.energy = 1.7e308;
  transport::lend_blocks(st, poses, corner, status, flips);
  state_w.write(st);
  EXPECT_TRUE(eventually([&] { return c.poll(), c.latest_state()->seq == 8; }, kStart));

  // With a server's command reader and ack and event writers, ladderctl takes the peer for its server: `status`
  // prints the huge figures in %g (it printed them with %f, 300 digits each) and the 0.1 mm thick blocks as such
  // (they were "64 x 0 mm").
  info.thickness = 1e-4;
  scene_w.write(info);
  const transport::Reader<ladder_msg_Command> command_r(participant, topics.command, transport::Profile::Command);
  const transport::Writer<ladder_msg_CommandAck> ack_w(participant, topics.ack, transport::Profile::CommandAck);
  const transport::Writer<ladder_msg_Event> event_w(participant, topics.event, transport::Profile::Event);
  const Result r = shell(kBin + "/clients/ladderctl status --domain " + std::to_string(domain) + " --sim-id " + id);
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("2 blocks of 64 x 0.1 mm"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("sim time 1e+300 s, step 0, running, energy 1.7e+308 J\n"), std::string::npos) << r.output;
}

// An X server of our own for the window; the screen is an XWD file we can read at any time.
class Xvfb {
 public:
  explicit Xvfb(const std::string& dir) : display_(display_name()), dir_(dir) {
    mkdir(dir.c_str(), 0755);
    process_.emplace(std::vector<std::string>{"/usr/bin/Xvfb", display_, "-screen", "0", "1024x768x24", "-fbdir", dir,
                                              "-nolisten", "tcp"},
                     dir + "/xvfb.log");
  }
  // Killed with the test, Xvfb leaves its lock and socket behind: removed, so that the number can be used again.
  ~Xvfb() {
    process_.reset();
    std::remove(socket_path(display_).c_str());
    std::remove(lock_path(display_).c_str());
  }
  Xvfb(const Xvfb&) = delete;
  Xvfb& operator=(const Xvfb&) = delete;
  // The socket appears when the server listens (display_name() picked a number that had none).
  bool ready() const {
    struct stat st {};
    return stat(socket_path(display_).c_str(), &st) == 0;
  }
  const std::string& display() const { return display_; }
  // A free display number, searched from one given by the pid so that two tests at once do not meet. A number whose
  // socket or lock is still there (left by a killed server) is passed over: with a stale socket ready() would say
  // yes before the new server listened, and the viewer could not open its window (a flaky failure, seen).
  static std::string display_name() {
    char name[16];
    for (int i = 0; i < 400; ++i) {
      std::snprintf(name, sizeof name, ":%d", 100 + (getpid() + i) % 400);
      struct stat st {};
      if (stat(socket_path(name).c_str(), &st) != 0 && stat(lock_path(name).c_str(), &st) != 0) return name;
    }
    std::snprintf(name, sizeof name, ":%d", 100 + getpid() % 400);
    return name;
  }
  static std::string socket_path(const std::string& display) { return "/tmp/.X11-unix/X" + display.substr(1); }
  static std::string lock_path(const std::string& display) { return "/tmp/.X" + display.substr(1) + "-lock"; }
  Image screen() const { return read_xwd(dir_ + "/Xvfb_screen0"); }
  std::string log() const { return process_->log(); }

 private:
  std::string display_, dir_;
  std::optional<Process> process_;
};

// Where the window of this title is on the screen (xdotool, once it is mapped), or nothing within kStart.
std::optional<Point> window_origin(const Xvfb& x, const std::string& title) {
  Result geometry;
  const bool found = eventually(
      [&] {
        geometry = shell("DISPLAY=" + x.display() + " xdotool search --name '" + title + "' getwindowgeometry --shell");
        return geometry.code == 0 && geometry.output.find("X=") != std::string::npos;
      },
      kStart);
  std::smatch m;
  if (!found || !std::regex_search(geometry.output, m, std::regex(R"(X=(-?\d+)\s+Y=(-?\d+))"))) return std::nullopt;
  return Point{std::stod(m[1]), std::stod(m[2])};
}

TEST_F(View, WindowUnderXvfbShowsTheLadderClicksPokeAndItOutlivesTheServer) {
  const client::State s = pause();  // a still picture
  Xvfb x(out_ + "-x");
  ASSERT_TRUE(eventually([&] { return x.ready(); }, kStart)) << x.log();
  Process viewer({"/usr/bin/env", "DISPLAY=" + x.display(), kViewer, "--domain", std::to_string(domain_), "--sim-id",
                  sim_id_, "--size", "640x600"},
                 out_ + "-viewer.log");
  std::optional<Camera> cam;
  ASSERT_TRUE(eventually([&] { return (cam = camera_in(viewer.log(), 640, 600)).has_value(); }, kStart))
      << viewer.log();
  // Where the window is on the screen.
  const std::string xdo = "DISPLAY=" + x.display() + " xdotool ";
  const auto where = window_origin(x, "ladder-view: " + sim_id_);
  ASSERT_TRUE(where) << "no window 'ladder-view: " << sim_id_ << "' on the screen; the viewer's log:\n" << viewer.log();
  const Point origin = *where;

  // The screenshot shows each block's wide face where the state has it (once the window has painted), and its tapes.
  const client::SceneInfo info = *client_->scene_info();
  const auto shows_ladder = [&] {
    const Image img = x.screen();
    for (std::size_t i = 0; i < s.blocks.size(); ++i) {
      const Point p = on_wide_face(*cam, info, s.blocks[i], i == 0 ? -0.35 : 0, -0.16);
      if (distance(img.at({p.x + origin.x, p.y + origin.y}), view::face_colour(int(i))) >= 12) return false;
    }
    return true;
  };
  if (!eventually(shows_ladder, kStart)) {
    write_png(x.screen(), out_ + "-screen.png");
    const auto exited = viewer.wait_exit(Millis(0));
    FAIL() << "the screen does not show the ladder (window at " << origin.x << ", " << origin.y << "; see " << out_
           << "-screen.png); the viewer " << (exited ? "has exited, status " + std::to_string(*exited) : "runs")
           << "; its log:\n" << viewer.log() << "\nXvfb's log:\n" << x.log();
  }
  expect_blocks_at_centres(x.screen(), *cam, info, s, origin);
  EXPECT_EQ(tapes_seen(x.screen(), *cam, info, s, origin), "ocococ");
  EXPECT_FALSE(cam->side());

  // A click on block 3's face in the 3-D view pokes it: the viewer reports the server's acceptance, the server
  // counts it and logs it.
  const Point p = on_wide_face(*cam, info, s.blocks[3], 0.1, -0.16);
  const Result click = shell(xdo + "mousemove --sync " + std::to_string(int(p.x + origin.x)) + " " +
                             std::to_string(int(p.y + origin.y)) + " click 1");
  ASSERT_EQ(click.code, 0) << click.output;
  EXPECT_TRUE(eventually([&] { return viewer.log().find("poke block 3: accepted") != std::string::npos; }, kStart))
      << viewer.log();
  const auto stats = client_->wait_stats([](const ladder_msg_Stats& st) { return st.commands_accepted >= 2; },
                                         Millis(10000));
  EXPECT_TRUE(stats) << "the server did not count the poke (pause + poke = 2 accepted)";
  EXPECT_TRUE(
      eventually([&] { return server_->log().find("poke (command 1) from ") != std::string::npos; }, kAnswer))
      << server_->log();

  // The window's title names the scene.
  const Result name = shell(xdo + "search --name 'ladder-view: " + sim_id_ + "' getwindowname");
  EXPECT_NE(name.output.find("ladder-view: " + sim_id_ + "  '" + info.scene_name + "'"), std::string::npos)
      << name.output;

  // The plots on (key p), the server stops: the viewer says it waits, and its banner is drawn over the plots. The
  // banner's line, centred at mid-height, runs into the plots' upper frame (lower right, from x = 0.64 w + 60):
  // there its letters are bright, where the plots' fill drawn over them had dimmed them to a third.
  ASSERT_EQ(shell(xdo + "key p").code, 0);
  const auto banner_over_plots = [&] {
    const Image img = x.screen();
    int bright = 0;
    for (int py = 296; py <= 308; ++py)
      for (int px = 480; px <= 575; ++px)
        bright += distance(img.at({px + origin.x, py + origin.y}), view::kText) < 60 ? 1 : 0;
    return bright >= 20;
  };
  EXPECT_FALSE(banner_over_plots()) << "bright pixels in the plots' frame before there is a banner";
  // The server stops: the viewer says it waits; a new server comes: the viewer shows it and its clicks work again.
  const auto count = [&](const std::string& words) {
    const std::string log = viewer.log();
    int n = 0;
    for (std::size_t at = log.find(words); at != std::string::npos; at = log.find(words, at + 1)) ++n;
    return n;
  };
  server_->signal(SIGTERM);
  ASSERT_TRUE(server_->wait_exit(kStart));
  EXPECT_TRUE(eventually([&] { return count("is not answering; waiting for it") == 1; }, kStart)) << viewer.log();
  if (!eventually(banner_over_plots, kAnswer)) {
    write_png(x.screen(), out_ + "-banner.png");
    ADD_FAILURE() << "the banner is not over the plots: see " << out_ << "-banner.png";
  }
  ASSERT_EQ(shell(xdo + "key p").code, 0);  // the plots off again: the ladder's pixels are checked below
  server_.emplace(std::vector<std::string>{kBin + "/server/ladderd", "--domain", std::to_string(domain_), "--sim-id",
                                           sim_id_, "--log-level", "debug"},
                  log_path_ + ".2");
  ASSERT_TRUE(eventually([&] { return count("answers again") == 1; }, kStart)) << viewer.log();
  ASSERT_EQ(shell(xdo + "click 1").code, 0);  // the pointer is still on block 3, which hangs where it did
  EXPECT_TRUE(eventually([&] { return count("poke block 3: accepted") == 2; }, kStart)) << viewer.log();
  viewer.signal(SIGTERM);
  EXPECT_TRUE(viewer.wait_exit(kStart).has_value());
}

// The overlay (key o) at the default window size stays clear of the hand that holds the top block: its lines were up to
// 60 characters long and it covered the fingers (darkened to under half their brightness). Its text lines are at most
// kOverlayColumns characters, a long answer wrapped.
TEST_F(View, TheOverlayAtTheDefaultSizeLeavesTheHandInSight) {
  const client::State s = pause();
  Xvfb x(out_ + "-x");
  ASSERT_TRUE(eventually([&] { return x.ready(); }, kStart)) << x.log();
  Process viewer({"/usr/bin/env", "DISPLAY=" + x.display(), kViewer, "--domain", std::to_string(domain_), "--sim-id",
                  sim_id_},
                 out_ + "-viewer.log");
  std::optional<Camera> cam;
  ASSERT_TRUE(eventually([&] { return (cam = camera_in(viewer.log(), 900, 700)).has_value(); }, kStart))
      << viewer.log();
  const auto where = window_origin(x, "ladder-view: " + sim_id_);
  ASSERT_TRUE(where) << viewer.log();
  const client::SceneInfo info = *client_->scene_info();
  const Point hand = cam->project(view::hand_centre(info, s.blocks[0]));
  const auto bright_hand = [&] {
    const Rgb c = x.screen().at({hand.x + where->x, hand.y + where->y});
    return is_hand(c) && c.r + c.g + c.b > 300;  // the hand's colours lit or shaded (339 and up), not under a box
  };
  ASSERT_TRUE(eventually(bright_hand, kStart)) << "no hand at " << hand.x << ", " << hand.y;
  // The overlay on, once the server's statistics (its longest lines) have come: drawn (its box's left margin at x = 8
  // is darker than the background), the hand still bright.
  ASSERT_TRUE(client_->wait_stats([](const ladder_msg_Stats&) { return true; }, kStart));
  std::this_thread::sleep_for(Millis(300));
  const std::string xdo = "DISPLAY=" + x.display() + " xdotool ";
  ASSERT_EQ(shell(xdo + "mousemove --sync " + std::to_string(int(where->x + 450)) + " " +
                  std::to_string(int(where->y + 690)) + " key o").code, 0);
  const auto overlay = [&] {
    const Rgb c = x.screen().at({8 + where->x, 120 + where->y});
    return distance(c, view::kBackground) > 15 && c.r + c.g + c.b < 60;
  };
  EXPECT_TRUE(eventually(overlay, kStart)) << "the overlay was not drawn";
  EXPECT_TRUE(bright_hand()) << "the overlay covers the hand at " << hand.x << ", " << hand.y;
  viewer.signal(SIGTERM);
  EXPECT_TRUE(viewer.wait_exit(kStart).has_value());
}

// Key f on a ladder framed small (blocks 14 px long here, as tall.toml's 64 blocks in the default window): the view
// zooms in about its centre until a block is 40 px long, and follows the ripple; f again stops, keeping the zoom.
TEST_F(View, FollowingTheRippleZoomsASmallLadderIn) {
  pause();
  Xvfb x(out_ + "-x");
  ASSERT_TRUE(eventually([&] { return x.ready(); }, kStart)) << x.log();
  Process viewer({"/usr/bin/env", "DISPLAY=" + x.display(), kViewer, "--domain", std::to_string(domain_), "--sim-id",
                  sim_id_, "--size", "160x120"},
                 out_ + "-viewer.log");
  std::optional<Camera> cam;
  ASSERT_TRUE(eventually([&] { return (cam = camera_in(viewer.log(), 160, 120)).has_value(); }, kStart))
      << viewer.log();
  const client::SceneInfo info = *client_->scene_info();
  ASSERT_LT(cam->scale * info.length, 20) << viewer.log();
  const auto where = window_origin(x, "ladder-view: " + sim_id_);
  ASSERT_TRUE(where) << viewer.log();
  const std::string xdo = "DISPLAY=" + x.display() + " xdotool ";
  const auto after = [&](const std::string& words) -> std::optional<Camera> {
    const std::string log = viewer.log();
    const std::size_t at = log.find(words);
    return at == std::string::npos ? std::nullopt : camera_in(log.substr(at), 160, 120);
  };
  // (Not the window's centre: that is the screen's, where the pointer starts, and --sync would wait for a motion.)
  ASSERT_EQ(shell(xdo + "mousemove --sync " + std::to_string(int(where->x + 40)) + " " +
                  std::to_string(int(where->y + 30)) + " key f").code, 0);
  std::optional<Camera> following;
  ASSERT_TRUE(eventually([&] { return (following = after("following the ripple;")).has_value(); }, kStart))
      << viewer.log();
  EXPECT_NEAR(following->scale * info.length, 40, 1e-6) << viewer.log();
  EXPECT_NEAR(following->cx, cam->cx, 1e-9);  // zoomed about the centre
  EXPECT_NEAR(following->cy, cam->cy, 1e-9);
  ASSERT_EQ(shell(xdo + "key f").code, 0);
  std::optional<Camera> stopped;
  ASSERT_TRUE(eventually([&] { return (stopped = after("no longer following the ripple;")).has_value(); }, kStart))
      << viewer.log();
  EXPECT_NEAR(stopped->scale, following->scale, 1e-9 * following->scale);
  viewer.signal(SIGTERM);
  EXPECT_TRUE(viewer.wait_exit(kStart).has_value());
}

TEST(Draw, OverlayLinesAreWrappedToItsWidth) {
  client::SceneInfo info = classic_info(100000);
  info.scene_name = "Classic Jacob's ladder, with every setting written out in its name";
  info.top = "held";
  info.dt = 1e-3;
  ladder_msg_Stats st{};
  st.step_p50_us = 123.4;
  st.step_p99_us = 5678.9;
  st.missed_deadlines = 123456789;
  st.solver_iterations = 30;
  st.solver_residual = 9.9e-13;
  st.max_hinge_error = 1.2e-12;
  st.energy = -1234.567891;
  st.commands_accepted = 1000000;
  st.commands_refused = 1000000;
  for (const std::string& l : view::stats_lines(info, st))
    EXPECT_LE(l.size(), view::kOverlayColumns) << l;
  using L = std::vector<std::string>;
  EXPECT_EQ(view::wrap("tip: accepted at t = 1.234 s", 38), L{"tip: accepted at t = 1.234 s"});
  EXPECT_EQ(view::wrap("poke block 9: refused: no block 9 (the ladder has blocks 0 to 5)", 38),
            (L{"poke block 9: refused: no block 9 (the", "ladder has blocks 0 to 5)"}));
  EXPECT_EQ(view::wrap("load: refused: /a/very/long/path/to/a/scene/file.toml:3:7", 20),
            (L{"load: refused:", "/a/very/long/path/to", "/a/scene/file.toml:3", ":7"}));
  EXPECT_EQ(view::wrap("ЖЖЖ ЖЖЖ", 3), (L{"ЖЖЖ", "ЖЖЖ"}));  // characters, not bytes
  EXPECT_EQ(view::wrap("", 38), L{""});
  EXPECT_EQ(view::wrap("ab c", 0), (L{"a", "b", "c"}));  // (no width: a character a line, not a loop for ever)
}

// Two ladders on the domain: Tab in the window switches to the other one (found by DDS discovery), which is then
// framed and shown, and a click pokes that ladder's block.
TEST_F(View, WindowSwitchesToTheOtherLadderOfTheDomainWithTab) {
  // Logs of an earlier run would answer the waits below at once.
  for (const std::string& log : {log_path_ + ".second", out_ + "-viewer.log"}) std::remove(log.c_str());
  Process second({kBin + "/server/ladderd", "--domain", std::to_string(domain_), "--sim-id", sim_id_ + "-2",
                  "--set", "ladder.blocks=3", "--log-level", "debug"},
                 log_path_ + ".second");
  Client other(domain_, sim_id_ + "-2", "test");
  ASSERT_TRUE(other.wait_for_server(kStart)) << second.log();
  const client::Ack paused = other.call(cmd::pause(), kAnswer);
  ASSERT_TRUE(paused.accepted);
  const auto s2 = other.wait_state([&](const client::State& st) { return st.commands_applied >= paused.command_seq; },
                                   kAnswer);
  ASSERT_TRUE(s2 && s2->paused);
  Xvfb x(out_ + "-x");
  ASSERT_TRUE(eventually([&] { return x.ready(); }, kStart)) << x.log();
  Process viewer({"/usr/bin/env", "DISPLAY=" + x.display(), kViewer, "--domain", std::to_string(domain_), "--sim-id",
                  sim_id_, "--size", "640x600"},
                 out_ + "-viewer.log");
  ASSERT_TRUE(eventually([&] { return viewer.log().find("(6 blocks)") != std::string::npos; }, kStart))
      << viewer.log();
  const std::string xdo = "DISPLAY=" + x.display() + " xdotool ";
  const auto where = window_origin(x, "ladder-view: " + sim_id_);
  ASSERT_TRUE(where) << "no window 'ladder-view: " << sim_id_ << "' on the screen; the viewer's log:\n" << viewer.log();
  const Point origin = *where;
  // Keys go to the window under the pointer (no window manager).
  const std::string corner = std::to_string(int(origin.x) + 5) + " " + std::to_string(int(origin.y) + 5);
  ASSERT_EQ(shell(xdo + "mousemove --sync " + corner + " key Tab").code, 0);
  ASSERT_TRUE(eventually([&] { return viewer.log().find("switched to sim id '" + sim_id_ + "-2' (2 ladders") !=
                                      std::string::npos; },
                         kStart))
      << viewer.log();
  const std::size_t at = viewer.log().find("switched to");
  std::optional<Camera> cam;
  ASSERT_TRUE(eventually([&] { return (cam = camera_in(viewer.log().substr(at), 640, 600)).has_value(); }, kStart))
      << viewer.log();
  EXPECT_NE(viewer.log().find("(3 blocks)", at), std::string::npos) << viewer.log();
  const client::SceneInfo info = *other.scene_info();
  const Point p = on_wide_face(*cam, info, s2->blocks[2], 0.1, -0.16);
  // The picture shows the other ladder: its block 2's face where its state has it; a click there pokes it.
  const auto shows_it = [&] {
    return distance(x.screen().at({p.x + origin.x, p.y + origin.y}), view::face_colour(2)) < 12;
  };
  ASSERT_TRUE(eventually(shows_it, kStart)) << viewer.log();
  ASSERT_EQ(shell(xdo + "mousemove --sync " + std::to_string(int(p.x + origin.x)) + " " +
                  std::to_string(int(p.y + origin.y)) + " click 1").code,
            0);
  EXPECT_TRUE(eventually([&] { return viewer.log().find("poke block 2: accepted") != std::string::npos; }, kStart))
      << viewer.log();
  EXPECT_TRUE(
      eventually([&] { return second.log().find("poke (command 1) from ") != std::string::npos; }, kAnswer))
      << second.log();
  EXPECT_EQ(server_->log().find("poke (command 1) from "), std::string::npos) << "the first ladder was poked";
  viewer.signal(SIGTERM);
  EXPECT_TRUE(viewer.wait_exit(kStart).has_value());
}

// A State that comes before its SceneInfo (the two topics arrive independently: a late joiner or a reset can see the
// State first) is not drawn yet and does not stop the window: once the SceneInfo comes, the ladder is shown. The
// publisher here is the test's own, under a sim id of its own, sending the real server's State and SceneInfo. The
// window used to take the State as drawable and read its missing SceneInfo: a crash (SIGSEGV), rarely, in the test
// above, and every time here.
TEST_F(View, WindowWaitsForTheSceneInfoOfAStateThatCameFirst) {
  const client::State s = pause();
  const client::SceneInfo info = *client_->scene_info();
  const std::string id = "early-state-" + std::to_string(getpid());
  const transport::Entity participant = transport::make_participant(static_cast<dds_domainid_t>(domain_));
  const transport::Topics topics(participant);
  const transport::Writer<ladder_msg_State> state_w(participant, topics.state, transport::Profile::State);
  const transport::Writer<ladder_msg_SceneInfo> scene_w(participant, topics.scene_info, transport::Profile::SceneInfo);
  std::vector<double> poses;
  std::vector<std::uint8_t> corner;
  std::vector<ladder_msg_HingeStatus> status;
  std::vector<std::uint32_t> flips;
  for (std::size_t i = 0; i < s.blocks.size(); ++i) {
    poses.insert(poses.end(), {s.blocks[i].x, s.blocks[i].y, s.blocks[i].theta});
    corner.push_back(static_cast<std::uint8_t>(s.hinges[i].corner));
    status.push_back(static_cast<ladder_msg_HingeStatus>(s.hinges[i].status));
    flips.push_back(s.hinges[i].flips);
  }
  ladder_msg_State st{};
  transport::copy_text(st.sim_id, id);
  st.generation = info.generation;
  st.seq = 1;
  st.sim_time = s.sim_time;
  st.paused = true;
  transport::lend_blocks(st, poses, corner, status, flips);
  state_w.write(st);

  Xvfb x(out_ + "-x");
  ASSERT_TRUE(eventually([&] { return x.ready(); }, kStart)) << x.log();
  Process viewer({"/usr/bin/env", "DISPLAY=" + x.display(), kViewer, "--domain", std::to_string(domain_), "--sim-id",
                  id, "--size", "640x600"},
                 out_ + "-viewer.log");
  // The State reaches the viewer within its discovery (well under a second here); the window must wait it out.
  const auto early = viewer.wait_exit(Millis(3000));
  ASSERT_FALSE(early.has_value()) << "the viewer ended (status " << *early << ") on a State without its SceneInfo; "
                                  << "its log:\n" << viewer.log();
  EXPECT_EQ(viewer.log().find("view centre"), std::string::npos) << viewer.log();

  ladder_msg_SceneInfo m{};
  transport::copy_text(m.sim_id, id);
  m.generation = info.generation;
  transport::copy_text(m.scene_name, info.scene_name);
  transport::copy_text(m.top, info.top);
  m.blocks = info.blocks;
  m.length = info.length;
  m.thickness = info.thickness;
  m.hinge_inset = info.hinge_inset;
  transport::lend(m.masses, info.masses);
  m.dt = info.dt;
  m.physics_rate = info.physics_rate;
  m.publish_rate = info.publish_rate;
  m.real_time_factor = info.real_time_factor;
  scene_w.write(m);
  std::optional<Camera> cam;
  EXPECT_TRUE(eventually([&] { return (cam = camera_in(viewer.log(), 640, 600)).has_value(); }, kStart))
      << viewer.log();
  EXPECT_NE(viewer.log().find("showing '" + info.scene_name + "' (6 blocks)"), std::string::npos) << viewer.log();
  EXPECT_FALSE(viewer.wait_exit(Millis(500)).has_value()) << viewer.log();
  viewer.signal(SIGTERM);
  EXPECT_TRUE(viewer.wait_exit(kStart).has_value());
}

// ---------------------------------------------------------------------------------------------------------------
// Rolling hinges: a real ladderd whose blocks have fully rounded ends (the classic toy with ladder.hinge = "rolling"
// and ladder.end_radius = thickness / 2, which hangs in a straight column).

class RollingView : public View {
 protected:
  std::vector<std::string> scene_args() const override {
    return {"--set", "ladder.hinge=rolling", "--set", "ladder.end_radius=0.0065"};
  }
};

// Snapshots of the paused ladder. The 3-D view: every block's face and its tapes where the state puts them, as for
// corner hinges. Zoomed on hinge 3 in the side view: the four arcs of the two ends that meet there are where the
// state and the radius put them (background 3 px outside, the block 4 px inside), the tapes run over every one of
// them and the hinge's dot is at the contact (halfway between the arc centres), where they cross. Zoomed on the
// bottom block's free end in 3-D: its narrow side's corner is cut off. Then the window under Xvfb: the screenshot
// shows the ladder, and a click inside block 3's rounded end pokes block 3.
TEST_F(RollingView, PngAndWindowShowRoundedEndsAndTheTapesCrossingAtEachContact) {
  const client::State s = pause();
  const client::SceneInfo info = *client_->scene_info();
  ASSERT_NE(info.options.find("ladder.hinge=rolling\n"), std::string::npos) << info.options;
  ASSERT_NE(info.options.find("ladder.end_radius=0.0065\n"), std::string::npos) << info.options;
  Rolling g;
  g.length = info.length;
  g.thickness = info.thickness;
  g.r = 0.0065;
  const double d = view::depth_of(info);
  const auto view_arg = [](Point c, double scale, double yaw, double pitch) {
    char buf[160];
    std::snprintf(buf, sizeof buf, " --view %.17g,%.17g,%.17g,%.17g,%.17g", c.x, c.y, scale, yaw, pitch);
    return std::string(buf);
  };

  const Result a = viewer("--png " + out_ + "-3d.png --size 500x700");
  ASSERT_EQ(a.code, 0) << a.output;
  const auto cam = camera_in(a.output, 500, 700);
  ASSERT_TRUE(cam) << a.output;
  const Image img = read_png(out_ + "-3d.png");
  expect_blocks_at_centres(img, *cam, info, s);
  EXPECT_EQ(tapes_seen(img, *cam, info, s), "ocococ");

  // Hinge 3, between blocks 2 and 3, in the side view at 12 000 px/m (the radius is 78 px).
  const int c = s.hinges[3].corner;
  const Point a2 = Rolling::world(s.blocks[2], g.corner_centre(2, c)), a3 = Rolling::world(s.blocks[3], g.corner_centre(3, c));
  const Point contact{0.5 * (a2.x + a3.x), 0.5 * (a2.y + a3.y)};
  const double scale = 12000, px = 1 / scale;
  const Result b = viewer("--png " + out_ + "-side.png --size 600x600" + view_arg(contact, scale, 0, 0));
  ASSERT_EQ(b.code, 0) << b.output;
  const auto side = camera_in(b.output, 600, 600);
  ASSERT_TRUE(side) << b.output;
  const Image sv = read_png(out_ + "-side.png");
  const auto at = [&](int block, Point local) { return sv.at(side->to_screen(Rolling::world(s.blocks[block], local))); };
  EXPECT_LT(distance(sv.at(side->to_screen(contact)), view::kHinge), 12) << "no hinge dot at the contact";
  for (const int block : {2, 3})
    for (const int sx : {-1, 1}) {
      const int sy = Rolling::end(block, c);
      for (const double deg : {15.0, 45.0, 75.0}) {
        const double angle = deg * M_PI / 180;
        const Rgb in = at(block, g.on_arc(sx, sy, angle, -4 * px)), tape = at(block, g.on_arc(sx, sy, angle));
        EXPECT_LT(distance(in, view::side_colour(block)), 12) << "block " << block << " arc (" << sx << ", " << sy
                                                               << ") at " << deg << " deg, 4 px in: rgb " << in.r
                                                               << "," << in.g << "," << in.b;
        EXPECT_TRUE(is_ribbon(tape)) << "block " << block << " arc (" << sx << ", " << sy << ") at " << deg
                                     << " deg: no tape; rgb " << tape.r << "," << tape.g << "," << tape.b;
        if (deg == 75.0) continue;  // near the tip the other block's arc and its tape are close
        const Rgb out = at(block, g.on_arc(sx, sy, angle, 3 * px));
        EXPECT_EQ(distance(out, view::kBackground), 0) << "block " << block << " arc (" << sx << ", " << sy << ") at "
                                                       << deg << " deg, 3 px out: rgb " << out.r << "," << out.g << ","
                                                       << out.b;
      }
    }

  // The bottom block's free end, in 3-D: the box's corner on its front narrow side (12 % of the radius in from both
  // edges) is background; inside the arc, the narrow side.
  const client::Pose& last = s.blocks[5];
  const double hw = 0.5 * g.thickness, hl = 0.5 * g.length;
  const Point end = Rolling::world(last, {0, -hl});
  const Result e = viewer("--png " + out_ + "-end.png --size 500x500" +
                          view_arg(end, 8000, view::kDefaultYaw * 180 / M_PI, view::kDefaultPitch * 180 / M_PI));
  ASSERT_EQ(e.code, 0) << e.output;
  const auto ecam = camera_in(e.output, 500, 500);
  ASSERT_TRUE(ecam) << e.output;
  const Image ev = read_png(out_ + "-end.png");
  const auto at3 = [&](Point local, double z) {
    const Point w = Rolling::world(last, local);
    return ev.at(ecam->project({w.x, w.y, z}));
  };
  const double inset = 0.12 * g.r;
  for (const int sx : {-1, 1}) {
    const Rgb cut = at3({sx * (hw - inset), -hl + inset}, 0.5 * d);
    EXPECT_EQ(distance(cut, view::kBackground), 0) << "corner " << sx << ": rgb " << cut.r << "," << cut.g << "," << cut.b;
  }
  EXPECT_LT(distance(at3(g.on_arc(-1, -1, M_PI / 4, -0.3 * g.r), 0.5 * d), view::side_colour(5)), 12);

  // The window: the picture, and a click inside block 3's rounded low end (on its front narrow side, halfway
  // between the arc's centre and its tip) pokes block 3.
  Xvfb x(out_ + "-x");
  ASSERT_TRUE(eventually([&] { return x.ready(); }, kStart)) << x.log();
  Process window({"/usr/bin/env", "DISPLAY=" + x.display(), kViewer, "--domain", std::to_string(domain_), "--sim-id",
                  sim_id_, "--size", "640x600"},
                 out_ + "-viewer.log");
  std::optional<Camera> wcam;
  ASSERT_TRUE(eventually([&] { return (wcam = camera_in(window.log(), 640, 600)).has_value(); }, kStart))
      << window.log();
  const auto where = window_origin(x, "ladder-view: " + sim_id_);
  ASSERT_TRUE(where) << window.log();
  const auto shows_ladder = [&] {
    const Image screen = x.screen();
    for (std::size_t i = 0; i < s.blocks.size(); ++i) {
      const Point p = on_wide_face(*wcam, info, s.blocks[i], i == 0 ? -0.35 : 0, -0.16);
      if (distance(screen.at({p.x + where->x, p.y + where->y}), view::face_colour(int(i))) >= 12) return false;
    }
    return true;
  };
  if (!eventually(shows_ladder, kStart)) {
    write_png(x.screen(), out_ + "-screen.png");
    FAIL() << "the screen does not show the ladder; see " << out_ << "-screen.png; the viewer's log:\n" << window.log();
  }
  write_png(x.screen(), out_ + "-screen.png");
  const Point q = Rolling::world(s.blocks[3], g.corner_centre(3, s.hinges[4].corner));
  const Point click = wcam->project({q.x + 0.5 * g.r * std::sin(s.blocks[3].theta),
                                     q.y - 0.5 * g.r * std::cos(s.blocks[3].theta), 0.5 * d});
  EXPECT_EQ(view::pick(*wcam, info, s, click).block, 3);
  ASSERT_EQ(shell("DISPLAY=" + x.display() + " xdotool mousemove --sync " + std::to_string(int(click.x + where->x)) +
                  " " + std::to_string(int(click.y + where->y)) + " click 1")
                .code,
            0);
  EXPECT_TRUE(eventually([&] { return window.log().find("poke block 3: accepted") != std::string::npos; }, kStart))
      << window.log();
  window.signal(SIGTERM);
  EXPECT_TRUE(window.wait_exit(kStart).has_value());
}

// ---------------------------------------------------------------------------------------------------------------
// A remote viewer: ladderd in one network namespace, ladder-view and ladderctl in another, joined by a veth pair
// with an address on each end, each side's Cyclone configuration naming its interface and the other's address
// (tests/daemon/netns.hpp). Skipped, saying why, when not root or when the kernel refuses a namespace.

TEST_F(View, RemoteViewerInAnotherNetworkNamespace) {
  NetnsPair net;  // namespaces that go with this process, however it ends: nothing left mounted in /run/netns
  if (const auto why = net.create()) GTEST_SKIP() << *why;
  const std::string xml_a = out_ + "-a.xml", xml_b = out_ + "-b.xml";
  std::ofstream(xml_a) << NetnsPair::xml_a();
  std::ofstream(xml_b) << NetnsPair::xml_b();
  // The remote server runs the same built-in scene as this test's local one, so both rest in the same state.
  Process remote(net.run_in('a', "file://" + xml_a,
                            {kBin + "/server/ladderd", "--domain", std::to_string(domain_), "--sim-id", sim_id_,
                             "--log-level", "debug"}),
                 out_ + "-remote.log");
  const client::State rest = pause();
  const std::string where_b = net.shell_prefix('b', "file://" + xml_b);
  const Result a = shell(where_b + kViewer + where() + " --timeout 30 --png " + out_ + "-remote.png --size 500x700");
  ASSERT_EQ(a.code, 0) << a.output << "\nremote server:\n" << remote.log();
  const auto cam = camera_in(a.output, 500, 700);
  ASSERT_TRUE(cam) << a.output;
  expect_blocks_at_centres(read_png(out_ + "-remote.png"), *cam, *client_->scene_info(), rest);

  const Result tip = shell(where_b + kBin + "/clients/ladderctl tip" + where() + " --timeout 30");
  ASSERT_EQ(tip.code, 0) << tip.output;
  EXPECT_NE(tip.output.find("accepted"), std::string::npos) << tip.output;
  std::smatch m;
  ASSERT_TRUE(std::regex_search(tip.output, m, std::regex(R"(accepted at t = ([0-9.]+) s)"))) << tip.output;
  char at[64];
  std::snprintf(at, sizeof at, "%.3f", std::stod(m[1]) + 1.0);
  const Result b = shell(where_b + kViewer + where() + " --timeout 30 --png " + out_ + "-remote-tipped.png --size 500x700 --at " + at);
  ASSERT_EQ(b.code, 0) << b.output;
  ASSERT_TRUE(std::regex_search(b.output, m, std::regex(R"(t = ([0-9.]+) s)"))) << b.output;
  EXPECT_GE(std::stod(m[1]), std::stod(at));
  // The ladder moved: at some resting block centres the tipped picture no longer shows a face.
  const Image tipped = read_png(out_ + "-remote-tipped.png");
  const auto cam2 = camera_in(b.output, 500, 700);
  ASSERT_TRUE(cam2);
  int faces = 0;
  for (const Rgb& c : tipped.pixels) faces += is_face(c);
  EXPECT_GT(faces, 1000) << "the tipped picture shows no ladder";
  EXPECT_NE(remote.log().find("tip (command 1) from "), std::string::npos) << remote.log();
}

}  // namespace
}  // namespace ladder::test
