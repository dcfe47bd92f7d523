// ladder-view's one drawing module: a State (plus its SceneInfo) and a camera -> a picture on a Cairo context.
// The window, the PNG snapshot and the terminal rendering all draw with it. No DDS here: only the client library's
// plain State and SceneInfo structs.
//
// Geometry (server/ladder/ladder.hpp): block i is a rectangle `length` tall and `thickness` wide seen side-on,
// centred on its pose (x, y) and turned by theta; in its frame x runs across the width and y along the length.
// Hinge particle c of block i sits at (+-w, +-length/2) with w = (1/2 - hinge_inset) * thickness: corners 0 and 1
// on the +x edge (c & 2 picks the -x edge), corner 0 at the low end on even blocks and the high end on odd ones.
#pragma once

#include "client.hpp"

#include <cairo.h>

#include <array>
#include <string>
#include <vector>

namespace ladder::view {

struct Point {
  double x = 0, y = 0;
};

// World (metres, y up) to image (pixels, y down): the world point (cx, cy) sits at the image's centre.
struct Camera {
  double cx = 0, cy = 0;  // [m]
  double scale = 1000;    // [px/m]
  int width = 800, height = 600;  // [px]

  Point to_screen(Point w) const { return {0.5 * width + (w.x - cx) * scale, 0.5 * height - (w.y - cy) * scale}; }
  Point to_world(Point s) const { return {cx + (s.x - 0.5 * width) / scale, cy - (s.y - 0.5 * height) / scale}; }
  // Zooms by `factor` keeping the world point under screen point s in place.
  void zoom_about(Point s, double factor);
};

// Frames the ladder: the top `max_blocks` blocks (all of a short ladder) with a margin, whole blocks at least.
Camera fit(const client::SceneInfo& info, const client::State& state, int width, int height, int max_blocks = 40);

// The palette. Block faces are warm (wood: red well above green, green well above blue), everything else is not,
// so a sampled pixel tells a block from the background; even and odd blocks differ in shade.
struct Rgb {
  int r, g, b;
};
inline constexpr Rgb kBackground{22, 26, 36};
inline constexpr Rgb kFaceEven{222, 142, 62};
inline constexpr Rgb kFaceOdd{196, 112, 40};
inline constexpr Rgb kDepth{110, 62, 26};  // the blocks' sides and tops seen in depth
inline constexpr Rgb kRibbon{236, 232, 214};
inline constexpr Rgb kHinge{250, 250, 250};
inline constexpr Rgb kLocked{230, 40, 60};
inline constexpr Rgb kBroken{140, 140, 150};
inline constexpr Rgb kGrip{70, 220, 120};
inline constexpr Rgb kText{235, 235, 240};
Rgb face_colour(int block);

// Block geometry in world coordinates.
std::array<Point, 4> outline(const client::SceneInfo& info, const client::Pose& pose);  // counter-clockwise
Point hinge_particle(const client::SceneInfo& info, int block, int c, const client::Pose& pose);
Point to_block_frame(const client::Pose& pose, Point world);
// The block whose rectangle contains the world point (the highest-numbered one where two overlap), or -1.
// Scans every block, O(blocks): about 0.1 ms for 100 000, once per click.
int block_at(const client::SceneInfo& info, const client::State& state, Point world);

// What the picture says besides the ladder.
struct Hud {
  bool show = true;              // the top line: sim time, real-time factor, paused
  bool stats = false;            // the overlay: more figures, one per line
  double real_time_factor = -1;  // measured (Stats); < 0 = not known yet
  std::string title;             // e.g. the sim id
  std::vector<std::string> lines;  // overlay lines (stats, keys, the last command's answer)
  std::string banner;            // big centred message, e.g. "waiting for ladderd ..."
};

// Draws everything: background, blocks with depth, ribbons, hinges (locked and broken ones marked), grips, HUD.
// Draws only what is on screen; returns how many blocks it drew.
int draw(cairo_t* cr, const Camera& camera, const client::SceneInfo& info, const client::State& state, const Hud& hud);
// Background and HUD only (no state yet).
void draw_empty(cairo_t* cr, const Camera& camera, const Hud& hud);

}  // namespace ladder::view
