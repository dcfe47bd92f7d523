// The two plots a teacher wants of a session, drawn with Cairo: the ripple's front (each flip-flop as a dot, its
// hinge against the sim time it happened: a ripple running down is a rising line of dots) and the energy against sim
// time. The window shows them on a key (p); `ladderctl plot` writes them as a PNG from a running or recorded session.
#pragma once

#include "draw.hpp"

#include <cairo.h>

#include <cstdint>
#include <string>
#include <vector>

namespace ladder::view {

// What the plots show, gathered state by state. Bounded: past kMaxPoints of either series, every other point of
// it is dropped (the plot keeps its shape, at half the resolution).
class History {
 public:
  static constexpr std::size_t kMaxPoints = 20000;
  // A state's sim time, energy and flip-flop counts (one per hinge): its energy, and a flip-flop at each hinge whose
  // count went up since the previous state (at this state's time). A state of another generation, or from before
  // the previous one (a reset or a new scene), starts the history again.
  void add(std::uint32_t generation, double t, double energy, const std::vector<std::uint32_t>& flips);
  const std::vector<Point>& energy() const { return energy_; }  // (t [s], E [J])
  const std::vector<Point>& flips() const { return flips_; }    // (t [s], hinge)
  int hinges() const { return hinges_; }
  // How many times the history started: 1 after the first state, one more for each start again.
  int runs() const { return runs_; }

 private:
  std::vector<Point> energy_, flips_;
  std::vector<std::uint32_t> last_;
  std::uint32_t generation_ = 0;
  double last_t_ = -1;
  int hinges_ = 0, runs_ = 0;
};

// A plot's frame: the data range and the pixel box it maps to.
struct Axes {
  double x = 0, y = 0, w = 0, h = 0;   // [px] the plotting area (inside the labels)
  double t0 = 0, t1 = 1, v0 = 0, v1 = 1;
  // (In halves: a range of energies from -1.7e308 to 1.7e308 J, finite, is not one a double holds.)
  Point at(double t, double v) const {
    return {x + (0.5 * t - 0.5 * t0) / (0.5 * t1 - 0.5 * t0) * w,
            y + h - (0.5 * v - 0.5 * v0) / (0.5 * v1 - 0.5 * v0) * h};
  }
};
// The two frames of plots drawn in the box (x, y, w, h): the ripple's front on top, the energy below.
std::array<Axes, 2> plot_axes(const History& h, double x, double y, double w, double h_px);

// Where an axis from lo to hi is ticked: the multiples of 1, 2 or 5 times a power of ten within it, the finest step
// that gives at most `most` ticks (with `whole`, a step of 1 at least: hinges). None when the range is empty or not
// finite.
std::vector<double> nice_ticks(double lo, double hi, int most, bool whole = false);

inline constexpr Rgb kFlipDot{250, 210, 60};
inline constexpr Rgb kFrame{115, 120, 133};  // the frames and their ticks
inline constexpr Rgb kEnergyLine{110, 200, 250};

// Draws both plots in the box, on a dark panel, their axes ticked and labelled (nice_ticks).
void draw_plots(cairo_t* cr, const History& h, double x, double y, double w, double h_px);
// Both plots alone on a w x h picture, written as a PNG; "" when written, else why not.
std::string write_plots_png(const History& h, const std::string& path, int w, int h_px);

}  // namespace ladder::view
