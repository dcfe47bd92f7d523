#include "draw.hpp"

#include "rounded.hpp"

#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <string_view>
#include <utility>

namespace ladder::view {

namespace {

constexpr double kMaxAngle = 80 * M_PI / 180;  // orbit limit: the plane z = 0 stays in sight

Point rotate(double theta, Point p) {
  const double c = std::cos(theta), s = std::sin(theta);
  return {c * p.x - s * p.y, s * p.x + c * p.y};
}

// The camera's rotation R = Rx(pitch) Ry(yaw), rows: the view's x, y and z axes in world coordinates.
struct Rotation {
  double m[3][3];
  Rotation(double yaw, double pitch) {
    const double c = std::cos(yaw), s = std::sin(yaw), cp = std::cos(pitch), sp = std::sin(pitch);
    const double r[3][3] = {{c, 0, s}, {sp * s, cp, -sp * c}, {-cp * s, sp, cp * c}};
    std::copy(&r[0][0], &r[0][0] + 9, &m[0][0]);
  }
  Vec3 apply(Vec3 w) const {
    return {m[0][0] * w.x + m[0][1] * w.y + m[0][2] * w.z, m[1][0] * w.x + m[1][1] * w.y + m[1][2] * w.z,
            m[2][0] * w.x + m[2][1] * w.y + m[2][2] * w.z};
  }
  Vec3 inverse(Vec3 v) const {
    return {m[0][0] * v.x + m[1][0] * v.y + m[2][0] * v.z, m[0][1] * v.x + m[1][1] * v.y + m[2][1] * v.z,
            m[0][2] * v.x + m[1][2] * v.y + m[2][2] * v.z};
  }
};

// The point of the plane z = 0 in front of which view coordinates (vx, vy) lie (relative to the target): the view
// ray (vx, vy, t) turned back into the world, with the t that puts it on the plane.
Point on_plane(const Rotation& r, double vx, double vy) {
  const double t = -(r.m[0][2] * vx + r.m[1][2] * vy) / r.m[2][2];
  const Vec3 w = r.inverse({vx, vy, t});
  return {w.x, w.y};
}

void set_colour(cairo_t* cr, Rgb c, double alpha = 1) {
  cairo_set_source_rgba(cr, c.r / 255.0, c.g / 255.0, c.b / 255.0, alpha);
}

void polygon(cairo_t* cr, const Point* p, int n) {
  cairo_move_to(cr, p[0].x, p[0].y);
  for (int i = 1; i < n; ++i) cairo_line_to(cr, p[i].x, p[i].y);
  cairo_close_path(cr);
}

// A box turned by theta about z: centre, half sizes along its own x, y and z.
struct Box {
  Vec3 centre;
  double theta = 0;
  Vec3 half;
  Vec3 corner(int sx, int sy, int sz) const {  // s* = +-1
    const Point r = rotate(theta, {sx * half.x, sy * half.y});
    return {centre.x + r.x, centre.y + r.y, centre.z + sz * half.z};
  }
  Vec3 local_to_world(Vec3 l) const {
    const Point r = rotate(theta, {l.x, l.y});
    return {centre.x + r.x, centre.y + r.y, centre.z + l.z};
  }
};

// The six faces of a box: which axis (0 x, 1 y, 2 z) and side. A face is drawn when its normal faces the viewer.
struct FaceDef {
  int axis, sign;
};
constexpr FaceDef kFaces[6] = {{0, 1}, {0, -1}, {1, 1}, {1, -1}, {2, 1}, {2, -1}};

Vec3 face_normal(const Box& b, FaceDef f) {
  if (f.axis == 2) return {0, 0, double(f.sign)};
  const Point n = rotate(b.theta, f.axis == 0 ? Point{double(f.sign), 0} : Point{0, double(f.sign)});
  return {n.x, n.y, 0};
}

// The face's four corners, in order round it.
std::array<Vec3, 4> face_corners(const Box& b, FaceDef f) {
  static constexpr int kRound[4][2] = {{-1, -1}, {1, -1}, {1, 1}, {-1, 1}};
  std::array<Vec3, 4> q;
  for (int i = 0; i < 4; ++i) {
    int s[3];
    s[f.axis] = f.sign;
    s[(f.axis + 1) % 3] = kRound[i][0];
    s[(f.axis + 2) % 3] = kRound[i][1];
    q[i] = b.corner(s[0], s[1], s[2]);
  }
  return q;
}

// Which blocks to draw, and at what level of detail. A block is on screen when its bounding sphere meets the image.
struct View {
  const Camera& cam;
  const client::SceneInfo& info;
  Rotation rot;
  double depth;      // [m] of a block
  double radius_px;  // bounding sphere of a block
  double length_px;  // a block's length on screen
  double r;          // [m] the rounded ends' radius; 0: square corners (boxes)
  int segments;      // facets to a quarter arc: the chord strays from the arc by at most about 0.3 px

  View(const Camera& c, const client::SceneInfo& i)
      : cam(c), info(i), rot(c.yaw, c.pitch), depth(depth_of(i)),
        radius_px(0.5 * std::sqrt(i.length * i.length + i.thickness * i.thickness + depth * depth) * c.scale),
        length_px(i.length * c.scale), r(end_radius_of(i)),
        segments(facets_for(r * c.scale)) {}

  // Facets to a quarter arc of radius r_px pixels: 2 to 24 (2 for a radius that is not a number).
  static int facets_for(double r_px) {
    const double f = std::ceil(0.8 * std::sqrt(2 * r_px));
    return f >= 2 ? (f <= 24 ? static_cast<int>(f) : 24) : 2;
  }

