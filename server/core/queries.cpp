// Read-only views of the world: where particles and parts are, energies, momenta, hinge error, and the moment a
// weld carried during the last step.
#include "core/world.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace ladder::core {

Vec2 World::particle_position(int p) const {
  const PartMotion m = part_motion(particles_.at(p).part);
  return m.x + m.q * particles_[p].local;
}

Vec2 World::particle_velocity(int p) const {
  const PartMotion m = part_motion(particles_.at(p).part);
  return m.v + m.w * perp(m.q * particles_[p].local);
}

Vec2 World::part_position(int part) const { return part_motion(part).x; }
double World::part_angle(int part) const { return part_motion(part).th; }
Vec2 World::part_velocity(int part) const { return part_motion(part).v; }

double World::kinetic_energy() const {
  double e = 0;
  for (size_t b = 0; b < bodies_.size(); ++b) {
    if (bodies_[b].kinematic) continue;
    e += 0.5 * (bodies_[b].mass * state_[b].v.squaredNorm() + bodies_[b].inertia * state_[b].w * state_[b].w);
  }
  return e;
}

// One pass for the watchdog: the energies, and in the same pass finite() (see there; with a dynamic body's mass and
// inertia positive a non-finite x, v or w already makes its energy non-finite, so only th and q are added).
// Bodies in pairs, with a partial sum for each of the two, so that the pass is not bound by one chain of dependent
// additions (a kinematic body counts as zero).
Energy World::energy() const {
  if (energy_version_ == motion_version_ && energy_structure_ == structure_) return energy_;
  const double gx = options_.gravity.x(), gy = options_.gravity.y();
  struct Sums {
    double k[2] = {0, 0}, p[2] = {0, 0}, zero = 0;
  };
  Sums lane[2];
  // Per half of a long chain (in_halves), with two sums each (the even and odd bodies of the half).
  in_halves(bodies_.size(), [&](size_t from, size_t to, int l) {
    Sums sum;  // a local, stored once: in lane[l], beside the other lane's, both threads would write one cache line
    const auto add = [&](size_t b, int i) __attribute__((always_inline)) {
      const BodyState& s = state_[b];
      if (bodies_[b].kinematic) {
        sum.zero += 0.0 * (s.x.x() + s.x.y() + s.v.x() + s.v.y() + s.w);
      } else {
        const Body& body = bodies_[b];
        sum.k[i] += body.mass * (s.v.x() * s.v.x() + s.v.y() * s.v.y()) + body.inertia * s.w * s.w;
        sum.p[i] -= body.mass * (gx * s.x.x() + gy * s.x.y());
      }
      sum.zero += 0.0 * (s.th + s.q.c + s.q.s);
    };
    size_t b = from;
    for (; b + 1 < to; b += 2) {
      add(b, 0);
      add(b + 1, 1);
    }
    if (b < to) add(b, 0);
    lane[l] = sum;
  });
  const Sums& a = lane[0];
  const Sums& b = lane[1];
  if (split_chain())
    energy_ = {0.5 * ((a.k[0] + a.k[1]) + (b.k[0] + b.k[1])), (a.p[0] + a.p[1]) + (b.p[0] + b.p[1])};
  else
    energy_ = {0.5 * (a.k[0] + a.k[1]), a.p[0] + a.p[1]};
  energy_.finite = std::isfinite(energy_.kinetic) && std::isfinite(energy_.potential) && a.zero + b.zero == 0 &&
                   std::isfinite(t_);
  energy_version_ = motion_version_;
  energy_structure_ = structure_;
  return energy_;
}

double World::potential_energy() const {
  double e = 0;
  for (size_t b = 0; b < bodies_.size(); ++b)
    if (!bodies_[b].kinematic) e -= bodies_[b].mass * options_.gravity.dot(state_[b].x);
  return e;
}

Vec2 World::linear_momentum(const std::vector<int>& parts) const {
  Vec2 p = Vec2::Zero();
  for (int i : parts) p += parts_.at(i).mass * part_motion(i).v;
  return p;
}

