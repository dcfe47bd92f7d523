#include "draw.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <utility>

namespace ladder::view {

namespace {

// The blocks have depth: the real toy's are about half as deep as they are long. An oblique projection shows the
// back face up and to the right of the front one; this is that offset in world units per unit of depth.
constexpr Point kDepthDir{0.34, 0.22};

Point depth_offset(const client::SceneInfo& info) {
  const double d = 0.5 * info.length;
  return {kDepthDir.x * d, kDepthDir.y * d};
}

Point rotate(double theta, Point p) {
  const double c = std::cos(theta), s = std::sin(theta);
  return {c * p.x - s * p.y, s * p.x + c * p.y};
}

void set_colour(cairo_t* cr, Rgb c, double alpha = 1) {
  cairo_set_source_rgba(cr, c.r / 255.0, c.g / 255.0, c.b / 255.0, alpha);
}

void polygon(cairo_t* cr, const Point* p, int n) {
  cairo_move_to(cr, p[0].x, p[0].y);
  for (int i = 1; i < n; ++i) cairo_line_to(cr, p[i].x, p[i].y);
  cairo_close_path(cr);
}

// Which blocks to draw, and at what level of detail. A block is on screen when its bounding circle (grown by the
// depth offset) meets the image.
struct View {
  const Camera& cam;
  const client::SceneInfo& info;
  double radius_px;  // bounding circle of a block and its depth
  double length_px;  // a block's length on screen

  View(const Camera& c, const client::SceneInfo& i)
      : cam(c), info(i), radius_px((0.5 * std::hypot(i.length, i.thickness) + std::hypot(depth_offset(i).x,
                                                                                         depth_offset(i).y)) *
                                   c.scale),
        length_px(i.length * c.scale) {}