  bool visible(const client::Pose& p) const {
    const Point s = cam.to_screen({p.x, p.y});
    return s.x > -radius_px && s.x < cam.width + radius_px && s.y > -radius_px && s.y < cam.height + radius_px;
  }
  Point screen(Vec3 w) const { return cam.project(w); }
  double towards_viewer(Vec3 n) const { return rot.apply(n).z; }
  double view_depth(Vec3 w) const { return rot.apply(w).z; }
  Box block(const client::Pose& p) const {
    return {{p.x, p.y, 0}, p.theta, {0.5 * info.thickness, 0.5 * info.length, 0.5 * depth}};
  }
};

// Far away, a block is a few pixels: the ladder is drawn as one polyline through the centres.
void draw_chain(cairo_t* cr, const View& v, const std::vector<client::Pose>& blocks) {
  cairo_set_line_width(cr, std::max(1.0, std::max(v.info.thickness, 0.7 * v.depth) * v.cam.scale));
  cairo_set_line_cap(cr, CAIRO_LINE_CAP_ROUND);
  bool open = false;
  for (const client::Pose& p : blocks) {
    if (!v.visible(p)) {
      open = false;
      continue;
    }
    const Point s = v.cam.to_screen({p.x, p.y});
    if (open)
      cairo_line_to(cr, s.x, s.y);
    else
      cairo_move_to(cr, s.x, s.y);
    open = true;
  }
  set_colour(cr, kFaceEven);
  cairo_stroke(cr);
}

// The tapes on a wide face: thin quads along the whole length, lying on it.
void draw_tapes(cairo_t* cr, const View& v, const Box& b, int sign, int hinge, int block) {
  for (const double zc : tape_centres(hinge, block)) {
    const double x = sign * b.half.x, z0 = (zc - 0.5 * kTapeWidth) * v.depth, z1 = (zc + 0.5 * kTapeWidth) * v.depth;
    const Point q[4] = {v.screen(b.local_to_world({x, -b.half.y, z0})), v.screen(b.local_to_world({x, -b.half.y, z1})),
                        v.screen(b.local_to_world({x, b.half.y, z1})), v.screen(b.local_to_world({x, b.half.y, z0}))};
    polygon(cr, q, 4);
  }
  set_colour(cr, kRibbon);
  cairo_fill(cr);
}

// Calls run(first, count) for each run of consecutive facets (round the closed outline) with the same key(facet).
template <typename Key, typename Run>
void for_each_run(const std::vector<Facet>& f, Key key, Run run) {
  const std::size_t n = f.size();
  std::size_t start = 0;  // a facet whose key differs from the one before it, so that no run wraps past the start
  while (start < n && key(f[start]) == key(f[(start + n - 1) % n])) ++start;
  if (start == n) {  // one key all round
    if (n) run(0, n);
    return;
  }
  for (std::size_t k = 0; k < n;) {
    std::size_t len = 1;
    while (len < n - k && key(f[(start + k + len) % n]) == key(f[(start + k) % n])) ++len;
    run((start + k) % n, len);
    k += len;
  }
}

// A band across the depth, from z0 to z1, over `count` facets from `first`: the outline's points at z0 forward,
// then at z1 back.
void band(cairo_t* cr, const View& v, const Box& b, const std::vector<Facet>& f, std::size_t first, std::size_t count,
          double z0, double z1) {
  const std::size_t n = f.size();
  const auto at = [&](Point p, double z) { return v.screen(b.local_to_world({p.x, p.y, z})); };
  Point p = at(f[first].a, z0);
  cairo_move_to(cr, p.x, p.y);
  for (std::size_t k = 0; k < count; ++k) {
    p = at(f[(first + k) % n].b, z0);
    cairo_line_to(cr, p.x, p.y);
  }
  for (std::size_t k = count; k-- > 0;) {
    p = at(f[(first + k) % n].b, z1);
    cairo_line_to(cr, p.x, p.y);
  }
  p = at(f[first].a, z1);
  cairo_line_to(cr, p.x, p.y);
  cairo_close_path(cr);
}

// A block with rounded ends: the narrow side toward the viewer (the whole outline), the facets round the outline
// that face the viewer, consecutive ones of one colour filled as one polygon (Cairo's antialiasing would leave a
// seam between two fills), then the tapes on them. A rounded box is convex: what faces the viewer never overlaps.
void draw_rounded_block(cairo_t* cr, const View& v, const client::State& s, int i, bool tapes,
                        std::vector<Facet>& facets) {
  const Box b = v.block(s.blocks[static_cast<std::size_t>(i)]);
  rounded_outline(v.info, s, i, v.r, v.segments, facets);
  for (const int sz : {1, -1}) {
    if (v.towards_viewer({0, 0, double(sz)}) <= 1e-9) continue;
    for (std::size_t k = 0; k < facets.size(); ++k) {
      const Point p = v.screen(b.local_to_world({facets[k].a.x, facets[k].a.y, sz * b.half.z}));
      k ? cairo_line_to(cr, p.x, p.y) : cairo_move_to(cr, p.x, p.y);
    }
    cairo_close_path(cr);
    set_colour(cr, side_colour(i));
    cairo_fill(cr);
  }
  const auto seen = [&](const Facet& f) {
    const Point n = rotate(b.theta, f.normal);
    return v.towards_viewer({n.x, n.y, 0}) > 1e-9;
  };
  for_each_run(facets, [&](const Facet& f) { return seen(f) ? (f.wide ? 1 : 2) : 0; },
               [&](std::size_t first, std::size_t count) {
                 if (!seen(facets[first])) return;
                 band(cr, v, b, facets, first, count, -b.half.z, b.half.z);
                 set_colour(cr, facets[first].wide ? face_colour(i) : kDepth);
                 cairo_fill(cr);
               });
  if (!tapes) return;
  // Runs of one set of tapes across the depth (a central one, or the outer pair), whosever they are: a tape that goes
  // on from one hinge's piece to another's is one polygon, with no seam.
  const auto tapes_key = [&](const Facet& f) {
    return f.hinge >= 0 && seen(f) ? static_cast<int>(tape_centres(f.hinge, f.owner).size()) : 0;
  };
  for_each_run(facets, tapes_key,
               [&](std::size_t first, std::size_t count) {
                 const Facet& f = facets[first];
                 if (f.hinge < 0 || !seen(f)) return;
                 for (const double zc : tape_centres(f.hinge, f.owner))
                   band(cr, v, b, facets, first, count, (zc - 0.5 * kTapeWidth) * v.depth,
                        (zc + 0.5 * kTapeWidth) * v.depth);
                 set_colour(cr, kRibbon);
                 cairo_fill(cr);
               });
}

// The side view of rounded blocks: their wide faces, and the tapes on them, are edge-on. The tapes are drawn as
// lines along the outline, so that the figure-8 they make at each contact point shows as the paper's side view
// would draw it. After every block, so that no block covers the tapes crossing onto it.
void draw_tape_lines(cairo_t* cr, const View& v, const client::State& s, const std::vector<char>& shown,
                     std::vector<Facet>& facets) {
  const double front = 0.5 * v.depth;
  cairo_set_line_width(cr, std::clamp(0.06 * v.info.thickness * v.cam.scale, 1.5, 3.0));
  cairo_set_line_join(cr, CAIRO_LINE_JOIN_ROUND);
  cairo_set_line_cap(cr, CAIRO_LINE_CAP_BUTT);
  for (std::size_t i = 0; i < s.blocks.size(); ++i) {
    if (!shown[i]) continue;
    const Box b = v.block(s.blocks[i]);
    rounded_outline(v.info, s, static_cast<int>(i), v.r, v.segments, facets);
    for_each_run(facets, [](const Facet& f) { return f.hinge >= 0; },
                 [&](std::size_t first, std::size_t count) {
                   if (facets[first].hinge < 0) return;
                   Point p = v.screen(b.local_to_world({facets[first].a.x, facets[first].a.y, front}));
                   cairo_move_to(cr, p.x, p.y);
                   for (std::size_t k = 0; k < count; ++k) {
                     const Facet& f = facets[(first + k) % facets.size()];
                     p = v.screen(b.local_to_world({f.b.x, f.b.y, front}));
                     cairo_line_to(cr, p.x, p.y);
                   }
                 });
  }
  set_colour(cr, kRibbon);
  cairo_stroke(cr);
}

// One block: its faces that face the viewer (a box's never overlap on screen), the tapes on its wide faces.
void draw_block(cairo_t* cr, const View& v, const client::State& s, int i, bool tapes) {
  const Box b = v.block(s.blocks[static_cast<std::size_t>(i)]);
  for (const FaceDef f : kFaces) {
    if (v.towards_viewer(face_normal(b, f)) <= 1e-9) continue;
    const std::array<Vec3, 4> w = face_corners(b, f);
    Point q[4];
    for (int k = 0; k < 4; ++k) q[k] = v.screen(w[k]);
    polygon(cr, q, 4);
    set_colour(cr, f.axis == 0 ? face_colour(i) : f.axis == 2 ? side_colour(i) : kDepth);
    cairo_fill(cr);
    if (f.axis != 0 || !tapes) continue;
    if (const int h = tapes_on(s, i, f.sign); h >= 0) draw_tapes(cr, v, b, f.sign, h, i);
  }
}

// The hand on a held top block: fingers pinching block 0 at its centre from the front (its +z side) and the
// forearm coming out toward the viewer, the axis the wrist turns the block about when it tips the ladder. Shaded by
// how squarely each face meets the view.
void draw_hand(cairo_t* cr, const View& v, const client::Pose& top) {
  const double t = v.info.thickness, l = v.info.length, d = v.depth;
  const Vec3 fingers = hand_centre(v.info, top);
  const double finger_depth = fingers.z - 0.5 * d, arm = 1.2 * d;
  const Box boxes[2] = {
      {{top.x, top.y, fingers.z + finger_depth + 0.5 * arm}, top.theta, {0.7 * t, 0.16 * l, 0.5 * arm}},  // forearm
      {fingers, top.theta, {0.8 * t, 0.22 * l, finger_depth}}};                                            // fingers
  for (const Box& b : boxes)
    for (const FaceDef f : kFaces) {
      const double facing = v.towards_viewer(face_normal(b, f));
      if (facing <= 1e-9) continue;
      const std::array<Vec3, 4> w = face_corners(b, f);
      Point q[4];
      for (int k = 0; k < 4; ++k) q[k] = v.screen(w[k]);
      polygon(cr, q, 4);
      const double k = std::clamp(facing, 0.0, 1.0);  // kHandShade (edge-on) to kHand (square on)
      set_colour(cr, {static_cast<int>(kHandShade.r + k * (kHand.r - kHandShade.r)),
                      static_cast<int>(kHandShade.g + k * (kHand.g - kHandShade.g)),
                      static_cast<int>(kHandShade.b + k * (kHand.b - kHandShade.b))});
      cairo_fill(cr);
    }
}

// Hinges: each hinge's axis (its particle along the whole depth), white when hinged, red and thicker when locked,
// with a dot at its front end; a broken hinge a grey cross on each of its two particles.
void draw_hinges(cairo_t* cr, const View& v, const client::State& s, const std::vector<char>& shown) {
  const double r = std::clamp(0.15 * v.info.thickness * v.cam.scale, 1.5, 5.0);
  const double front = v.towards_viewer({0, 0, 1}) >= 0 ? 0.5 * v.depth : -0.5 * v.depth;
  for (std::size_t k = 1; k < s.blocks.size() && k < s.hinges.size(); ++k) {
    if (!(shown[k - 1] || shown[k])) continue;
    const client::Hinge& h = s.hinges[k];
    const int ki = static_cast<int>(k);
    const Point p2 = h.status == ladder_msg_BROKEN ? hinge_particle(v.info, v.r, ki, h.corner, s.blocks[k])
                                                   : pivot(v.info, v.r, s, ki);
    const Point p = v.screen({p2.x, p2.y, front}), back = v.screen({p2.x, p2.y, -front});
    if (h.status == ladder_msg_BROKEN) {
      const Point q2 = hinge_particle(v.info, v.r, ki - 1, h.corner, s.blocks[k - 1]);
      set_colour(cr, kBroken);
      cairo_set_line_width(cr, 1.5);
      for (const Point& x : {p, v.screen({q2.x, q2.y, front})}) {
        cairo_move_to(cr, x.x - r, x.y - r);
        cairo_line_to(cr, x.x + r, x.y + r);
        cairo_move_to(cr, x.x - r, x.y + r);
        cairo_line_to(cr, x.x + r, x.y - r);
      }
      cairo_stroke(cr);
      continue;
    }
    const bool locked = h.status == ladder_msg_LOCKED;
    set_colour(cr, locked ? kLocked : kHinge);
    cairo_set_line_width(cr, locked ? 1.2 * r : 0.6 * r);
    cairo_set_line_cap(cr, CAIRO_LINE_CAP_ROUND);
    cairo_move_to(cr, back.x, back.y);
    cairo_line_to(cr, p.x, p.y);
    cairo_stroke(cr);
    cairo_arc(cr, p.x, p.y, locked ? 1.5 * r : r, 0, 2 * M_PI);
    cairo_fill(cr);
  }
}

// A user's hand: a ring at the grip's target and a dashed line to the block it holds, each drawn where it is in the
// image (a target kilometres away would otherwise be a dashed line of millions of pixels).
void draw_grips(cairo_t* cr, const View& v, const client::State& s) {
  constexpr double kRing = 6;
  for (const ladder_msg_Grip& g : s.grips) {
    if (g.block < 0 || static_cast<std::size_t>(g.block) >= s.blocks.size()) continue;
    const Point t = v.cam.to_screen({g.target_x, g.target_y});
    Point from = v.cam.to_screen({s.blocks[g.block].x, s.blocks[g.block].y}), to = t;
    set_colour(cr, kGrip);
    cairo_set_line_width(cr, 2);
    if (clip_to_image(v.cam, kRing, from, to)) {
      const double dash[] = {4, 3};
      cairo_set_dash(cr, dash, 2, 0);
      cairo_move_to(cr, from.x, from.y);
      cairo_line_to(cr, to.x, to.y);
      cairo_stroke(cr);
      cairo_set_dash(cr, nullptr, 0, 0);
    }
    if (t.x > -kRing && t.x < v.cam.width + kRing && t.y > -kRing && t.y < v.cam.height + kRing) {
      cairo_arc(cr, t.x, t.y, kRing, 0, 2 * M_PI);
      cairo_stroke(cr);
    }
  }
}

// `text` without an incomplete UTF-8 sequence at its end. Every text the picture shows is valid UTF-8 (the client
// makes what comes from DDS printable) until snprintf cuts a line to its buffer, maybe inside a character: cairo
// then put the context in an error state and drew nothing more of the frame.
std::string whole_characters(std::string text) {
  std::size_t start = text.size();  // where the last character begins
  for (int back = 0; back < 4 && start > 0; ++back)
    if ((static_cast<unsigned char>(text[--start]) & 0xC0) != 0x80) break;
  if (start == text.size()) return text;
  const unsigned char lead = static_cast<unsigned char>(text[start]);
  const std::size_t need = lead < 0x80 ? 1 : lead >= 0xF0 ? 4 : lead >= 0xE0 ? 3 : lead >= 0xC0 ? 2 : 1;
  if (text.size() - start < need) text.resize(start);
  return text;
}

void draw_text_box(cairo_t* cr, double x, double y, double size, std::vector<std::string> lines) {
  if (lines.empty()) return;
  for (std::string& l : lines) l = whole_characters(std::move(l));
  cairo_select_font_face(cr, "DejaVu Sans Mono", CAIRO_FONT_SLANT_NORMAL, CAIRO_FONT_WEIGHT_NORMAL);
  cairo_set_font_size(cr, size);
  double w = 0;
  for (const std::string& l : lines) {
    cairo_text_extents_t e;
    cairo_text_extents(cr, l.c_str(), &e);
    w = std::max(w, e.x_advance);
  }
  const double line = 1.3 * size;
  cairo_set_source_rgba(cr, 0, 0, 0, 0.55);
  cairo_rectangle(cr, x - 4, y - 4, w + 8, line * static_cast<double>(lines.size()) + 8);
  cairo_fill(cr);
  set_colour(cr, kText);
  for (std::size_t i = 0; i < lines.size(); ++i) {
    cairo_move_to(cr, x, y + line * static_cast<double>(i) + size);
    cairo_show_text(cr, lines[i].c_str());
  }
}

// Each drawn block's number (every number_stride()-th), just right of where the block is on screen.
// A label that would cover one already drawn (the two blocks of a folded pair lie side by side at one height) is
// moved right, past it.
void draw_numbers(cairo_t* cr, const View& v, const client::State& s, const std::vector<char>& shown) {
  constexpr double kSize = 12, kPad = 4, kHeight = 1.3 * kSize + 2 * kPad;  // draw_text_box's box
  const std::size_t stride = static_cast<std::size_t>(number_stride(v.length_px));
  cairo_select_font_face(cr, "DejaVu Sans Mono", CAIRO_FONT_SLANT_NORMAL, CAIRO_FONT_WEIGHT_NORMAL);
  cairo_set_font_size(cr, kSize);
  struct Placed {
    double left, top, right;
  };
  std::vector<Placed> placed;
  for (std::size_t i = 0; i < s.blocks.size(); ++i) {
    if (!shown[i] || i % stride != 0) continue;
    const Box b = v.block(s.blocks[i]);
    double right = -1e300;
    for (int c = 0; c < 8; ++c)
      right = std::max(right, v.screen(b.corner(c & 1 ? 1 : -1, c & 2 ? 1 : -1, c & 4 ? 1 : -1)).x);
    const Point centre = v.cam.to_screen({s.blocks[i].x, s.blocks[i].y});
    const std::string label = std::to_string(i);
    cairo_text_extents_t e;
    cairo_text_extents(cr, label.c_str(), &e);
    double x = right + 8;
    const double y = centre.y - 7;
    for (bool moved = true; moved;) {
      moved = false;
      for (const Placed& p : placed)
        if (x - kPad < p.right && x + e.x_advance + kPad > p.left && std::abs(y - p.top) < kHeight) {
          x = p.right + 2 * kPad;  // its box begins kPad after the other's ends
          moved = true;
        }
    }
    placed.push_back({x - kPad, y, x + e.x_advance + kPad});
    draw_text_box(cr, x, y, kSize, {label});
  }
}

// A bar of 1, 2 or 5 times a power of ten metres, 60 to 150 pixels long, bottom left, with its length.
void draw_scale_bar(cairo_t* cr, const Camera& cam) {
  const double target = 150 / cam.scale;  // [m] the longest bar
  const double decade = std::pow(10, std::floor(std::log10(target)));
  double len = decade;
  for (const double m : {2.0, 5.0, 10.0})
    if (m * decade <= target) len = m * decade;
  char text[32];
  if (len >= 1)
    std::snprintf(text, sizeof text, "%g m", len);
  else if (len >= 0.01)
    std::snprintf(text, sizeof text, "%g cm", len * 100);
  else
    std::snprintf(text, sizeof text, "%g mm", len * 1000);
  const double px = len * cam.scale, x = 16, y = cam.height - 18;
  set_colour(cr, kText);
  cairo_set_line_width(cr, 2);
  cairo_move_to(cr, x, y - 5);
  cairo_line_to(cr, x, y);
  cairo_line_to(cr, x + px, y);
  cairo_line_to(cr, x + px, y - 5);
  cairo_stroke(cr);
  cairo_select_font_face(cr, "DejaVu Sans", CAIRO_FONT_SLANT_NORMAL, CAIRO_FONT_WEIGHT_NORMAL);
  cairo_set_font_size(cr, 12);
  cairo_move_to(cr, x + px + 6, y + 4);
  cairo_show_text(cr, text);
}

void draw_hud(cairo_t* cr, const Camera& cam, const Hud& hud, const client::State* s) {
  if (hud.show) {
    std::vector<std::string> top;
    char buf[320];
    if (s) {
      const std::string rtf =
          hud.real_time_factor >= 0 && !s->paused ? client::fixed(hud.real_time_factor, 2) : "-";  // (as ascii.cpp)
      std::snprintf(buf, sizeof buf, "%s  t = %s s  real-time x%s%s", hud.title.c_str(),
                    client::fixed(s->sim_time, 3).c_str(), rtf.c_str(), s->paused ? "  PAUSED" : "");
      top.emplace_back(buf);
    } else {
      top.push_back(hud.title);
    }
    draw_text_box(cr, 10, 10, 14, top);
    // The overlay down the left side, clear of the ladder that the view centres.
    if (hud.stats) draw_text_box(cr, 10, 40, 12, hud.lines);
  }
  if (hud.scale_bar) draw_scale_bar(cr, cam);
  draw_banner(cr, cam, hud.banner);
}

}  // namespace

int number_stride(double length_px) {
  constexpr double kLabel = 24;  // [px] a label's box: 12 px text, its line and margins
  for (int stride = 1;; stride *= 10)
    for (const int m : {1, 2, 5})
      if (m * stride * length_px >= kLabel || m * stride >= 1000000) return m * stride;
}

void draw_banner(cairo_t* cr, const Camera& cam, const std::string& text) {
  if (text.empty()) return;
  const std::string whole = whole_characters(text);
  cairo_select_font_face(cr, "DejaVu Sans Mono", CAIRO_FONT_SLANT_NORMAL, CAIRO_FONT_WEIGHT_NORMAL);
  cairo_set_font_size(cr, 20);
  cairo_text_extents_t e;
  cairo_text_extents(cr, whole.c_str(), &e);
  draw_text_box(cr, 0.5 * (cam.width - e.x_advance), 0.5 * cam.height - 10, 20, {whole});
}

Vec3 Camera::to_view(Vec3 w) const { return Rotation(yaw, pitch).apply({w.x - cx, w.y - cy, w.z}); }

Point Camera::to_world(Point s) const {
  const Point w = on_plane(Rotation(yaw, pitch), (s.x - 0.5 * width) / scale, -(s.y - 0.5 * height) / scale);
  return {cx + w.x, cy + w.y};
}

void Camera::zoom_about(Point s, double factor) {
  const Point w = to_world(s);
  scale *= factor;
  const Point after = to_world(s);
  cx += w.x - after.x;
  cy += w.y - after.y;
}

void Camera::orbit(double dyaw, double dpitch) {
  yaw = std::clamp(yaw + dyaw, -kMaxAngle, kMaxAngle);
  pitch = std::clamp(pitch + dpitch, -kMaxAngle, kMaxAngle);
}

void Camera::pan(Point a, Point b) {
  const Point wa = to_world(a), wb = to_world(b);
  cx -= wb.x - wa.x;
  cy -= wb.y - wa.y;
}

Rgb face_colour(int block) { return block % 2 == 0 ? kFaceEven : kFaceOdd; }
Rgb side_colour(int block) { return block % 2 == 0 ? kSideEven : kSideOdd; }

namespace {
// The text after "key=" on its line of SceneInfo's options, or null.
const char* option(const client::SceneInfo& info, const std::string& key) {
  const std::string k = key + "=";
  const std::size_t at = info.options.starts_with(k) ? 0 : info.options.find("\n" + k);
  return at == std::string::npos ? nullptr : info.options.c_str() + at + (at == 0 ? 0 : 1) + k.size();
}
}  // namespace

double depth_of(const client::SceneInfo& info) {
  if (const char* text = option(info, "ladder.depth")) {
    char* end = nullptr;
    const double d = std::strtod(text, &end);
    if (end != text && std::isfinite(d) && d > 0) return d;
  }
  return kDefaultDepth;
}

double end_radius_of(const client::SceneInfo& info) {
  const char* hinge = option(info, "ladder.hinge");
  const char* text = option(info, "ladder.end_radius");
  if (!hinge || !text) return 0;
  const std::string_view kind(hinge);
  if (kind.substr(0, kind.find('\n')) != "rolling") return 0;
  char* end = nullptr;
  const double r = std::strtod(text, &end);
  // The server holds r within [0, thickness / 2]; a SceneInfo from elsewhere is held there too (the options print
  // r to three digits, which may put a fully rounded end a hair past half the thickness).
  if (end == text || !std::isfinite(r) || !(r > 0) || !(info.thickness > 0)) return 0;
  return std::min(r, 0.5 * info.thickness);
}

std::array<Point, 4> outline(const client::SceneInfo& info, const client::Pose& pose) {
  const double hw = 0.5 * info.thickness, hl = 0.5 * info.length;
  std::array<Point, 4> o = {Point{-hw, -hl}, Point{hw, -hl}, Point{hw, hl}, Point{-hw, hl}};
  for (Point& p : o) {
    const Point r = rotate(pose.theta, p);
    p = {pose.x + r.x, pose.y + r.y};
  }
  return o;
}

Point hinge_particle(const client::SceneInfo& info, int block, int c, const client::Pose& pose) {
  return hinge_particle(info, end_radius_of(info), block, c, pose);
}

Point hinge_particle(const client::SceneInfo& info, double r, int block, int c, const client::Pose& pose) {
  // As the core places them (server/ladder/ladder.cpp, corner_local): the corners, or the arc centres r in from
  // both edges.
  const double w = (0.5 - info.hinge_inset) * info.thickness - r, l = 0.5 * info.length - r;
  const bool low = ((c & 1) == 0) == (block % 2 == 0);
  const Point q = rotate(pose.theta, {(c & 2) ? -w : w, low ? -l : l});
  return {pose.x + q.x, pose.y + q.y};
}

Point pivot(const client::SceneInfo& info, const client::State& state, int hinge) {
  return pivot(info, end_radius_of(info), state, hinge);
}

Point pivot(const client::SceneInfo& info, double r, const client::State& state, int hinge) {
  const auto k = static_cast<std::size_t>(hinge);
  const int c = state.hinges[k].corner;
  const Point below = hinge_particle(info, r, hinge, c, state.blocks[k]);
  if (r <= 0) return below;  // the two blocks' corners are one point: the one always drawn
  // Two equal arcs touching: their contact is halfway between their centres.
  const Point above = hinge_particle(info, r, hinge - 1, c, state.blocks[k - 1]);
  return {0.5 * (above.x + below.x), 0.5 * (above.y + below.y)};
}

Point to_block_frame(const client::Pose& pose, Point world) {
  return rotate(-pose.theta, {world.x - pose.x, world.y - pose.y});
}

int block_at(const client::SceneInfo& info, const client::State& state, Point world) {
  const double r = end_radius_of(info);
  int found = -1;
  for (std::size_t i = 0; i < state.blocks.size(); ++i)
    if (in_rounded_outline(info, r, to_block_frame(state.blocks[i], world))) found = static_cast<int>(i);
  return found;
}

int tapes_on(const client::State& state, int block, int sign) {
  const std::size_t n = std::min(state.blocks.size(), state.hinges.size());
  for (const int k : {block, block + 1}) {
    if (k < 1 || static_cast<std::size_t>(k) >= n) continue;
    const client::Hinge& h = state.hinges[static_cast<std::size_t>(k)];
    if (h.status != ladder_msg_BROKEN && ((h.corner & 2) ? -1 : 1) == sign) return k;
  }
  return -1;
}

std::vector<double> tape_centres(int hinge, int block) {
  if (hinge == block + 1) return {-0.32, 0.32};  // the hinge below: the upper block of its pair
  return {0.0};
}

Pick pick(const Camera& cam, const client::SceneInfo& info, const client::State& state, Point s) {
  // The ray o + t u, u toward the viewer: the nearest box is the one it leaves last.
  const Rotation r(cam.yaw, cam.pitch);
  const double vx = (s.x - 0.5 * cam.width) / cam.scale, vy = -(s.y - 0.5 * cam.height) / cam.scale;
  const Vec3 o0 = r.inverse({vx, vy, 0}), u = r.inverse({0, 0, 1});
  const Vec3 o{cam.cx + o0.x, cam.cy + o0.y, o0.z};
  const double half[3] = {0.5 * info.thickness, 0.5 * info.length, 0.5 * depth_of(info)};
  const double radius = end_radius_of(info);
  Pick best;
  double best_t = -std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < state.blocks.size(); ++i) {
    const client::Pose& p = state.blocks[i];
    const Point lo = rotate(-p.theta, {o.x - p.x, o.y - p.y}), lu = rotate(-p.theta, {u.x, u.y});
    const double origin[3] = {lo.x, lo.y, o.z}, dir[3] = {lu.x, lu.y, u.z};
    double t0 = -std::numeric_limits<double>::infinity(), t1 = std::numeric_limits<double>::infinity();
    // A box: three slabs. With rounded ends: the slab across the depth, then the rounded outline in the block's plane.
    for (int a = radius > 0 ? 2 : 0; a < 3 && t0 <= t1; ++a) {
      if (std::abs(dir[a]) < 1e-12) {
        if (std::abs(origin[a]) > half[a]) t0 = std::numeric_limits<double>::infinity();
        continue;
      }
      double ta = (-half[a] - origin[a]) / dir[a], tb = (half[a] - origin[a]) / dir[a];
      if (ta > tb) std::swap(ta, tb);
      t0 = std::max(t0, ta);
      t1 = std::min(t1, tb);
    }
    if (double a = 0, b = 0; radius > 0 && t0 <= t1) {
      if (!rounded_interval(info, radius, lo, lu, a, b)) continue;
      t0 = std::max(t0, a);
      t1 = std::min(t1, b);
    }
    if (t0 > t1 || t1 <= best_t) continue;
    best_t = t1;
    const double mid = 0.5 * (t0 + t1);  // inside the (rounded) box: a point of the block's outline
    best = {static_cast<int>(i), {o.x + mid * u.x, o.y + mid * u.y}};
  }
  return best;
}

