// The outline of a block with rounded ends (a rolling hinge's, docs/model.md section 9) in the block's own frame, as
// the drawing module draws it and picks it: the four flat sides and an arc of radius r at each corner, each arc cut
// into straight facets, and which tapes lie on each piece. No Cairo here: geometry only.
//
// The tapes, as on the 1889 toy whose tapes wrap its rounded ends in a figure-8: hinge k's tapes on a block run along
// its wide face on the hinge's side (tapes_on(), as for corner hinges) and over the hinge's arc to the contact point
// (pivot()); there they cross to the other block and wrap the rest of its end: its hinge arc beyond the contact, its
// flat end, and the arc at that end's other corner, up to its other wide face. So at the contact point one block's
// tapes leave its arc for the other's, and the other's tapes come the other way: the tapes cross there.
#pragma once

#include "draw.hpp"

#include <vector>

namespace ladder::view {

// One straight piece of the outline, in the block's frame (x across the thickness, y along the length, origin at the
// centre).
struct Facet {
  Point a, b;       // its ends, counter-clockwise round the block
  Point normal;     // outward, unit
  bool wide = true;  // nearer a wide face (normal +-x) than an end (+-y): drawn in the wide face's colour
  int hinge = -1;   // the tapes on it are tape_centres(hinge, owner); -1: none
  int owner = -1;
};

// Block `block`'s outline with ends rounded by r (0 < r <= thickness / 2), counter-clockwise from the start of the
// arc at its (+x, +y) corner, `segments` facets to a quarter arc (one more where a contact point cuts an arc), the
// tapes on each facet as above. Flat pieces of zero length (the ends when r = thickness / 2) are left out.
void rounded_outline(const client::SceneInfo& info, const client::State& state, int block, double r, int segments,
                     std::vector<Facet>& out);

// Whether a point of the block's frame lies in its outline (the rectangle with its corners rounded by r >= 0).
bool in_rounded_outline(const client::SceneInfo& info, double r, Point local);

// The parameters t for which o + t d (block frame) lies in the outline: [t0, t1], or false. A ray with d = 0 lies in
// it for every t or none.
bool rounded_interval(const client::SceneInfo& info, double r, Point o, Point d, double& t0, double& t1);

}  // namespace ladder::view
