// ladder-view's one drawing module: a State (plus its SceneInfo) and a camera -> a picture on a Cairo context.
// The window, the PNG snapshot and the terminal rendering all draw with it (a software renderer: Cairo fills the
// projected faces back to front, so it needs no GPU and runs under Xvfb). No DDS here: only the client library's
// plain State and SceneInfo structs.
//
// Geometry (server/ladder/ladder.hpp): the model is 2-D, seen side-on. Block i is a rectangle `length` tall and
// `thickness` wide centred on its pose (x, y), turned by theta about z; in its frame x runs across the thickness and
// y along the length. Hinge particle c of block i sits at (+-w, +-length/2) with w = (1/2 - hinge_inset) *
// thickness: corners 0 and 1 on the +x side (c & 2 picks the -x side), corner 0 at the low end on even blocks and
// the high end on odd ones. The viewer gives each block a depth along z (the scene's ladder.depth), centred on
// z = 0: a wooden box whose two wide faces (length x depth, normal +-x) carry the ribbons, whose narrow sides
// (length x thickness, normal +-z) are what the side view sees, and whose ends (thickness x depth) meet at the
// hinges.
//
// Rolling hinges (SceneInfo's options say ladder.hinge=rolling, with ladder.end_radius r > 0; docs/model.md section
// 9): each corner of a block is an arc of radius r centred r in from both edges (r = thickness / 2: a fully rounded
// end), the hinge particles sit at the arc centres, and two hinged blocks turn about the contact of their arcs,
// halfway between their arc centres: where the tapes cross (rounded.hpp).
#pragma once

#include "client.hpp"

#include <cairo.h>

#include <array>
#include <numbers>
#include <string>
#include <vector>

namespace ladder::view {

struct Point {
  double x = 0, y = 0;
};
struct Vec3 {
  double x = 0, y = 0, z = 0;
};

// World (metres; x right, y up, z out of the page toward the side-on viewer) to image (pixels, y down): an
// orthographic camera turned by yaw about the vertical through the target, then by pitch about the image's
// horizontal. yaw = pitch = 0 is the side view (the model's own plane, as the paper draws it). Orthographic, so
// that `scale` holds everywhere in the picture (the scale bar is true) and a block's screen size does not depend
// on its depth.
struct Camera {
  double cx = 0, cy = 0;  // [m] the target, on the plane z = 0, at the image's centre
  double scale = 1000;    // [px/m]
  int width = 800, height = 600;  // [px]
  double yaw = 0, pitch = 0;      // [rad]