Vec3 hand_centre(const client::SceneInfo& info, const client::Pose& top) {
  return {top.x, top.y, 0.5 * depth_of(info) + 0.15 * depth_of(info)};
}

Camera fit(const client::SceneInfo& info, const client::State& state, int width, int height, int max_blocks,
           double yaw, double pitch) {
  Camera cam;
  cam.width = width;
  cam.height = height;
  cam.yaw = yaw;
  cam.pitch = pitch;
  cam.cx = cam.cy = 0;
  const std::size_t n = std::min(state.blocks.size(), static_cast<std::size_t>(std::max(1, max_blocks)));
  if (n == 0) return cam;
  double lo_x = std::numeric_limits<double>::infinity(), lo_y = lo_x, hi_x = -lo_x, hi_y = -lo_x;
  const Camera at_origin = cam;
  const View v(at_origin, info);
  const auto extend = [&](Vec3 w) {
    const Vec3 p = at_origin.to_view(w);
    lo_x = std::min(lo_x, p.x);
    hi_x = std::max(hi_x, p.x);
    lo_y = std::min(lo_y, p.y);
    hi_y = std::max(hi_y, p.y);
  };
  for (std::size_t i = 0; i < n; ++i) {
    const Box b = v.block(state.blocks[i]);
    for (int c = 0; c < 8; ++c) extend(b.corner(c & 1 ? 1 : -1, c & 2 ? 1 : -1, c & 4 ? 1 : -1));
  }
  // A ladder hanging from a held or pinned top block is framed with the room its blocks sweep as a ripple runs down
  // (a block turns about a hinge on the ladder's line: a length and a thickness to each side; below, a block's
  // diagonal a block, the longest the hinges' pitch can be), so that the frame keeps its scale before a tip, during it
  // and after (two snapshots for a handout were framed differently: 1653 and 1436 px/m). Its centre may still move,
  // by up to a thickness (9 mm of the classic ladder's 13 in View.PngBeforeAndAfterATip...: not traced further).
  if ((info.top == "held" || info.top == "pinned") && std::isfinite(info.length) && std::isfinite(info.thickness)) {
    const client::Pose& top = state.blocks[0];
    const double side = info.length + info.thickness, half_depth = 0.5 * depth_of(info);
    const double up = top.y + 0.5 * info.length + info.thickness;
    const double hinge_pitch = std::hypot(info.length, info.thickness);
    const double down = top.y - (static_cast<double>(n) - 0.5) * hinge_pitch - info.thickness;
    for (const double x : {top.x - side, top.x + side})
      for (const double y : {up, down})
        for (const double z : {-half_depth, half_depth}) extend({x, y, z});
  }
  // 10 % margin on every side; never so close that a block is bigger than the image.
  const double span_x = std::max(hi_x - lo_x, info.length), span_y = std::max(hi_y - lo_y, info.length);
  cam.scale = 0.8 * std::min(width / span_x, height / span_y);
  // The target: the point of z = 0 that the middle of those bounds is in front of.
  const Point w = on_plane(v.rot, 0.5 * (lo_x + hi_x), 0.5 * (lo_y + hi_y));
  cam.cx = w.x;
  cam.cy = w.y;
  // Blocks spread beyond what a double spans (1e308 m apart: a peer's state, not a ladder) leave the bounds infinite:
  // then a view of the origin at a block's size, rather than a scale of 0 or NaN.
  if (!(std::isfinite(cam.scale) && cam.scale > 0 && std::isfinite(cam.cx) && std::isfinite(cam.cy))) {
    cam.scale = std::isfinite(info.length) && info.length > 0 ? 0.2 * std::min(width, height) / info.length : 1;
    cam.cx = cam.cy = 0;
  }
  return cam;
}