double World::angular_momentum(const std::vector<int>& parts, const Vec2& about) const {
  double l = 0;
  for (int i : parts) {
    const PartMotion m = part_motion(i);
    l += parts_.at(i).inertia * m.w + parts_[i].mass * cross(m.x - about, m.v);
  }
  return l;
}

// A joint's gap: its two particles' distance, and for a rolling joint their arc centres' offset from 2 r along the
// rolling direction, u from pa's toward pb's (the parts' own angles, unwrapped).
Vec2 World::joint_gap(const Joint& j) const {
  const Vec2 gap = particle_position(j.pa) - particle_position(j.pb);
  if (!(j.radius > 0)) return gap;
  const double psi = 0.5 * (part_angle(particles_[j.pa].part) + part_angle(particles_[j.pb].part)) + j.psi0;
  return gap + 2 * j.radius * unit_at(psi);
}

double World::max_hinge_error() const {
  double worst = 0;
  for (const Joint& j : joints_)
    if (j.alive) worst = std::max(worst, joint_gap(j).norm());
  return worst;
}

// Without a branch per value (the watchdog asks after every step): x * 0 is a zero for every finite x and NaN for an
// infinity or a NaN, and a sum of zeros is a zero, so the sums are zero exactly when every value is finite.
bool World::finite() const {
  Vec2 zero = Vec2::Zero();
  for (const BodyState& s : state_) zero += 0.0 * s.x + 0.0 * s.v + 0.0 * Vec2(s.q.c, s.q.s) + 0.0 * Vec2(s.th, s.w);
  return zero.x() == 0 && zero.y() == 0 && std::isfinite(t_);
}