  bool visible(const client::Pose& p) const {
    const Point s = cam.to_screen({p.x, p.y});
    return s.x > -radius_px && s.x < cam.width + radius_px && s.y > -radius_px && s.y < cam.height + radius_px;
  }
  Point screen(Point w) const { return cam.to_screen(w); }
};

// Far away, a block is a few pixels: the ladder is drawn as one polyline through the centres.
void draw_chain(cairo_t* cr, const View& v, const std::vector<client::Pose>& blocks) {
  cairo_set_line_width(cr, std::max(1.0, v.info.thickness * v.cam.scale));
  cairo_set_line_cap(cr, CAIRO_LINE_CAP_ROUND);
  bool open = false;
  for (const client::Pose& p : blocks) {
    if (!v.visible(p)) {
      open = false;
      continue;
    }
    const Point s = v.screen({p.x, p.y});
    if (open)
      cairo_line_to(cr, s.x, s.y);
    else
      cairo_move_to(cr, s.x, s.y);
    open = true;
  }
  set_colour(cr, kFaceEven);
  cairo_stroke(cr);
}

// The sides seen in depth: the back face and the four faces swept by the edges, all behind every front face.
void draw_depth(cairo_t* cr, const View& v, const std::array<Point, 4>& front) {
  const Point d = depth_offset(v.info);
  const Point off{d.x * v.cam.scale, -d.y * v.cam.scale};
  for (int e = 0; e < 4; ++e) {
    const Point a = front[e], b = front[(e + 1) % 4];
    Point q[4] = {a, b, {b.x + off.x, b.y + off.y}, {a.x + off.x, a.y + off.y}};
    // One winding for every quad: the fill rule (non-zero) would cut holes where opposite windings overlap.
    const double area = (b.x - a.x) * off.y - (b.y - a.y) * off.x;
    if (area < 0) std::swap(q[1], q[3]);
    polygon(cr, q, 4);
  }
}

std::array<Point, 4> screen_outline(const View& v, const client::Pose& p) {
  std::array<Point, 4> o = outline(v.info, p);
  for (Point& q : o) q = v.screen(q);
  return o;
}

// Ribbons (paper, Figure 3): hinge k with corner c wraps corner (k-1, c^1) -> (k, c) -> (k, c^1), along the two
// blocks' faces on the hinge's side. A broken hinge has no ribbon; seen from the front, the front outer ribbon
// hides the others, so that is the one drawn.
void draw_ribbons(cairo_t* cr, const View& v, const client::State& s, const std::vector<char>& shown) {
  cairo_set_line_width(cr, std::clamp(0.1 * v.info.thickness * v.cam.scale, 1.0, 4.0));
  cairo_set_line_join(cr, CAIRO_LINE_JOIN_ROUND);
  for (std::size_t k = 1; k < s.blocks.size() && k < s.hinges.size(); ++k) {
    const client::Hinge& h = s.hinges[k];
    if (h.status == ladder_msg_BROKEN || !(shown[k - 1] || shown[k])) continue;
    const int c = h.corner, ki = static_cast<int>(k);
    const Point a = v.screen(hinge_particle(v.info, ki - 1, c ^ 1, s.blocks[k - 1]));
    const Point m = v.screen(hinge_particle(v.info, ki, c, s.blocks[k]));
    const Point b = v.screen(hinge_particle(v.info, ki, c ^ 1, s.blocks[k]));
    cairo_move_to(cr, a.x, a.y);
    cairo_line_to(cr, m.x, m.y);
    cairo_line_to(cr, b.x, b.y);
  }
  set_colour(cr, kRibbon);
  cairo_stroke(cr);
}

// Hinge points: white when hinged; a locked pair gets a red dot and red outlines; a broken hinge a grey cross on
// each of its two particles.
void draw_hinges(cairo_t* cr, const View& v, const client::State& s, const std::vector<char>& shown) {
  const double r = std::clamp(0.15 * v.info.thickness * v.cam.scale, 1.5, 5.0);
  for (std::size_t k = 1; k < s.blocks.size() && k < s.hinges.size(); ++k) {
    if (!(shown[k - 1] || shown[k])) continue;
    const client::Hinge& h = s.hinges[k];
    const int ki = static_cast<int>(k);
    const Point p = v.screen(hinge_particle(v.info, ki, h.corner, s.blocks[k]));
    if (h.status == ladder_msg_BROKEN) {
      const Point q = v.screen(hinge_particle(v.info, ki - 1, h.corner, s.blocks[k - 1]));
      set_colour(cr, kBroken);
      cairo_set_line_width(cr, 1.5);
      for (const Point& x : {p, q}) {
        cairo_move_to(cr, x.x - r, x.y - r);
        cairo_line_to(cr, x.x + r, x.y + r);
        cairo_move_to(cr, x.x - r, x.y + r);
        cairo_line_to(cr, x.x + r, x.y - r);
      }
      cairo_stroke(cr);
      continue;
    }
    if (h.status == ladder_msg_LOCKED) {
      // The pair moves as one: both outlines in red (clear of the centres, where a test samples the faces).
      set_colour(cr, kLocked);
      cairo_set_line_width(cr, std::max(1.0, 0.4 * r));
      for (std::size_t i : {k - 1, k}) {
        const std::array<Point, 4> o = screen_outline(v, s.blocks[i]);
        polygon(cr, o.data(), 4);
      }
      cairo_stroke(cr);
    }
    set_colour(cr, h.status == ladder_msg_LOCKED ? kLocked : kHinge);
    cairo_arc(cr, p.x, p.y, h.status == ladder_msg_LOCKED ? 1.5 * r : r, 0, 2 * M_PI);
    cairo_fill(cr);
  }
}

// A user's hand: a ring at the grip's target and a dashed line to the block it holds.
void draw_grips(cairo_t* cr, const View& v, const client::State& s) {
  for (const ladder_msg_Grip& g : s.grips) {
    if (g.block < 0 || static_cast<std::size_t>(g.block) >= s.blocks.size()) continue;
    const Point t = v.screen({g.target_x, g.target_y});
    const Point b = v.screen({s.blocks[g.block].x, s.blocks[g.block].y});
    set_colour(cr, kGrip);
    cairo_set_line_width(cr, 2);
    const double dash[] = {4, 3};
    cairo_set_dash(cr, dash, 2, 0);
    cairo_move_to(cr, b.x, b.y);
    cairo_line_to(cr, t.x, t.y);
    cairo_stroke(cr);
    cairo_set_dash(cr, nullptr, 0, 0);
    cairo_arc(cr, t.x, t.y, 6, 0, 2 * M_PI);
    cairo_stroke(cr);
  }
}

void draw_text_box(cairo_t* cr, double x, double y, double size, const std::vector<std::string>& lines) {
  if (lines.empty()) return;
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

void draw_hud(cairo_t* cr, const Camera& cam, const Hud& hud, const client::State* s) {
  if (hud.show) {
    std::vector<std::string> top;
    char buf[160];
    if (s) {
      char rtf[32] = "-";
      if (hud.real_time_factor >= 0) std::snprintf(rtf, sizeof rtf, "%.2f", hud.real_time_factor);
      std::snprintf(buf, sizeof buf, "%s  t = %.3f s  real-time x%s%s", hud.title.c_str(), s->sim_time, rtf,
                    s->paused ? "  PAUSED" : "");
      top.emplace_back(buf);
    } else {
      top.push_back(hud.title);
    }
    if (hud.stats) top.insert(top.end(), hud.lines.begin(), hud.lines.end());
    draw_text_box(cr, 10, 10, 14, top);
  }
  if (!hud.banner.empty()) {
    cairo_select_font_face(cr, "DejaVu Sans", CAIRO_FONT_SLANT_NORMAL, CAIRO_FONT_WEIGHT_BOLD);
    cairo_set_font_size(cr, 20);
    cairo_text_extents_t e;
    cairo_text_extents(cr, hud.banner.c_str(), &e);
    draw_text_box(cr, 0.5 * (cam.width - e.x_advance), 0.5 * cam.height - 10, 20, {hud.banner});
  }
}

}  // namespace

void Camera::zoom_about(Point s, double factor) {
  const Point w = to_world(s);
  scale *= factor;
  const Point after = to_world(s);
  cx += w.x - after.x;
  cy += w.y - after.y;
}

Rgb face_colour(int block) { return block % 2 == 0 ? kFaceEven : kFaceOdd; }

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
  const double w = (0.5 - info.hinge_inset) * info.thickness;
  const bool low = ((c & 1) == 0) == (block % 2 == 0);
  const Point r = rotate(pose.theta, {(c & 2) ? -w : w, low ? -0.5 * info.length : 0.5 * info.length});
  return {pose.x + r.x, pose.y + r.y};
}

Point to_block_frame(const client::Pose& pose, Point world) {
  return rotate(-pose.theta, {world.x - pose.x, world.y - pose.y});
}

int block_at(const client::SceneInfo& info, const client::State& state, Point world) {
  int found = -1;
  for (std::size_t i = 0; i < state.blocks.size(); ++i) {
    const Point l = to_block_frame(state.blocks[i], world);
    if (std::abs(l.x) <= 0.5 * info.thickness && std::abs(l.y) <= 0.5 * info.length) found = static_cast<int>(i);
  }
  return found;
}

Camera fit(const client::SceneInfo& info, const client::State& state, int width, int height, int max_blocks) {
  Camera cam;
  cam.width = width;
  cam.height = height;
  double lo_x = std::numeric_limits<double>::infinity(), lo_y = lo_x, hi_x = -lo_x, hi_y = -lo_x;
  const Point d = depth_offset(info);
  const std::size_t n = std::min(state.blocks.size(), static_cast<std::size_t>(std::max(1, max_blocks)));
  for (std::size_t i = 0; i < n; ++i)
    for (const Point& p : outline(info, state.blocks[i]))
      for (const Point& q : {p, Point{p.x + d.x, p.y + d.y}}) {
        lo_x = std::min(lo_x, q.x);
        hi_x = std::max(hi_x, q.x);
        lo_y = std::min(lo_y, q.y);
        hi_y = std::max(hi_y, q.y);
      }
  if (n == 0) return cam;
  // 10 % margin on every side; never so close that a block is bigger than the image.
  const double span_x = std::max(hi_x - lo_x, info.length), span_y = std::max(hi_y - lo_y, info.length);
  cam.scale = 0.8 * std::min(width / span_x, height / span_y);
  cam.cx = 0.5 * (lo_x + hi_x);
  cam.cy = 0.5 * (lo_y + hi_y);
  return cam;
}

void draw_empty(cairo_t* cr, const Camera& camera, const Hud& hud) {
  set_colour(cr, kBackground);
  cairo_paint(cr);
  draw_hud(cr, camera, hud, nullptr);
}

int draw(cairo_t* cr, const Camera& camera, const client::SceneInfo& info, const client::State& state,
         const Hud& hud) {
  set_colour(cr, kBackground);
  cairo_paint(cr);
  const View v(camera, info);
  int drawn = 0;
  if (v.length_px < 3) {
    // Level of detail: blocks of a few pixels are a line.
    draw_chain(cr, v, state.blocks);
    for (const client::Pose& p : state.blocks) drawn += v.visible(p);
  } else {
    std::vector<char> shown(state.blocks.size());
    for (std::size_t i = 0; i < state.blocks.size(); ++i) shown[i] = v.visible(state.blocks[i]);
    // Depth first, all of it, so that no block's sides cover another's front face.
    if (v.length_px >= 6) {
      for (std::size_t i = 0; i < state.blocks.size(); ++i)
        if (shown[i]) draw_depth(cr, v, screen_outline(v, state.blocks[i]));
      set_colour(cr, kDepth);
      cairo_fill(cr);
    }
    // Front faces, one colour per parity (a path per colour keeps it to two fills).
    for (int parity = 0; parity < 2; ++parity) {
      for (std::size_t i = parity; i < state.blocks.size(); i += 2) {
        if (!shown[i]) continue;
        const std::array<Point, 4> o = screen_outline(v, state.blocks[i]);
        polygon(cr, o.data(), 4);
        ++drawn;
      }
      set_colour(cr, face_colour(parity));
      cairo_fill(cr);
    }
    if (v.length_px >= 12) {
      draw_ribbons(cr, v, state, shown);
      draw_hinges(cr, v, state, shown);
    }
  }
  draw_grips(cr, v, state);
  draw_hud(cr, camera, hud, &state);
  return drawn;
}

}  // namespace ladder::view