void draw_empty(cairo_t* cr, const Camera& camera, const Hud& hud) {
  set_colour(cr, kBackground);
  cairo_paint(cr);
  Hud h = hud;
  h.scale_bar = false;
  draw_hud(cr, camera, h, nullptr);
}

int draw(cairo_t* cr, const Camera& camera, const client::SceneInfo& info, const client::State& state,
         const Hud& hud) {
  set_colour(cr, kBackground);
  cairo_paint(cr);
  const View v(camera, info);
  int drawn = 0;
  std::vector<char> shown(state.blocks.size());
  for (std::size_t i = 0; i < state.blocks.size(); ++i) shown[i] = v.visible(state.blocks[i]);
  if (v.length_px < 3) {
    // Level of detail: blocks of a few pixels are a line.
    draw_chain(cr, v, state.blocks);
    drawn = static_cast<int>(std::count(shown.begin(), shown.end(), 1));
  } else {
    // Back to front (painter's order): blocks are disjoint boxes, so the order of their centres' depths will do.
    std::vector<std::pair<double, int>> order;
    for (std::size_t i = 0; i < state.blocks.size(); ++i)
      if (shown[i]) order.emplace_back(v.view_depth({state.blocks[i].x, state.blocks[i].y, 0}), static_cast<int>(i));
    std::sort(order.begin(), order.end());
    // Square corners keep the plain box: the pictures of corner-hinge scenes stay what they were, and cost less.
    std::vector<Facet> facets;  // one block's rounded outline at a time
    for (const auto& [depth, i] : order) {
      if (v.r > 0)
        draw_rounded_block(cr, v, state, i, v.length_px >= 12, facets);
      else
        draw_block(cr, v, state, i, v.length_px >= 12);
    }
    drawn = static_cast<int>(order.size());
    if (v.r > 0 && camera.side() && v.length_px >= 12) draw_tape_lines(cr, v, state, shown, facets);
    if (info.top == "held" && !state.blocks.empty() && shown[0]) draw_hand(cr, v, state.blocks[0]);
    if (hud.marks && v.length_px >= 12) draw_hinges(cr, v, state, shown);
    if (hud.numbers && v.length_px >= 12) draw_numbers(cr, v, state, shown);
  }
  if (hud.marks) draw_grips(cr, v, state);
  draw_hud(cr, camera, hud, &state);
  return drawn;
}