// Impulse-momentum balance over the last step for S, the parts on pb's side of the weld (reached from pb's part
// through other welds). S moves rigidly with its body, so about S's centre of mass c:
//   linear:   m_S (v1 - v0)  = h F_ext + sum J_row + J_weld
//   angular:  I_S (w1 - w0)  = h tau_ext + sum (p_row - c) x J_row + (P - c) x J_weld + h M_weld
// with the row impulses the solver applied and P the weld point. Every lever arm is taken at mid-step (the mean
// of its start and end positions): the impulses act through the step, and end-of-step arms would be off by
// O(w h) (40 % of the moment at w = 100 rad/s and h = 1 ms; second order at mid-step).
double World::weld_moment(int pa, int pb, int about_a, int about_b) const {
  const int j = find_joint(pa, pb);
  if (j < 0 || joints_[j].kind != JointKind::Weld)
    throw std::invalid_argument("weld_moment: particles " + std::to_string(pa) + " and " + std::to_string(pb) +
                                " are not welded");
  if (!(last_h_ > 0) || step_structure_ != structure_ || step_start_.size() != state_.size()) return 0;
  const int part_a = particles_[pa].part, part_b = particles_[pb].part;
  const int body = parts_[part_b].body;
  // S: flood over welds from part_b without crossing joint j.
  std::vector<int> side{part_b};
  std::vector<char> in(parts_.size(), 0);
  in[part_b] = 1;
  for (size_t i = 0; i < side.size(); ++i) {
    for (size_t k = 0; k < joints_.size(); ++k) {
      const Joint& jt = joints_[k];
      if (static_cast<int>(k) == j || !jt.alive || jt.kind != JointKind::Weld) continue;
      const int x = particles_[jt.pa].part, y = particles_[jt.pb].part;
      const int other = x == side[i] ? y : (y == side[i] ? x : -1);
      if (other >= 0 && !in[other]) {
        in[other] = 1;
        side.push_back(other);
      }
    }
  }
  if (in[part_a]) return 0;  // welded around a loop: no moment can be attributed to this weld
  const BodyState& s1 = state_[body];
  const BodyState& s0 = step_start_[body];
  // Where a point fixed in the body frame is at mid-step.
  const auto mid = [&](const Vec2& r) { return Vec2(0.5 * ((s0.x + s0.q * r) + (s1.x + s1.q * r))); };
  double m = 0, inertia = 0;
  Vec2 rel_c = Vec2::Zero();  // S's centre of mass in the body frame
  for (int i : side) {
    m += parts_[i].mass;
    rel_c += parts_[i].mass * parts_[i].rel_x;
  }
  if (!(m > 0)) return 0;
  rel_c /= m;
  for (int i : side) inertia += parts_[i].inertia + parts_[i].mass * (parts_[i].rel_x - rel_c).squaredNorm();
  const Vec2 c = mid(rel_c);
  const Vec2 v1 = s1.v + s1.w * perp(s1.q * rel_c);
  const Vec2 v0 = s0.v + s0.w * perp(s0.q * rel_c);
  const double h = last_h_;
  // External forces on S over the step (as the kick applies them, at the start of the step). A held body gets no
  // kick (the hand prescribes its motion), but the forces act on it all the same: the weld and the hand carry them.
  Vec2 f_ext = Vec2::Zero();
  double tau_ext = 0;
  for (int i : side) {
    const Part& p = parts_[i];
    const Vec2 d0 = s0.q * p.rel_x;
    const Vec2 fp = p.mass * (options_.gravity - options_.linear_damping * (s0.v + s0.w * perp(d0)));
    f_ext += fp;
    tau_ext += cross(mid(p.rel_x) - c, fp) - options_.angular_damping * p.inertia * s0.w;
  }
  for (const AppliedForce& af : step_forces_) {
    if (!in[af.part] || !((t_ - h) < af.until)) continue;
    const Part& p = parts_[af.part];
    const Vec2 force = af.over_step(t_ - h, h);
    f_ext += force;
    tau_ext += cross(mid(p.rel_x + p.rel_q * af.local) - c, force);
  }
  Vec2 j_rows = Vec2::Zero();
  double m_rows = 0;
  for (size_t k = 0; k < rows_.size(); ++k) {
    const Row& r = rows_[k];
    const double friction = options_.hinge_friction * (state_[r.b].w - state_[r.a].w) * h;
    // A rolling row acts at its contact point, r u from the arc centre (u at mid-step, from both bodies' angles).
    const Vec2 roll = r.rolls ? Vec2(0.5 * (roll_offset(k, step_start_[r.a], step_start_[r.b]) + roll_offset(k)))
                              : Vec2::Zero();
    if (in[r.part_a]) {
      j_rows += row_impulse_[k];
      m_rows += cross(mid(r.ra) + roll - c, row_impulse_[k]) + friction;
    }
    if (in[r.part_b]) {
      j_rows -= row_impulse_[k];
      m_rows -= cross(mid(r.rb) - roll - c, row_impulse_[k]) + friction;
    }
  }
  const Part& pbp = parts_[part_b];
  Vec2 weld_point = mid(pbp.rel_x + pbp.rel_q * particles_[pb].local);
  const Joint& jt = joints_[static_cast<size_t>(j)];
  if (jt.radius > 0) {  // a rolling weld's pivot: the contact point, r u from pb's arc centre toward pa's
    const Part& pap = parts_[part_a];
    const double th = 0.5 * (s0.th + s1.th);
    const double psi = th + 0.5 * (pap.rel_th + pbp.rel_th) + jt.psi0;
    const Vec2 u = unit_at(psi);
    weld_point += (jt.pa == pb ? 1.0 : -1.0) * jt.radius * u;
  }
  const Vec2 j_weld = m * (v1 - v0) - h * f_ext - j_rows;
  Vec2 about = weld_point;
  if (about_a >= 0 || about_b >= 0) {  // the weld's force, applied at weld_point, has a moment about another point
    const auto point = [&](int p) {
      if (p < 0 || p >= static_cast<int>(particles_.size()) || parts_[particles_[p].part].body != body)
        throw std::invalid_argument("weld_moment: particle " + std::to_string(p) + " is not on the welded body");
      const Part& part = parts_[particles_[p].part];
      return mid(part.rel_x + part.rel_q * particles_[p].local);
    };
    about = 0.5 * (point(about_a) + point(about_b));
  }
  const double angular = inertia * (s1.w - s0.w) - h * tau_ext - m_rows - cross(about - c, j_weld);
  return angular / h;
}

}  // namespace ladder::core
