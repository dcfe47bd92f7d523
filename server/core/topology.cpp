// Building the model and restructuring it at run time: combine, separate, and the rebuild of bodies and hinge rows
// that follows each of them.
#include "core/world.hpp"

#include <algorithm>
#include <cmath>
#include <map>
#include <numbers>
#include <numeric>
#include <stdexcept>
#include <string>

namespace ladder::core {

namespace {

std::string particle_name(int p) { return "particle " + std::to_string(p); }

int find_root(std::vector<int>& parent, int i) {
  while (parent[i] != i) i = parent[i] = parent[parent[i]];
  return i;
}

}  // namespace

World::World(const Options& options) : options_(options) {}

// No option enters K = G M^-1 G^T, so its factorisation stays valid: a setting that changes nothing leaves the next
// step exactly as it would have been.
void World::set_options(const Options& options) {
  options_ = options;
  mark_motion_changed();  // gravity may have changed: so has the potential energy
}

int World::add_part(const PartDef& def) {
  if (def.particles.empty()) throw std::invalid_argument("a part needs at least one particle");
  double mass = 0;
  Vec2 com = Vec2::Zero();
  for (const auto& p : def.particles) {
    if (!(p.mass >= 0) || !std::isfinite(p.mass)) throw std::invalid_argument("particle mass must be finite and >= 0");
    if (!p.local.allFinite()) throw std::invalid_argument("particle offset must be finite");
    mass += p.mass;
    com += p.mass * p.local;
  }
  if (mass > 0) com /= mass;
  Part part;
  part.first_particle = particle_count();
  part.particle_count = static_cast<int>(def.particles.size());
  part.mass = mass;
  part.kinematic = def.kinematic;
  const int index = part_count();
  for (const auto& p : def.particles) part.inertia += p.mass * (p.local - com).squaredNorm();
  if (!def.kinematic && !(mass > 0 && part.inertia > 0))  // before anything changes: a refused part leaves no trace
    throw std::invalid_argument("a dynamic part needs positive mass and rotational inertia");
  for (const auto& p : def.particles) particles_.push_back({p.mass, index, p.local - com});
  const Rot q = Rot::of(def.angle);
  // A new part starts as its own body whose frame is the part frame.
  part.body = static_cast<int>(bodies_.size());
  parts_.push_back(part);
  part_frames_.push_back({part.rel_q, part.body});
  Body body;
  body.mass = mass;
  body.inertia = part.inertia;
  body.kinematic = def.kinematic;
  body.inv_mass = def.kinematic ? 0 : 1 / mass;
  body.inv_inertia = def.kinematic ? 0 : 1 / part.inertia;
  body.own_inertia = part.inertia;
  body.gyration = std::sqrt(body.inertia * body.inv_mass);
  body.anchor_part = index;
  if (body.kinematic) kinematic_bodies_.push_back(part.body);
  bodies_.push_back(body);
  body_parts_.push_back({index});
  BodyState s;
  s.x = def.position + q * com;
  s.th = def.angle;
  s.q = q;
  s.v = def.kinematic ? Vec2::Zero() : def.velocity;
  s.w = def.kinematic ? 0 : def.omega;
  state_.push_back(s);
  ++structure_;
  mark_state_changed();
  return index;
}

void World::set_drive(int part, Drive drive) {
  parts_.at(part).drive = std::move(drive);
  if (!parts_[part].kinematic) {
    parts_[part].kinematic = true;
    rebuild();
  }
  drive_kinematic(t_);
}

void World::release(int part) {
  Part& p = parts_.at(part);
  if (!p.kinematic) return;
  if (!(p.mass > 0 && p.inertia > 0)) throw std::invalid_argument("a massless part cannot be released");
  p.kinematic = false;
  try {
    rebuild();  // keeps the part's current velocity: it leaves the hand moving as the hand moved
  } catch (...) {
    p.kinematic = true;  // a released body may be left in three hinges: stay held
    throw;
  }
  p.drive = nullptr;
  project_velocities();
}

int World::find_joint(int pa, int pb) const {
  for (size_t j = 0; j < joints_.size(); ++j) {
    const Joint& jt = joints_[j];
    if (jt.alive && ((jt.pa == pa && jt.pb == pb) || (jt.pa == pb && jt.pb == pa))) return static_cast<int>(j);
  }
  return -1;
}

// The offset psi0 of a new rolling joint from where its particles are now: u points from pa's arc centre toward
// pb's, and psi = (theta_a + theta_b) / 2 + psi0 is its direction (theta the parts' unwrapped angles). They should be
// 2 r apart; a difference is the joint's gap, closed as a plain hinge's is.
double World::rolling_offset(int pa, int pb) const {
  const Vec2 d = particle_position(pb) - particle_position(pa);
  if (!(d.norm() > 0))
    throw std::invalid_argument("a rolling hinge needs its two arc centres apart (they are " + particle_name(pa) +
                                " and " + particle_name(pb) + ", at one point)");
  return std::atan2(d.y(), d.x()) - 0.5 * (part_angle(particles_[pa].part) + part_angle(particles_[pb].part));
}

Restructure World::combine(int pa, int pb, double roll_radius) {
  ensure_built();
  if (!(roll_radius >= 0) || !std::isfinite(roll_radius))
    throw std::invalid_argument("combine: the rolling radius must be a finite number >= 0");
  if (pa < 0 || pb < 0 || pa >= particle_count() || pb >= particle_count())
    throw std::invalid_argument("combine: no such particle (" + std::to_string(pa) + ", " + std::to_string(pb) + ")");
  const int part_a = particles_[pa].part, part_b = particles_[pb].part;
  if (part_a == part_b) throw std::invalid_argument("combine: " + particle_name(pa) + " and " + particle_name(pb) +
                                                    " belong to the same rigid part");
  const double ke_before = kinetic_energy();
  const auto saved = joints_;
  Restructure result;
  const int j = find_joint(pa, pb);
  if (j >= 0) {
    // A further combine on a hinged pair welds the two bodies into one (the paper's lock, Algorithm 3). The
    // paper clones the merged particle to keep ten particles in the body; here a hinge never merged the two
    // particles in the first place (it holds them coincident), so both are still there.
    if (joints_[j].kind == JointKind::Weld)
      throw std::invalid_argument("combine: " + particle_name(pa) + " and " + particle_name(pb) + " are already welded");
    joints_[j].kind = JointKind::Weld;
    result.kind = JointKind::Weld;
  } else {
    const int body_a = parts_[part_a].body, body_b = parts_[part_b].body;
    if (body_a == body_b)
      throw std::invalid_argument("combine: " + particle_name(pa) + " and " + particle_name(pb) +
                                  " are already in one rigid body");
    for (const Joint& jt : joints_) {
      if (!jt.alive) continue;
      const int ba = parts_[particles_[jt.pa].part].body, bb = parts_[particles_[jt.pb].part].body;
      if ((ba == body_a && bb == body_b) || (ba == body_b && bb == body_a))
        throw std::invalid_argument("combine: the two bodies are already hinged at particles " +
                                    std::to_string(jt.pa) + " and " + std::to_string(jt.pb) +
                                    "; combine those to weld them");
    }
    joints_.push_back({pa, pb, JointKind::Hinge, true, roll_radius, roll_radius > 0 ? rolling_offset(pa, pb) : 0.0});
    result.kind = JointKind::Hinge;
  }
  try {
    rebuild();  // validates everything before it commits anything
  } catch (...) {
    joints_ = saved;  // so this is all there is to undo
    throw;
  }
  // Make the configuration and the velocities consistent with the new connectivity. Positions: a hinge made
  // between particles that are apart (a user's join within the capture distance) closes the gap now, without
  // a velocity kick. Velocities: a projection in the mass metric, i.e. the perfectly inelastic meeting of the
  // two particles; its impulses are internal, so free bodies keep their momentum.
  if (result.kind == JointKind::Hinge) {
    start_anchors();
    factor_system(ua0_, ub0_);
    solve_positions(ua0_, ub0_, 0.0);
  }
  project_velocities();
  result.energy_removed = ke_before - kinetic_energy();
  return result;
}

Restructure World::separate(int pa, int pb) {
  ensure_built();
  const int j = find_joint(pa, pb);
  if (j < 0)
    throw std::invalid_argument("separate: no hinge or weld joins " + particle_name(pa) + " and " + particle_name(pb));
  const auto saved = joints_;
  Restructure result;
  if (joints_[j].kind == JointKind::Weld) {
    // Unlock (Algorithm 4): the welded body splits back into the bodies it was made of, each moving as it
    // moved inside the weld, so nothing jumps and no energy changes.
    joints_[j].kind = JointKind::Hinge;
    result.kind = JointKind::Hinge;
  } else {
    joints_[j].alive = false;
    result.kind = JointKind::Hinge;
    result.removed = true;
  }
  try {
    rebuild();  // an unlock can refuse: a split body may be left in three hinges
  } catch (...) {
    joints_ = saved;
    throw;
  }
  return result;
}

World::PartMotion World::part_motion(int part) const {
  const Part& p = parts_[part];
  const BodyState& s = state_[p.body];
  const Vec2 d = s.q * p.rel_x;
  return {s.x + d, s.v + s.w * perp(d), s.th + p.rel_th, s.w, s.q * p.rel_q};
}

void World::set_body_from_parts(int b, const std::vector<int>& parts, const std::vector<PartMotion>& motion) {
  Body& body = bodies_[b];
  BodyState& s = state_[b];
  const int anchor = body.anchor_part;
  const PartMotion& am = motion[anchor];
  if (parts.size() == 1) {
    // The common case, kept exact: a lone part's frame is its body's frame.
    const Part& p = parts_[anchor];
    body.mass = p.mass;
    body.inertia = p.inertia;
    s = {am.x, am.v, am.q, am.th, am.w};
  } else {
    double m = 0;
    Vec2 com = Vec2::Zero(), momentum = Vec2::Zero();
    for (int i : parts) {
      m += parts_[i].mass;
      com += parts_[i].mass * motion[i].x;
      momentum += parts_[i].mass * motion[i].v;
    }
    com = m > 0 ? Vec2(com / m) : am.x;
    double inertia = 0, spin = 0;  // about the composite centre of mass
    const Vec2 v = m > 0 ? Vec2(momentum / m) : am.v;
    for (int i : parts) {
      const Vec2 d = motion[i].x - com;
      inertia += parts_[i].inertia + parts_[i].mass * d.squaredNorm();
      spin += parts_[i].inertia * motion[i].w + parts_[i].mass * cross(d, motion[i].v - v);
    }
    body.mass = m;
    body.inertia = inertia;
    s.x = com;
    s.q = am.q.renormalised();
    s.th = am.th;
    if (body.kinematic) {
      s.w = am.w;
      s.v = am.v + am.w * perp(com - am.x);
    } else {
      // Merging: the composite keeps the parts' total linear and angular momentum (perfectly inelastic).
      s.v = v;
      s.w = spin / inertia;
    }
  }
  body.inv_mass = body.kinematic ? 0 : 1 / body.mass;
  body.inv_inertia = body.kinematic ? 0 : 1 / body.inertia;
  body.gyration = std::sqrt(body.inertia * body.inv_mass);
  body.own_inertia = 0;
  for (int i : parts) body.own_inertia += parts_[i].inertia;
  body.single_part = parts.size() == 1;
  for (int i : parts) {
    Part& p = parts_[i];
    p.body = b;
    if (i == anchor) {
      p.rel_x = s.q.apply_inverse(motion[i].x - s.x);
      p.rel_q = Rot{};
      p.rel_th = 0;
      if (parts.size() == 1) p.rel_x = Vec2::Zero();
    } else {
      p.rel_x = s.q.apply_inverse(motion[i].x - s.x);
      p.rel_th = motion[i].th - s.th;
      // From the rotations, not from the unwrapped angles (which lose all precision at large angles), and pulled
      // back to unit length so that repeated merges and splits cannot make bodies grow.
      p.rel_q = (s.q.inverse() * motion[i].q).renormalised();
    }
    part_frames_[static_cast<size_t>(i)] = {p.rel_q, p.body};
  }
}

void World::connect(int pa, int pb, double roll_radius) {
  if (pa < 0 || pb < 0 || pa >= particle_count() || pb >= particle_count() ||
      particles_[pa].part == particles_[pb].part)
    throw std::invalid_argument("connect: particles " + std::to_string(pa) + " and " + std::to_string(pb) +
                                " cannot be hinged");
  if (!(roll_radius >= 0) || !std::isfinite(roll_radius))
    throw std::invalid_argument("connect: the rolling radius must be a finite number >= 0");
  joints_.push_back({pa, pb, JointKind::Hinge, true, roll_radius, roll_radius > 0 ? rolling_offset(pa, pb) : 0.0});
  dirty_ = true;
}

void World::rebuild() {
  const int np = part_count();
  std::vector<PartMotion> motion(static_cast<size_t>(np));
  for (int i = 0; i < np; ++i) motion[i] = part_motion(i);

  // The hinge forces of the rows that exist now, by their joint's two particles and oriented as acting on the first
  // particle's body, for the rows that the new structure keeps (hinge_force_).
  std::map<std::pair<int, int>, Vec2> kept_force;
  if (hinge_force_.size() == rows_.size())
    for (size_t k = 0; k < rows_.size(); ++k) {
      const Joint& jt = joints_[static_cast<size_t>(rows_[k].joint)];
      if (!jt.alive || jt.kind != JointKind::Hinge) continue;
      const bool flipped = particles_[jt.pa].part != rows_[k].part_a;
      kept_force[{jt.pa, jt.pb}] = flipped ? Vec2(-hinge_force_[k]) : hinge_force_[k];
    }

  // Drop broken joints so that the joint list does not grow with every flip-flop.
  std::erase_if(joints_, [](const Joint& j) { return !j.alive; });

  // Bodies are the connected components of parts under welds, numbered by their lowest part.
  std::vector<int> parent(static_cast<size_t>(np));
  std::iota(parent.begin(), parent.end(), 0);
  for (const Joint& j : joints_) {
    if (j.kind != JointKind::Weld) continue;
    const int ra = find_root(parent, particles_[j.pa].part), rb = find_root(parent, particles_[j.pb].part);
    if (ra != rb) parent[std::max(ra, rb)] = std::min(ra, rb);
  }
  std::vector<int> body_of_root(static_cast<size_t>(np), -1);
  std::vector<std::vector<int>> groups;
  for (int i = 0; i < np; ++i) {
    const int r = find_root(parent, i);
    if (body_of_root[r] < 0) {
      body_of_root[r] = static_cast<int>(groups.size());
      groups.emplace_back();
    }
    groups[body_of_root[r]].push_back(i);
  }

  // Hinge rows, checked before anything is committed so that a refused combine leaves the model untouched.
  std::vector<Body> bodies(groups.size());
  for (size_t b = 0; b < groups.size(); ++b) {
    for (int i : groups[b]) {
      if (parts_[i].kinematic && !bodies[b].kinematic) {
        bodies[b].kinematic = true;
        bodies[b].anchor_part = i;
      }
    }
    if (bodies[b].anchor_part < 0) bodies[b].anchor_part = groups[b].front();
  }
  std::vector<Row> rows;
  for (size_t j = 0; j < joints_.size(); ++j) {
    const Joint& jt = joints_[j];
    if (jt.kind != JointKind::Hinge) continue;
    const int pa = particles_[jt.pa].part, pb = particles_[jt.pb].part;
    const int a = body_of_root[find_root(parent, pa)], b = body_of_root[find_root(parent, pb)];
    if (a == b)
      throw std::invalid_argument("a hinge between particles " + std::to_string(jt.pa) + " and " +
                                  std::to_string(jt.pb) + " would join a body to itself (a closed loop)");
    if (bodies[a].kinematic && bodies[b].kinematic) continue;  // nothing can move: no equation to solve
    rows.push_back(
        {Vec2::Zero(), Vec2::Zero(), a, b, pa, pb, static_cast<int>(j), false, false, false, false, false, false});
  }
  order_rows(bodies, rows);  // may throw: nothing is committed yet
  // Commit.
  dirty_ = false;
  bodies_.swap(bodies);
  state_.assign(groups.size(), BodyState{});
  body_parts_ = std::move(groups);
  for (size_t b = 0; b < body_parts_.size(); ++b) set_body_from_parts(static_cast<int>(b), body_parts_[b], motion);
  for (Row& r : rows) {
    const Joint& jt = joints_[r.joint];
    const bool swapped = particles_[jt.pa].part != r.part_a;
    const int qa = swapped ? jt.pb : jt.pa, qb = swapped ? jt.pa : jt.pb;
    const Part& A = parts_[r.part_a];
    const Part& B = parts_[r.part_b];
    r.ra = A.rel_x + A.rel_q * particles_[qa].local;
    r.rb = B.rel_x + B.rel_q * particles_[qb].local;
  }
  // Rolling rows: psi = (theta_pa + theta_pb) / 2 + psi0 in the parts' angles is, in the bodies', (th_a + th_b) / 2 +
  // psi0 + (rel_th_a + rel_th_b) / 2; a row that runs from the joint's pb to its pa has u the other way.
  roll_.assign(rows.size(), Roll{});
  for (size_t k = 0; k < rows.size(); ++k) {
    Row& r = rows[k];
    const Joint& jt = joints_[r.joint];
    r.rolls = jt.radius > 0;
    if (!r.rolls) continue;
    const bool swapped = particles_[jt.pa].part != r.part_a;
    roll_[k] = {jt.radius, jt.psi0 + 0.5 * (parts_[r.part_a].rel_th + parts_[r.part_b].rel_th) +
                               (swapped ? std::numbers::pi : 0.0)};
  }
  rows_ = std::move(rows);
  for (size_t k = 0; k < rows_.size(); ++k) {
    Row& r = rows_[k];
    r.shares_next = k + 1 < rows_.size() && rows_[k + 1].link_prev;
    r.corrects_a = !r.link_prev && !bodies_[r.a].kinematic;
    r.corrects_b = !bodies_[r.b].kinematic;
    r.kinematic_side = bodies_[r.a].kinematic || bodies_[r.b].kinematic;
  }
  kinematic_bodies_.clear();
  for (size_t b = 0; b < bodies_.size(); ++b)
    if (bodies_[b].kinematic) kinematic_bodies_.push_back(static_cast<int>(b));
  kinematic_rows_.clear();
  for (size_t k = 0; k < rows_.size(); ++k)
    if (rows_[k].kinematic_side) kinematic_rows_.push_back(static_cast<int>(k));
  has_rolling_ = std::any_of(rows_.begin(), rows_.end(), [](const Row& r) { return r.rolls; });
  has_welds_ = std::any_of(joints_.begin(), joints_.end(), [](const Joint& j) { return j.kind == JointKind::Weld; });
  row_impulse_.assign(rows_.size(), Vec2::Zero());
  hinge_force_.assign(rows_.size(), Vec2::Zero());
  hinge_force_1_.assign(rows_.size(), Vec2::Zero());
  hinge_force_2_.assign(rows_.size(), Vec2::Zero());
  for (size_t k = 0; k < rows_.size(); ++k) {
    const Joint& jt = joints_[static_cast<size_t>(rows_[k].joint)];
    const auto it = kept_force.find({jt.pa, jt.pb});
    if (it == kept_force.end()) continue;
    hinge_force_[k] = particles_[jt.pa].part != rows_[k].part_a ? Vec2(-it->second) : it->second;
  }
  force_steps_ = std::min(force_steps_, 1);  // the older forces are gone
  ++structure_;
  mark_state_changed();
  factor_version_ = 0;
}

// Orders hinge rows along the chains of dynamic bodies so that the system is block-tridiagonal, and orients each
// row so that the body it shares with the previous row is its body a. Throws if a dynamic body is in more than two
// hinges or the hinges close a loop: those systems are not banded and the engine refuses them.
void World::order_rows(const std::vector<Body>& bodies, std::vector<Row>& rows) {
  const size_t nb = bodies.size();
  std::vector<std::vector<int>> incident(nb);
  for (size_t r = 0; r < rows.size(); ++r) {
    for (int b : {rows[r].a, rows[r].b}) {
      if (bodies[b].kinematic) continue;
      incident[b].push_back(static_cast<int>(r));
      if (incident[b].size() > 2)
        throw std::invalid_argument("a moving body may take part in at most two hinges (the engine solves chains); "
                                    "body " + std::to_string(b) + " would have three");
    }
  }
  auto next_row = [&](int body, int row) {
    if (bodies[body].kinematic) return -1;
    for (int r : incident[body])
      if (r != row) return r;
    return -1;
  };
  auto swap_row = [](Row& r) {
    std::swap(r.a, r.b);
    std::swap(r.ra, r.rb);
    std::swap(r.part_a, r.part_b);
  };
  std::vector<Row> out;
  out.reserve(rows.size());
  std::vector<char> used(rows.size(), 0);
  for (size_t start = 0; start < rows.size(); ++start) {
    if (used[start]) continue;
    const bool end = next_row(rows[start].a, static_cast<int>(start)) < 0 ||
                     next_row(rows[start].b, static_cast<int>(start)) < 0;
    if (!end) continue;
    int cur = static_cast<int>(start);
    Row row = rows[cur];
    if (next_row(row.a, cur) >= 0) swap_row(row);
    row.link_prev = false;
    while (true) {
      used[cur] = 1;
      out.push_back(row);
      const int nxt = next_row(row.b, cur);
      if (nxt < 0 || used[nxt]) break;
      const int shared = row.b;
      row = rows[nxt];
      if (row.a != shared) swap_row(row);
      row.link_prev = true;
      cur = nxt;
    }
  }
  if (out.size() != rows.size())
    throw std::invalid_argument("the hinges would close a loop of moving bodies; the engine solves open chains only");
  rows = std::move(out);
}

const std::vector<int>& World::body_parts(int body) const { return body_parts_.at(body); }

}  // namespace ladder::core