std::vector<Mark> marks(const Camera& camera, const client::SceneInfo& info, const client::State& s) {
  const View v(camera, info);
  const double front = v.towards_viewer({0, 0, 1}) >= 0 ? 0.5 * v.depth : -0.5 * v.depth;  // as draw_hinges()
  std::vector<Mark> out;
  for (std::size_t k = 1; k < s.blocks.size() && k < s.hinges.size(); ++k) {
    const client::Hinge& h = s.hinges[k];
    const int ki = static_cast<int>(k);
    if (h.status == ladder_msg_BROKEN) {
      for (const int b : {ki, ki - 1}) {
        const Point p = hinge_particle(v.info, v.r, b, h.corner, s.blocks[static_cast<std::size_t>(b)]);
        out.push_back({v.screen({p.x, p.y, front}), 'x'});
      }
      continue;
    }
    // A plain hinge only where blocks are a few pixels long: on a long ladder seen whole, one a row would hide it.
    if (h.status != ladder_msg_LOCKED && v.length_px < 4) continue;
    const Point p = pivot(v.info, v.r, s, ki);
    out.push_back({v.screen({p.x, p.y, front}), h.status == ladder_msg_LOCKED ? '@' : 'o'});
  }
  for (const ladder_msg_Grip& g : s.grips)
    if (g.block >= 0 && static_cast<std::size_t>(g.block) < s.blocks.size())
      out.push_back({v.cam.to_screen({g.target_x, g.target_y}), '*'});
  return out;
}

