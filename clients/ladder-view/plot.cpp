#include "plot.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <cstdio>

namespace ladder::view {

namespace {

constexpr double kTick = 4;  // [px] a tick mark

// Every other point dropped, the last one kept.
void halve(std::vector<Point>& v) {
  std::vector<Point> kept;
  kept.reserve(v.size() / 2 + 1);
  for (std::size_t i = 0; i < v.size(); i += 2) kept.push_back(v[i]);
  if (v.size() % 2 == 0) kept.push_back(v.back());
  v.swap(kept);
}

void text(cairo_t* cr, double x, double y, const std::string& s) {
  cairo_move_to(cr, x, y);
  cairo_show_text(cr, s.c_str());
}

std::string number(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.4g", v);
  return buf;
}

// A frame, its axes ticked and labelled (the values left, the times below, in seconds), and its title.
void frame(cairo_t* cr, const Axes& a, const std::string& title, const std::string& unit, bool whole) {
  cairo_set_source_rgb(cr, kFrame.r / 255.0, kFrame.g / 255.0, kFrame.b / 255.0);
  cairo_set_line_width(cr, 1);
  cairo_rectangle(cr, a.x + 0.5, a.y + 0.5, a.w, a.h);
  // (a ladder's hinges each ticked up to 8 of them)
  const std::vector<double> values = nice_ticks(a.v0, a.v1, whole ? 8 : 6, whole), times = nice_ticks(a.t0, a.t1, 6);
  for (const double v : values) {
    const double py = std::round(a.at(a.t0, v).y) + 0.5;
    cairo_move_to(cr, a.x - kTick, py);
    cairo_line_to(cr, a.x, py);
  }
  for (const double t : times) {
    const double px = std::round(a.at(t, a.v0).x) + 0.5;
    cairo_move_to(cr, px, a.y + a.h);
    cairo_line_to(cr, px, a.y + a.h + kTick);
  }
  cairo_stroke(cr);
  cairo_set_source_rgb(cr, 0.85, 0.86, 0.9);
  cairo_select_font_face(cr, "DejaVu Sans", CAIRO_FONT_SLANT_NORMAL, CAIRO_FONT_WEIGHT_NORMAL);
  cairo_set_font_size(cr, 11);
  text(cr, a.x, a.y - 5, title);
  cairo_text_extents_t e;
  for (const double v : values) {
    const std::string s = number(v);
    cairo_text_extents(cr, s.c_str(), &e);
    text(cr, a.x - kTick - 3 - e.x_advance, a.at(a.t0, v).y + 4, s);
  }
  for (const double t : times) {
    const std::string s = number(t);
    cairo_text_extents(cr, s.c_str(), &e);
    text(cr, a.at(t, a.v0).x - 0.5 * e.x_advance, a.y + a.h + kTick + 11, s);
  }
  text(cr, a.x + a.w + 4, a.y + a.h + kTick + 11, "s");
  text(cr, a.x + a.w - 7 * static_cast<double>(unit.size()), a.y - 5, unit);
}

}  // namespace

std::vector<double> nice_ticks(double lo, double hi, int most, bool whole) {
  std::vector<double> out;
  if (!(std::isfinite(lo) && std::isfinite(hi) && hi > lo) || most < 1) return out;
  const double rough = (hi - lo) / most, decade = std::pow(10, std::floor(std::log10(rough)));
  double step = 10 * decade;
  for (const double m : {5.0, 2.0, 1.0})
    if ((hi - lo) / (m * decade) <= most) step = m * decade;
  if (whole) step = std::max(step, 1.0);
  if (!(step > 0) || (hi - lo) / step > 1e3) return out;  // (a range past what a double resolves)
  for (double k = std::ceil(lo / step); k * step <= hi; ++k) out.push_back(k * step == 0 ? 0 : k * step);
  return out;
}

void History::add(std::uint32_t generation, double t, double energy, const std::vector<std::uint32_t>& flips) {
  if (runs_ == 0 || generation != generation_ || t < last_t_) {
    energy_.clear();
    flips_.clear();
    last_.clear();
    generation_ = generation;
    ++runs_;
  }
  last_t_ = t;
  if (!std::isfinite(energy)) return;
  energy_.push_back({t, energy});
  // One mark per hinge that flipped since the last state, however many times: its marks would all be the same point
  // (and a count that jumps by 4e9, from a forged or a restarted publisher, must not become 4e9 points).
  if (last_.size() == flips.size())
    for (std::size_t k = 1; k < flips.size(); ++k)
      if (flips[k] > last_[k]) flips_.push_back({t, static_cast<double>(k)});
  last_ = flips;
  hinges_ = static_cast<int>(flips.size()) - 1;
  if (energy_.size() > kMaxPoints) halve(energy_);
  if (flips_.size() > kMaxPoints) halve(flips_);
}

std::array<Axes, 2> plot_axes(const History& h, double x, double y, double w, double h_px) {
  double t0 = h.energy().empty() ? 0 : h.energy().front().x, t1 = h.energy().empty() ? 1 : h.energy().back().x;
  if (!(t1 > t0)) t1 = t0 + 1;
  double e0 = 0, e1 = 1;
  if (!h.energy().empty()) {
    const auto [lo, hi] = std::minmax_element(h.energy().begin(), h.energy().end(),
                                              [](const Point& a, const Point& b) { return a.y < b.y; });
    e0 = lo->y;
    e1 = hi->y;
    const double pad = std::max(0.1 * (0.5 * e1 - 0.5 * e0), 1e-9 * std::max(1.0, std::abs(e1)));
    constexpr double kMost = std::numeric_limits<double>::max();
    e0 = std::max(e0 - pad, -kMost);  // (finite even for a log's energies of +-1.7e308 J)
    e1 = std::min(e1 + pad, kMost);
  }
  // Room for the labels: 60 px left, 22 px above and below each plot.
  const double left = x + 60, width = std::max(10.0, w - 70), each = std::max(10.0, 0.5 * h_px - 44);
  return {Axes{left, y + 22, width, each, t0, t1, 0, std::max(1.0, static_cast<double>(h.hinges()) + 0.5)},
          Axes{left, y + 22 + each + 44, width, each, t0, t1, e0, e1}};
}

void draw_plots(cairo_t* cr, const History& h, double x, double y, double w, double h_px) {
  cairo_save(cr);
  cairo_set_source_rgba(cr, 0, 0, 0, 0.7);
  cairo_rectangle(cr, x, y, w, h_px);
  cairo_fill(cr);
  const auto [front, energy] = plot_axes(h, x, y, w, h_px);
  frame(cr, front, "ripple front: hinge of each flip-flop", "hinge", true);
  frame(cr, energy, "energy", "J", false);
  // Inside the frames only.
  cairo_set_source_rgb(cr, kFlipDot.r / 255.0, kFlipDot.g / 255.0, kFlipDot.b / 255.0);
  for (const Point& f : h.flips()) {
    const Point p = front.at(f.x, f.y);
    cairo_arc(cr, p.x, p.y, 3, 0, 2 * M_PI);
    cairo_fill(cr);
  }
  if (h.energy().size() > 1) {
    cairo_set_source_rgb(cr, kEnergyLine.r / 255.0, kEnergyLine.g / 255.0, kEnergyLine.b / 255.0);
    cairo_set_line_width(cr, 1.5);
    const Point p0 = energy.at(h.energy().front().x, h.energy().front().y);
    cairo_move_to(cr, p0.x, p0.y);
    for (const Point& e : h.energy()) {
      const Point p = energy.at(e.x, e.y);
      cairo_line_to(cr, p.x, p.y);
    }
    cairo_stroke(cr);
  }
  cairo_restore(cr);
}

std::string write_plots_png(const History& h, const std::string& path, int w, int h_px) {
  cairo_surface_t* surface = cairo_image_surface_create(CAIRO_FORMAT_ARGB32, w, h_px);
  cairo_t* cr = cairo_create(surface);
  cairo_set_source_rgb(cr, kBackground.r / 255.0, kBackground.g / 255.0, kBackground.b / 255.0);
  cairo_paint(cr);
  draw_plots(cr, h, 0, 0, w, h_px);
  cairo_destroy(cr);
  const std::string why = write_png(surface, path);
  cairo_surface_destroy(surface);
  return why;
}

}  // namespace ladder::view