  // A world point relative to the target, turned into the camera's axes: x right, y up, z toward the viewer.
  Vec3 to_view(Vec3 w) const;
  Point project(Vec3 w) const {
    const Vec3 v = to_view(w);
    return {0.5 * width + v.x * scale, 0.5 * height - v.y * scale};
  }
  Point to_screen(Point w) const { return project({w.x, w.y, 0}); }
  // The point of the plane z = 0 under screen point s (where a drag on the picture goes).
  Point to_world(Point s) const;
  // Zooms by `factor` keeping the world point under screen point s in place.
  void zoom_about(Point s, double factor);
  // Turns the view (orbit about the target), keeping the plane z = 0 in sight: |yaw| and |pitch| stay below 80 deg.
  void orbit(double dyaw, double dpitch);
  // Moves the target so that the picture follows a drag from screen point a to b.
  void pan(Point a, Point b);
  bool side() const { return yaw == 0 && pitch == 0; }
};

// The default 3-D view: from the front-right, a little above, so that each block's wide face and its ribbons face
// the viewer at rest: -50 and 12 degrees, as --view gives them. [rad]
inline constexpr double kDefaultYaw = -50 * std::numbers::pi / 180, kDefaultPitch = 12 * std::numbers::pi / 180;

// The part of the segment a-b (screen points) inside the image and a margin of that many pixels around it, found
// by Liang-Barsky: a and b are moved to its ends. False when no part of it is there, or a point is not a number.
bool clip_to_image(const Camera& cam, double margin, Point& a, Point& b);

// Frames the ladder: the top `max_blocks` blocks (all of a short ladder) with a margin, whole blocks at least, seen
// with the given yaw and pitch.
Camera fit(const client::SceneInfo& info, const client::State& state, int width, int height, int max_blocks = 40,
           double yaw = kDefaultYaw, double pitch = kDefaultPitch);

// The palette. Block faces are warm (wood: red well above green, green well above blue), everything else is not,
// so a sampled pixel tells a block from the background; even and odd blocks differ in shade. Faces are flat
// colours: a sampled pixel says which face of which parity it is.
struct Rgb {
  int r, g, b;
};
inline constexpr Rgb kBackground{22, 26, 36};
inline constexpr Rgb kFaceEven{222, 142, 62};  // the wide faces
inline constexpr Rgb kFaceOdd{196, 112, 40};
inline constexpr Rgb kSideEven{168, 100, 42};  // the narrow sides (length x thickness)
inline constexpr Rgb kSideOdd{146, 84, 30};
inline constexpr Rgb kDepth{110, 62, 26};  // the ends (thickness x depth)
inline constexpr Rgb kRibbon{236, 232, 214};
inline constexpr Rgb kHinge{250, 250, 250};
inline constexpr Rgb kLocked{230, 40, 60};
inline constexpr Rgb kBroken{140, 140, 150};
inline constexpr Rgb kGrip{70, 220, 120};
inline constexpr Rgb kHand{120, 150, 215};  // a blue glove: not warm, so never taken for a block
inline constexpr Rgb kHandShade{84, 105, 150};  // its faces turned from the light: shaded between this and kHand
inline constexpr Rgb kText{235, 235, 240};
Rgb face_colour(int block);  // the wide face's
Rgb side_colour(int block);  // the narrow side's: what the side view shows

// A block's depth [m]: the scene's ladder.depth (SceneInfo's options), else the scene's default. (A replay's SceneInfo
// carries the scene's fixed ladder.* keys too: ladderctl replay makes the recorded scene again to know them.)
inline constexpr double kDefaultDepth = 0.045;
double depth_of(const client::SceneInfo& info);
// The radius [m] of the arcs that round a block's corners: the scene's ladder.end_radius when its ladder.hinge is
// "rolling" (within 0 and half the thickness), else 0: the paper's square corners.
double end_radius_of(const client::SceneInfo& info);

// Block geometry in world coordinates.
// The block's rectangle, counter-clockwise (its corners square: with rolling hinges they are rounded, rounded.hpp).
std::array<Point, 4> outline(const client::SceneInfo& info, const client::Pose& pose);
// Hinge particle c of a block: its corner, or with rounded ends the centre of the corner's arc. The second form
// takes end_radius_of(info), read once for a loop over many blocks.
Point hinge_particle(const client::SceneInfo& info, int block, int c, const client::Pose& pose);
Point hinge_particle(const client::SceneInfo& info, double r, int block, int c, const client::Pose& pose);
// Where hinge k (1 <= k < the blocks) turns: its particle on block k (for a corner hinge the two blocks' particles
// coincide), or for a rolling hinge the contact of the two arcs, halfway between the two blocks' arc centres.
Point pivot(const client::SceneInfo& info, const client::State& state, int hinge);
Point pivot(const client::SceneInfo& info, double r, const client::State& state, int hinge);
Point to_block_frame(const client::Pose& pose, Point world);
// The block whose outline (its rectangle, with rounded corners for rolling hinges) contains the world point (the
// highest-numbered one where two overlap), or -1. Scans every block, O(blocks): about 0.1 ms for 100 000, once per
// click.
int block_at(const client::SceneInfo& info, const client::State& state, Point world);

// The ribbons (tapes) as on the real toy: hinge k's tapes run along the wide face on its hinge's side (c & 2) of
// both blocks it joins: two outer tapes on the upper block k-1, one central tape on the lower block k. So each block
// carries two outer tapes on one wide face (those of the hinge below it) and a central one on the other (the hinge
// above), and down one side of the ladder the faces alternate, as the paper's Figure 3 shows. A broken hinge has
// none. Which are seen follows the hinges: a flip-flop turns a block over, and the face toward the viewer is then
// the one with the other tapes (Algorithm 2's "hide and show ribbons").
// The tapes of `block` on its face of side `sign` (+1: the +x face): -1 none, else the hinge whose tapes they are.
int tapes_on(const client::State& state, int block, int sign);
// Where across the depth the tapes of `hinge` on `block` lie: centres as fractions of the depth (0 = middle).
std::vector<double> tape_centres(int hinge, int block);
inline constexpr double kTapeWidth = 0.16;  // [fraction of the depth]

// The block under screen point s, and the point of it there (its x, y: in the block's outline), or block -1.
// Casts the ray through s against every block's box (with rounded ends, the box with its corners rounded: a click
// on a cut-off corner finds what is behind it), O(blocks).
struct Pick {
  int block = -1;
  Point world;
};
Pick pick(const Camera& cam, const client::SceneInfo& info, const client::State& state, Point s);

// What the picture says besides the ladder.
struct Hud {
  bool show = true;              // the top line: sim time, real-time factor, paused
  bool stats = false;            // the overlay: more figures, one per line
  bool numbers = false;          // each block's number beside it
  bool scale_bar = true;         // a bar of a round length, bottom left
  double real_time_factor = -1;  // measured (Stats); < 0 = not known yet
  std::string title;             // e.g. the sim id
  std::vector<std::string> lines;  // overlay lines (stats, keys, the last command's answer)
  std::string banner;            // big centred message, e.g. "waiting for ladderd ..."
  bool marks = true;             // the hinges' and grips' marks (the terminal rendering sets its own: marks())
};

// Where the hinges and grips are marked, in screen pixels, and with what character: 'o' a hinge, '@' a locked one,
// 'x' each of a broken hinge's two particles, '*' a grip's target (plain hinges only where a block is at least 4 px
// long). The terminal rendering puts these characters in
// its cells: a mark a few pixels across, read back from an antialiased picture, is lost or mistaken for an edge.
struct Mark {
  Point at;
  char ch;
};
std::vector<Mark> marks(const Camera& camera, const client::SceneInfo& info, const client::State& state);

// Draws everything: background, blocks as boxes (back to front) with their ribbons, the hand on a held top block,
// hinges (locked and broken ones marked, each at its pivot), grips, numbers, scale bar, HUD. Rolling-hinge blocks
// have their corners rounded, and their tapes wrap the rounded ends and cross at each contact point (rounded.hpp);
// in the side view, where the wide faces are edge-on, their tapes are drawn as lines along the outline. Draws only
// what is on screen; returns how many blocks it drew.
int draw(cairo_t* cr, const Camera& camera, const client::SceneInfo& info, const client::State& state, const Hud& hud);
// Writes the surface to `path` as a PNG; "" when done, else why not in words ("No such file or directory": cairo
// says only "error while writing to output stream").
std::string write_png(cairo_surface_t* surface, const std::string& path);
// Background and HUD only (no state yet).
void draw_empty(cairo_t* cr, const Camera& camera, const Hud& hud);
// Which block numbers are drawn (key n, --numbers) when a block is `length_px` long on screen: every 1st, 2nd, 5th,
// 10th, ..., the first of these whose labels, one block length apart, do not overlap (a 64-block ladder framed in
// 700 px had 45 labels on top of each other).
int number_stride(double length_px);
// A big message centred in the picture (Hud::banner; the window draws it itself, last, over the plots).
void draw_banner(cairo_t* cr, const Camera& camera, const std::string& text);

// The hand that holds a held top block: fingers pinching block 0 at its centre from the front, the forearm toward
// the viewer (the axis about which the wrist turns the block when the ladder is tipped). The fingers' centre in
// world coordinates, for tests and the picture.
Vec3 hand_centre(const client::SceneInfo& info, const client::Pose& top);

}  // namespace ladder::view