std::string write_png(cairo_surface_t* surface, const std::string& path) {
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) return std::strerror(errno);
  const auto put = [](void* file, const unsigned char* data, unsigned int length) {
    return std::fwrite(data, 1, length, static_cast<std::FILE*>(file)) == length ? CAIRO_STATUS_SUCCESS
                                                                                  : CAIRO_STATUS_WRITE_ERROR;
  };
  const cairo_status_t st = cairo_surface_write_to_png_stream(surface, put, f);
  int why = errno;
  struct stat file {};
  const bool regular = fstat(fileno(f), &file) == 0 && S_ISREG(file.st_mode);
  if (st != CAIRO_STATUS_SUCCESS && regular) (void)!ftruncate(fileno(f), 0);  // (nothing half-written through a link)
  errno = 0;
  const bool closed = std::fclose(f) == 0;
  if (st == CAIRO_STATUS_SUCCESS && closed) return {};
  if (st == CAIRO_STATUS_SUCCESS) why = errno;  // (a small picture fails only when the buffer is flushed, at fclose)
  // No half-written picture left behind; but only a file of ours is removed, never what the path names through a
  // link nor a device: --png /dev/full, run as root, removed the device (a later write then made /dev/full a plain
  // file, and every program that relied on it being full was misled).
  struct stat named {};
  if (regular && lstat(path.c_str(), &named) == 0 && S_ISREG(named.st_mode)) std::remove(path.c_str());
  return st == CAIRO_STATUS_WRITE_ERROR || !closed ? std::string(std::strerror(why ? why : EIO))
                                                   : std::string(cairo_status_to_string(st));
}

bool clip_to_image(const Camera& cam, double margin, Point& a, Point& b) {
  double t0 = 0, t1 = 1;
  const double dx = b.x - a.x, dy = b.y - a.y;
  const auto edge = [&](double p, double q) {  // inside where p t <= q
    if (p == 0) return q >= 0;
    const double t = q / p;
    if (p < 0) t0 = std::max(t0, t);
    else t1 = std::min(t1, t);
    return t0 <= t1;
  };
  if (!(edge(-dx, a.x + margin) && edge(dx, cam.width + margin - a.x) && edge(-dy, a.y + margin) &&
        edge(dy, cam.height + margin - a.y)))
    return false;
  const Point from = a;
  a = {from.x + t0 * dx, from.y + t0 * dy};
  b = {from.x + t1 * dx, from.y + t1 * dy};
  return std::isfinite(a.x) && std::isfinite(a.y) && std::isfinite(b.x) && std::isfinite(b.y);
}

}  // namespace ladder::view
