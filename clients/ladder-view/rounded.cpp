#include "rounded.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace ladder::view {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// Where corner c of `block` is (server/ladder/ladder.cpp, corner_local): side +1 for corners 0 and 1 (the +x side),
// end -1 at the low end (-y): corner 0 is at the low end of even blocks and the high end of odd ones.
int side_of(int c) { return (c & 2) ? -1 : 1; }
int end_of(int block, int c) { return ((c & 1) == 0) == (block % 2 == 0) ? -1 : 1; }

// A hinge at one end of a block: the corner whose arc carries it, and how far along that arc (0 at the wide face, 1
// at the end) the contact point lies.
struct EndHinge {
  int k, other;    // the hinge, and the block on its other side
  int side, end;
  double contact;  // [0, 1]
};

// The block's hinges that carry tapes (not broken), with their contact points. The contact is the pivot, halfway
// between the two blocks' arc centres; seen from this block's arc centre, its direction gives the place on the arc.
// A pair bent past the arc's ends (a forged state) has it clamped to them.
int end_hinges(const client::SceneInfo& info, const client::State& s, int block, double r, EndHinge out[2]) {
  const int n = static_cast<int>(std::min(s.blocks.size(), s.hinges.size()));
  int count = 0;
  for (const int k : {block, block + 1}) {
    if (k < 1 || k >= n || s.hinges[static_cast<std::size_t>(k)].status == ladder_msg_BROKEN) continue;
    const int c = s.hinges[static_cast<std::size_t>(k)].corner;
    const int side = side_of(c), end = end_of(block, c);
    const Point centre{side * (0.5 * info.thickness - r), end * (0.5 * info.length - r)};
    const Point p = to_block_frame(s.blocks[static_cast<std::size_t>(block)], pivot(info, r, s, k));
    // The angle from the wide face's normal (side, 0) toward the end's (0, end).
    const double a = std::atan2(end * (p.y - centre.y), side * (p.x - centre.x));
    out[count++] = {k, k == block ? block - 1 : block + 1, side, end, std::clamp(a / (0.5 * M_PI), 0.0, 1.0)};
  }
  return count;
}

void slab(double o, double d, double half, double& t0, double& t1) {
  if (std::abs(d) < 1e-12) {
    if (std::abs(o) > half) t0 = kInf;
    return;
  }
  double ta = (-half - o) / d, tb = (half - o) / d;
  if (ta > tb) std::swap(ta, tb);
  t0 = std::max(t0, ta);
  t1 = std::min(t1, tb);
}

}  // namespace

void rounded_outline(const client::SceneInfo& info, const client::State& state, int block, double r, int segments,
                     std::vector<Facet>& out) {
  out.clear();
  const double hw = 0.5 * info.thickness, hl = 0.5 * info.length;
  EndHinge hinges[2];
  const int nh = end_hinges(info, state, block, r, hinges);
  // Whose tapes lie at fraction u (0 at the wide face, 1 at the end) of the arc at corner (sx, sy): a hinge's own
  // up to its contact point, the other block's beyond it; at the end's other corner, the other block's.
  const auto arc_tapes = [&](int sx, int sy, double u, Facet& f) {
    for (int i = 0; i < nh; ++i)
      if (hinges[i].side == sx && hinges[i].end == sy) {
        f.hinge = hinges[i].k;
        f.owner = u < hinges[i].contact ? block : hinges[i].other;
        return;
      }
    for (int i = 0; i < nh; ++i)
      if (hinges[i].side == -sx && hinges[i].end == sy) {
        f.hinge = hinges[i].k;
        f.owner = hinges[i].other;
        return;
      }
  };
  const auto flat = [&](Point a, Point b, Point normal) {
    if (std::hypot(b.x - a.x, b.y - a.y) <= 0) return;
    Facet f{a, b, normal, normal.y == 0};
    if (f.wide) {
      if (const int h = tapes_on(state, block, normal.x > 0 ? 1 : -1); h >= 0) f.hinge = h, f.owner = block;
    } else {
      for (int i = 0; i < nh && f.hinge < 0; ++i)
        if (hinges[i].end == (normal.y > 0 ? 1 : -1)) f.hinge = hinges[i].k, f.owner = hinges[i].other;
    }
    out.push_back(f);
  };
  // The quarter arc at corner (sx, sy), counter-clockwise: it starts on the wide face at (+,+) and (-,-), on the end
  // at the other two. Cut into `segments` facets, and at a contact point, so that each facet has one owner's tapes.
  const auto arc = [&](int sx, int sy) {
    const Point centre{sx * (hw - r), sy * (hl - r)};
    const Point d0 = sx == sy ? Point{double(sx), 0} : Point{0, double(sy)};  // the start's direction
    const Point d1{-d0.y, d0.x};
    const bool face_first = sx == sy;
    std::vector<double> cuts;  // fractions of the quarter, counter-clockwise
    for (int m = 0; m <= segments; ++m) cuts.push_back(double(m) / segments);
    for (int i = 0; i < nh; ++i)
      if (hinges[i].side == sx && hinges[i].end == sy) {
        const double f = face_first ? hinges[i].contact : 1 - hinges[i].contact;
        if (f > 1e-9 && f < 1 - 1e-9) cuts.push_back(f);
      }
    std::sort(cuts.begin(), cuts.end());
    cuts.erase(std::unique(cuts.begin(), cuts.end(), [](double a, double b) { return b - a < 1e-9; }), cuts.end());
    const auto dir = [&](double f) {
      const double c = std::cos(0.5 * M_PI * f), s = std::sin(0.5 * M_PI * f);
      return Point{c * d0.x + s * d1.x, c * d0.y + s * d1.y};
    };
    for (std::size_t m = 0; m + 1 < cuts.size(); ++m) {
      const Point a = dir(cuts[m]), b = dir(cuts[m + 1]), n = dir(0.5 * (cuts[m] + cuts[m + 1]));
      Facet f{{centre.x + r * a.x, centre.y + r * a.y}, {centre.x + r * b.x, centre.y + r * b.y}, n,
              std::abs(n.x) >= std::abs(n.y)};
      const double mid = 0.5 * (cuts[m] + cuts[m + 1]);
      arc_tapes(sx, sy, face_first ? mid : 1 - mid, f);
      out.push_back(f);
    }
  };
  arc(1, 1);
  flat({hw - r, hl}, {r - hw, hl}, {0, 1});
  arc(-1, 1);
  flat({-hw, hl - r}, {-hw, r - hl}, {-1, 0});
  arc(-1, -1);
  flat({r - hw, -hl}, {hw - r, -hl}, {0, -1});
  arc(1, -1);
  flat({hw, r - hl}, {hw, hl - r}, {1, 0});
}

bool in_rounded_outline(const client::SceneInfo& info, double r, Point l) {
  const double hw = 0.5 * info.thickness, hl = 0.5 * info.length;
  if (!(std::abs(l.x) <= hw && std::abs(l.y) <= hl)) return false;
  if (r <= 0) return true;
  const double dx = std::max(std::abs(l.x) - (hw - r), 0.0), dy = std::max(std::abs(l.y) - (hl - r), 0.0);
  return dx * dx + dy * dy <= r * r;
}

bool rounded_interval(const client::SceneInfo& info, double r, Point o, Point d, double& t0, double& t1) {
  const double hw = 0.5 * info.thickness, hl = 0.5 * info.length;
  // The outline is convex and the union of a cross of two rectangles and four discs at the arc centres: the line
  // meets it in one interval, the union of the pieces' intervals.
  double lo = kInf, hi = -kInf;
  const auto add = [&](double a, double b) {
    if (a > b) return;
    lo = std::min(lo, a);
    hi = std::max(hi, b);
  };
  for (const Point half : {Point{hw, hl - r}, Point{hw - r, hl}}) {
    double a = -kInf, b = kInf;
    slab(o.x, d.x, half.x, a, b);
    slab(o.y, d.y, half.y, a, b);
    add(a, b);
  }
  const double dd = d.x * d.x + d.y * d.y;
  for (const int sx : {-1, 1})
    for (const int sy : {-1, 1}) {
      if (r <= 0) break;
      const double ox = o.x - sx * (hw - r), oy = o.y - sy * (hl - r);
      const double c = ox * ox + oy * oy - r * r;
      if (dd < 1e-24) {
        if (c <= 0) add(-kInf, kInf);
        continue;
      }
      const double b = d.x * ox + d.y * oy, disc = b * b - dd * c;
      if (disc < 0) continue;
      const double q = std::sqrt(disc);
      add((-b - q) / dd, (-b + q) / dd);
    }
  if (lo > hi) return false;
  t0 = lo;
  t1 = hi;
  return true;
}

}  // namespace ladder::view
