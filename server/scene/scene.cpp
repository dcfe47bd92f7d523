#include "scene/scene.hpp"

#include "ladder/limits.hpp"
#include "ladder/spelling.hpp"

#include <toml++/toml.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdlib>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <functional>
#include <initializer_list>
#include <limits>
#include <map>
#include <sstream>
#include <system_error>
#include <utility>

namespace ladder::scene {

namespace {

using core::Vec2;

constexpr double kInf = std::numeric_limits<double>::infinity();
// The bounds below keep every accepted live setting (also from a scene file) within what a step can take; the
// figures were measured on the shipped scenes (docs/scenes.md gives each bound's reason).
constexpr double kMaxGravity = 1000;     // [m/s^2] about 100 g; 1e4 still steps, 1e308 overflows the first step
constexpr double kMinSubstep = 1e-7;     // [s] the smallest sim.dt: sim.dt / sim.substeps may not go below it

// ---------------------------------------------------------------------------------------------------------------
// The schema: every documented key with its type and valid range. keys_help() prints it and the reader takes each
// key's range from it, so the help, the checks and the did-you-mean hints cannot drift apart.

// An interval of allowed values; an infinite end is no bound.
struct Range {
  double lo = -kInf, hi = kInf;
  bool lo_open = false, hi_open = false;

  bool contains(double v) const {
    return (lo_open ? v > lo : v >= lo) && (hi_open ? v < hi : v <= hi);
  }
};
constexpr Range kAnyNumber{};
constexpr Range at_least(double lo) { return {lo, kInf, false, false}; }
constexpr Range between(double lo, double hi) { return {lo, hi, false, false}; }

enum class Kind { Integer, Number, Boolean, String, Choice, Pair, Numbers };

struct KeyDef {
  std::string_view name;           // "table.key"
  Kind kind = Kind::Number;
  Range range{};                   // of the value, or of each element of a list
  std::string_view choices{};      // Kind::Choice, separated by '|'
  std::string_view help{};         // with the unit in brackets
  std::string_view range_text{};   // replaces the printed range when it depends on other keys
};

constexpr std::array kKeys{
    KeyDef{.name = "scene.name", .kind = Kind::String,
           .help = "title shown to the user (default: the file's name without its extension)"},
    KeyDef{.name = "scene.description", .kind = Kind::String, .help = "what the scene shows"},
    KeyDef{.name = "ladder.blocks", .kind = Kind::Integer, .range = between(1, kMaxBlocks),
           .help = "number of blocks; without it, the length of ladder.masses"},
    KeyDef{.name = "ladder.length", .kind = Kind::Number, .range = between(1e-3, 10), .help = "block length [m]"},
    KeyDef{.name = "ladder.thickness", .kind = Kind::Number, .range = between(1e-4, 10), .help = "block thickness [m]"},
    KeyDef{.name = "ladder.depth", .kind = Kind::Number, .range = {0, 10, true, false},
           .help = "block depth into the page, drawn by the viewer only (the model is 2-D) [m]"},
    // The shape and the masses are bounded where the step has been run (the classic scene tipped, 3 s at 1 ms, at each
    // bound and with masses alternating between the two); 1e-300 kg made the first state non-finite.
    KeyDef{.name = "ladder.mass", .kind = Kind::Number, .range = between(1e-6, 1e6), .help = "mass of each block [kg]"},
    KeyDef{.name = "ladder.masses", .kind = Kind::Numbers, .range = between(1e-6, 1e6),
           .help = "mass of each block in turn, one per block [kg]"},
    KeyDef{.name = "ladder.top", .kind = Kind::Choice, .choices = "held|pinned|free",
           .help = "top block held in a hand, pinned at its top-left corner, or free"},
    KeyDef{.name = "ladder.start", .kind = Kind::Choice, .choices = "hanging|straight",
           .help = "start at rest, or as a straight vertical column"},
    KeyDef{.name = "ladder.logic", .kind = Kind::Boolean, .help = "flip-flops, locks and unlocks (Algorithm 1)"},
    KeyDef{.name = "ladder.flip_impact", .kind = Kind::Choice, .choices = "face|corner",
           .help = "a flip-flop's inelastic meeting: the whole face, or the far corners only (the paper's)"},
    KeyDef{.name = "ladder.hinge_inset", .kind = Kind::Number, .range = {0, 0.5, false, true},
           .help = "hinge distance in from the block's edge [fraction of the thickness]",
           .range_text = ">= 0 and < 0.5; 0 with ladder.hinge = \"rolling\""},
    KeyDef{.name = "ladder.hinge", .kind = Kind::Choice, .choices = "corner|rolling",
           .help = "the paper's corner hinge, or the real toy's rolling hinge (rounded ends rolling on each other)"},
    KeyDef{.name = "ladder.end_radius", .kind = Kind::Number, .range = at_least(0),
           .help = "radius of the rounded block ends of a rolling hinge; 0 turns about the corner [m]",
           .range_text = "0, or >= ladder.thickness * 1e-6 and <= ladder.thickness / 2; > 0 needs ladder.hinge = "
                         "\"rolling\""},
    KeyDef{.name = "ladder.tip_duration", .kind = Kind::Number, .range = at_least(1e-3),
           .help = "time the hand takes to turn the top block over [s]"},
    KeyDef{.name = "ladder.unlock_threshold", .kind = Kind::Number, .range = at_least(0),
           .help = "pull of a straight pair's contact above which a lock lets go, or a meeting with the stop is an "
                   "impact [N m]"},
    // (At 1e300 a join pulled back blocks that had fallen 17 km, 2e4 J removed; a hand reaches 10 m.)
    KeyDef{.name = "ladder.capture_distance", .kind = Kind::Number, .range = between(0, 10),
           .help = "farthest apart two corners may be for a join [m]"},
    // A radian per 1 ms step at 1000 rad/s (extremes_test folds through the singular configuration so); at 1e4 the
    // first steps fail, and 1e300 made the first state non-finite.
    KeyDef{.name = "initial.kick_omega", .kind = Kind::Number, .range = between(-1000, 1000),
           .help = "initial angular velocity of block 1 about its top hinge [rad/s]"},
    // (A turn of 1e300 rad is finite, but its sine and cosine are rounding noise.)
    KeyDef{.name = "initial.tilt", .kind = Kind::Number, .range = between(-2 * std::numbers::pi, 2 * std::numbers::pi),
           .help = "initial rotation of the whole ladder about its top-left corner [rad]",
           .range_text = ">= -2 pi and <= 2 pi"},
    KeyDef{.name = "sim.dt", .kind = Kind::Number, .range = between(kMinDt, kMaxDt), .help = "time step [s]"},
    KeyDef{.name = "sim.substeps", .kind = Kind::Integer, .range = between(1, 1000),
           .help = "steps of sim.dt / sim.substeps taken per step of sim.dt (the server's tick)",
           .range_text = ">= 1 and <= 1000, and sim.dt / sim.substeps >= 1e-07 s"},
    KeyDef{.name = "sim.accuracy", .kind = Kind::Choice, .choices = "fast|balanced|accurate",
           .help = "preset for sim.integrator, sim.substeps, sim.stabilization and solver.*; such a key given "
                   "beside it, or by --set over a file's preset, wins (docs/tradeoff.md)"},
    KeyDef{.name = "sim.integrator", .kind = Kind::Choice,
           .choices = "euler|symplectic_euler|rattle|rk4|projection|reduced|midpoint", .help = "time integrator"},
    KeyDef{.name = "sim.stabilization", .kind = Kind::Choice, .choices = "none|velocity|position",
           .help = "projection back onto the hinges after a step"},
    KeyDef{.name = "sim.adaptive", .kind = Kind::Boolean,
           .help = "cover each step with sub-steps chosen by error control (step doubling) to sim.error_tolerance"},
    KeyDef{.name = "sim.error_tolerance", .kind = Kind::Number, .range = between(1e-12, 1e-2),
           .help = "largest estimated error of an adaptive sub-step, a displacement [m]"},
    KeyDef{.name = "sim.gravity", .kind = Kind::Pair, .help = "gravitational acceleration [m/s^2]",
           .range_text = "|g| <= 1000"},
    KeyDef{.name = "solver.kind", .kind = Kind::Choice, .choices = "newton|newton_linesearch",
           .help = "hinge constraint solver"},
    // Below about 1e-15 m the solve cannot get there (rounding leaves 4e-16 m on a 1000-block chain), so every solve
    // ran to solver.max_iterations and a step of `long` with 1000 sub-steps took minutes.
    KeyDef{.name = "solver.tolerance", .kind = Kind::Number, .range = between(1e-15, 1e-6),
           .help = "hinge position error the solver drives below [m]"},
    KeyDef{.name = "solver.max_iterations", .kind = Kind::Integer, .range = between(1, 1000),
           .help = "iterations per nonlinear solve (a midpoint solve still short is rescued: docs/model.md 3.1)"},
    KeyDef{.name = "solver.threads", .kind = Kind::Integer, .range = between(1, 2),
           .help = "threads a midpoint step may use: 2 solves a chain of 2048 hinges or more in two halves at once "
                   "(the same bits as 1; docs/model.md 3.2)"},
    // The drags are explicit forces: at 1 ms a block stops within a step already at 1000 /s (3e5 fails the step),
    // and hinge friction above 0.4 N m s fails it for the shipped 25 g blocks.
    KeyDef{.name = "damping.linear", .kind = Kind::Number, .range = between(0, 1000),
           .help = "drag force -c m v on each block [1/s]",
           .range_text = ">= 0 and <= 1000, and <= 1 / (sim.dt / sim.substeps)"},
    KeyDef{.name = "damping.angular", .kind = Kind::Number, .range = between(0, 1000),
           .help = "drag torque -c I w on each block [1/s]",
           .range_text = ">= 0 and <= 1000, and <= 1 / (sim.dt / sim.substeps)"},
    KeyDef{.name = "damping.hinge", .kind = Kind::Number, .range = between(0, 0.1),
           .help = "viscous hinge torque -c (w_b - w_a) [N m s]"},
    KeyDef{.name = "timeline.t", .kind = Kind::Number, .range = at_least(0),
           .help = "time the command is applied, required [s]"},
    KeyDef{.name = "timeline.command", .kind = Kind::Choice, .choices = "tip|poke|push|break|join",
           .help = "what to do, required"},
    KeyDef{.name = "timeline.block", .kind = Kind::Integer, .range = at_least(0),
           .help = "block to poke or push, required by both", .range_text = ">= 0 and < ladder.blocks"},
    KeyDef{.name = "timeline.hinge", .kind = Kind::Integer, .range = at_least(0),
           .help = "hinge to break or join, required by both; hinge 0 is the top block's hold or pin",
           .range_text = ">= 0 and < ladder.blocks"},
    KeyDef{.name = "timeline.impulse", .kind = Kind::Pair, .help = "poke impulse, required by poke [N s]",
           .range_text = "size <= 1, the server's default commands.max_impulse"},
    KeyDef{.name = "timeline.at", .kind = Kind::Pair,
           .help = "poke: world point; push: point in the block's frame; default the block's centre [m]",
           .range_text = "on the block when the command comes; a poke's within 10 m of the origin"},
    KeyDef{.name = "timeline.force", .kind = Kind::Pair, .help = "push force, required by push [N]",
           .range_text = "size <= 100, the server's default commands.max_force"},
    KeyDef{.name = "timeline.duration", .kind = Kind::Number, .range = {0, kMaxDuration, true, false},
           .help = "push duration, required by push [s]"},
};

constexpr std::array<std::string_view, 6> kTables{"scene", "ladder", "initial", "sim", "solver", "damping"};

// Which timeline fields each command takes besides t and command.
struct CommandDef {
  std::string_view name, required, optional;  // field names separated by spaces
};
constexpr std::array kCommands{
    CommandDef{"tip", "", ""},
    CommandDef{"poke", "block impulse", "at"},
    CommandDef{"push", "block force duration", "at"},
    CommandDef{"break", "hinge", ""},
    CommandDef{"join", "hinge", ""},
};

const KeyDef* find_key(std::string_view name) {
  for (const KeyDef& k : kKeys)
    if (k.name == name) return &k;
  return nullptr;
}

// For names the code itself passes: a miss is a bug here, not a user error.
const KeyDef& key_def(std::string_view name) {
  const KeyDef* k = find_key(name);
  if (!k) throw std::logic_error("scene: undocumented key " + std::string(name));
  return *k;
}

std::string_view table_of(std::string_view key) { return key.substr(0, key.find('.')); }
std::string_view leaf_of(std::string_view key) { return key.substr(key.find('.') + 1); }

std::vector<std::string_view> split(std::string_view s, char sep) {
  std::vector<std::string_view> out;
  while (!s.empty()) {
    const size_t i = s.find(sep);
    out.push_back(s.substr(0, i));
    if (i == std::string_view::npos) break;
    s.remove_prefix(i + 1);
  }
  return out;
}

bool contains_word(std::string_view list, std::string_view word) {
  const auto words = split(list, ' ');
  return std::find(words.begin(), words.end(), word) != words.end();
}

// ---------------------------------------------------------------------------------------------------------------
// Messages

std::string describe(const Range& r) {
  std::string lo, hi;
  if (std::isfinite(r.lo)) lo = (r.lo_open ? "> " : ">= ") + format_number(r.lo);
  if (std::isfinite(r.hi)) hi = (r.hi_open ? "< " : "<= ") + format_number(r.hi);
  if (!lo.empty() && !hi.empty()) return lo + " and " + hi;
  return lo + hi;
}

std::string a_type(const toml::node& n) {
  switch (n.type()) {
    case toml::node_type::string: return "a string";
    case toml::node_type::integer: return "an integer";
    case toml::node_type::floating_point: return "a floating-point number";
    case toml::node_type::boolean: return "a boolean";
    case toml::node_type::array: return "an array";
    case toml::node_type::table: return "a table";
    case toml::node_type::date: return "a date";
    case toml::node_type::time: return "a time";
    case toml::node_type::date_time: return "a date-time";
    case toml::node_type::none: break;
  }
  return "nothing";
}

std::string position(std::string_view source, const toml::source_position& p) {
  return std::string(source) + ":" + std::to_string(p.line) + ":" + std::to_string(p.column);
}

// " (did you mean 'ladder.blocks'?)" for the nearest candidate within two edits, or "". A name without a table
// is also compared with the candidates' last parts, so `blocks` at the top level suggests ladder.blocks.
std::string did_you_mean(std::string_view name, const std::vector<std::string_view>& candidates) {
  const bool bare = name.find('.') == std::string_view::npos;
  std::string_view best;
  size_t best_distance = 3;
  const auto distance = [&](std::string_view c) { return edit_distance_below(name, c, best_distance); };
  for (std::string_view c : candidates) {
    size_t d = distance(c);
    if (bare && c.find('.') != std::string_view::npos) d = std::min(d, distance(leaf_of(c)));
    // d < size: a one-letter name is not "near" every other one-letter name.
    if (d < best_distance && d < name.size()) best = c, best_distance = d;
  }
  return best.empty() ? std::string() : " (did you mean '" + std::string(best) + "'?)";
}

std::vector<std::string_view> file_key_names() {
  std::vector<std::string_view> names(kTables.begin(), kTables.end());
  names.push_back("timeline");
  for (const KeyDef& k : kKeys) names.push_back(k.name);
  return names;
}

// Keys --set may change: everything but the timeline, which is a list of entries.
std::vector<std::string_view> settable_key_names() {
  std::vector<std::string_view> names;
  for (const KeyDef& k : kKeys)
    if (table_of(k.name) != "timeline") names.push_back(k.name);
  return names;
}

// Where a value came from, for messages: its position in the file, or the --set override that supplied it.
struct Site {
  std::string_view source;  // file name
  std::string_view set;     // the override's text when it supplied the value, else empty
  std::string name;         // the key as the user knows it: "ladder.masses[2]", "timeline[0].block"

  std::string at(const toml::source_position& p) const {
    return set.empty() ? position(source, p) : "--set " + std::string(set);
  }
  [[noreturn]] void fail(const toml::source_position& p, const std::string& message) const {
    throw SceneError(at(p) + ": " + message);
  }
  [[noreturn]] void fail(const toml::node& n, const std::string& message) const { fail(n.source().begin, message); }
  Site element(size_t i) const { return {source, set, name + "[" + std::to_string(i) + "]"}; }
  Site field(std::string_view f) const { return {source, set, name + "." + std::string(f)}; }
};

// ---------------------------------------------------------------------------------------------------------------
// Typed conversion of one node, with the checks every key of that kind gets.

double to_number(const toml::node& n, const Site& s, const Range& r) {
  double v = 0;
  if (const auto* i = n.as_integer()) {
    v = static_cast<double>(i->get());
  } else if (const auto* f = n.as_floating_point()) {
    v = f->get();
  } else {
    s.fail(n, s.name + " must be a number, not " + a_type(n));
  }
  if (!std::isfinite(v)) s.fail(n, s.name + " must be finite (got " + format_number(v) + ")");
  if (!r.contains(v)) s.fail(n, s.name + " must be " + describe(r) + " (got " + format_number(v) + ")");
  return v;
}

// Integer keys refuse 6.0: a count or an index written as a float is more likely a slip than intended.
int to_int(const toml::node& n, const Site& s, const Range& r) {
  const auto* i = n.as_integer();
  // A whole number past every range (e.g. `--set ladder.blocks=99999999999999999999`, past 2^63 and so read as a
  // float) is refused for its size, which is what is wrong with it.
  if (const auto* f = n.as_floating_point(); f && std::isfinite(f->get()) && f->get() == std::floor(f->get()) &&
                                             !r.contains(f->get()))
    s.fail(n, s.name + " must be " + describe(r) + " (got " + format_number(f->get()) + ")");
  if (!i) s.fail(n, s.name + " must be an integer, not " + a_type(n));
  const std::int64_t v = i->get();
  if (!r.contains(static_cast<double>(v)))
    s.fail(n, s.name + " must be " + describe(r) + " (got " + std::to_string(v) + ")");
  return static_cast<int>(v);  // every integer range here lies within int
}

bool to_bool(const toml::node& n, const Site& s) {
  const auto* b = n.as_boolean();
  if (!b) s.fail(n, s.name + " must be a boolean (true or false), not " + a_type(n));
  return b->get();
}

std::string to_text(const toml::node& n, const Site& s) {
  const auto* t = n.as_string();
  if (!t) s.fail(n, s.name + " must be a string, not " + a_type(n));
  // A text is sent over DDS and recorded as a C string, which ends at a NUL: a name with one in it reached the
  // clients cut short and made the session log unreadable.
  if (t->get().find('\0') != std::string::npos)
    s.fail(n, s.name + " must not hold a NUL character (U+0000)");
  return t->get();
}

const toml::array& to_array(const toml::node& n, const Site& s, std::string_view of) {
  const auto* a = n.as_array();
  if (!a) s.fail(n, s.name + " must be an array of " + std::string(of) + ", not " + a_type(n));
  return *a;
}

Vec2 to_vec2(const toml::node& n, const Site& s) {
  const toml::array& a = to_array(n, s, "2 numbers");
  if (a.size() != 2)
    s.fail(n, s.name + " must have exactly 2 elements [x, y] (got " + std::to_string(a.size()) + ")");
  return {to_number(*a.get(0), s.element(0), kAnyNumber), to_number(*a.get(1), s.element(1), kAnyNumber)};
}

std::vector<double> to_numbers(const toml::node& n, const Site& s, const Range& r) {
  const toml::array& a = to_array(n, s, "numbers");
  std::vector<double> out;
  out.reserve(a.size());
  for (size_t i = 0; i < a.size(); ++i) out.push_back(to_number(*a.get(i), s.element(i), r));
  return out;
}

// The index of the value in `choices` ("held|pinned|free").
size_t to_choice(const toml::node& n, const Site& s, std::string_view choices) {
  const std::string text = to_text(n, s);
  const auto names = split(choices, '|');
  const auto it = std::find(names.begin(), names.end(), text);
  if (it != names.end()) return static_cast<size_t>(it - names.begin());
  std::string list;
  for (size_t i = 0; i < names.size(); ++i) list += (i == 0 ? "" : i + 1 == names.size() ? " or " : ", ") + std::string(names[i]);
  s.fail(n, s.name + " must be " + list + " (got '" + text + "')" + did_you_mean(text, names));
}

// ---------------------------------------------------------------------------------------------------------------
// Structure: every table and key must be documented. Checked before any value so that a misspelt key is reported
// as such rather than silently left at its default.

struct Problem {
  toml::source_position at;
  std::string message;
};

std::string unknown(std::string_view what, std::string_view name, const std::vector<std::string_view>& candidates) {
  return "unknown " + std::string(what) + " '" + std::string(name) + "'" + did_you_mean(name, candidates);
}

void check_keys(std::string_view table, const toml::table& t, std::vector<Problem>& out) {
  for (auto&& [k, v] : t) {
    const std::string name = std::string(table) + "." + std::string(k.str());
    if (!find_key(name)) out.push_back({k.source().begin, unknown("key", name, file_key_names())});
  }
}

void check_timeline(const toml::node& v, std::vector<Problem>& out) {
  const auto* a = v.as_array();
  if (!a) {
    out.push_back({v.source().begin, "timeline must be an array of tables ([[timeline]]), not " + a_type(v)});
    return;
  }
  for (size_t i = 0; i < a->size(); ++i) {
    const toml::node& e = *a->get(i);
    if (const auto* t = e.as_table())
      check_keys("timeline", *t, out);
    else
      out.push_back({e.source().begin, "timeline[" + std::to_string(i) + "] must be a table, not " + a_type(e)});
  }
}

void check_structure(const toml::table& root, std::string_view source) {
  std::vector<Problem> problems;
  for (auto&& [k, v] : root) {
    const std::string_view name = k.str();
    if (name == "timeline") {
      check_timeline(v, problems);
    } else if (std::find(kTables.begin(), kTables.end(), name) == kTables.end()) {
      problems.push_back({k.source().begin, unknown(v.is_table() ? "table" : "key", name, file_key_names())});
    } else if (const auto* t = v.as_table()) {
      check_keys(name, *t, problems);
    } else {
      problems.push_back({v.source().begin, std::string(name) + " must be a table, not " + a_type(v)});
    }
  }
  if (problems.empty()) return;
  // The first problem in the file, not in toml++'s (alphabetical) key order.
  const auto first = std::min_element(problems.begin(), problems.end(),
                                      [](const Problem& a, const Problem& b) { return a.at < b.at; });
  throw SceneError(position(source, first->at) + ": " + first->message);
}

// ---------------------------------------------------------------------------------------------------------------
// Overrides

using Origins = std::map<std::string, std::string, std::less<>>;  // key -> the override text that set it

std::string_view trim(std::string_view s) {
  const size_t b = s.find_first_not_of(" \t");
  if (b == std::string_view::npos) return {};
  return s.substr(b, s.find_last_not_of(" \t") - b + 1);
}

// VALUE as TOML, or as a bare string when it is not valid TOML (so `sim.integrator=rk4` needs no quotes). An array
// or inline table that is not valid TOML is an error (what TOML found wrong, and its column in VALUE), not a string.
void assign_value(toml::table& target, std::string_view leaf, std::string_view value) {
  constexpr std::string_view kPrefix = "v = ";
  const std::string text(trim(value));
  try {
    toml::table parsed = toml::parse(std::string(kPrefix) + std::string(value));
    if (parsed.size() == 1 && parsed.contains("v")) {
      parsed.get("v")->visit([&](auto&& node) { target.insert_or_assign(leaf, std::move(node)); });
      return;
    }
  } catch (const toml::parse_error& e) {
    // not TOML: a number TOML cannot hold (an integer past 2^63), else a bare string; but not an array or a table
    if (text.starts_with('[') || text.starts_with('{')) {
      const auto column = static_cast<long>(e.source().begin.column) - static_cast<long>(kPrefix.size());
      throw SceneError(std::string(text.starts_with('[') ? "not a valid TOML array" : "not a valid TOML table") +
                       (column >= 1 ? " (near character " + std::to_string(column) + ")" : std::string()) + ": " +
                       std::string(e.description()));
    }
  }
  char* end = nullptr;
  const double x = text.empty() ? 0 : std::strtod(text.c_str(), &end);
  // (A decimal number past a double's range, 1e400, is read as inf: "must be finite (got inf)", not "a string".)
  if (end && *end == '\0' && !std::isnan(x) && text.find_first_of("xXnNiI") == std::string::npos) {
    target.insert_or_assign(leaf, x);  // (ranges then say what is wrong with it, not "a string")
    return;
  }
  target.insert_or_assign(leaf, text);
}

Origins apply_overrides(toml::table& root, const std::vector<std::string>& overrides) {
  if (overrides.size() > kMaxOverrides)
    throw SceneError("at most " + std::to_string(kMaxOverrides) + " --set overrides (got " +
                     std::to_string(overrides.size()) + ")");
  Origins origins;
  for (const std::string& text : overrides) {
    const auto fail = [&](const std::string& message) { throw SceneError("--set " + text + ": " + message); };
    const size_t eq = text.find('=');
    if (eq == std::string::npos) fail("expected KEY=VALUE, e.g. sim.dt=0.0005");
    const std::string_view key = trim(std::string_view(text).substr(0, eq));
    const KeyDef* def = find_key(key);
    if (def && table_of(key) == "timeline")
      fail(std::string(key) + ": the timeline is a list of [[timeline]] entries, given in the scene file only, not "
           "with --set; edit a copy of the scene");
    if (!def) fail(unknown("key", key, settable_key_names()));
    const std::string table(table_of(key));
    if (!root.contains(table)) root.insert_or_assign(table, toml::table{});
    try {
      assign_value(*root.get_as<toml::table>(table), leaf_of(key), std::string_view(text).substr(eq + 1));
    } catch (const SceneError& e) {
      fail(std::string(key) + ": " + e.what());
    }
    origins.insert_or_assign(std::string(key), text);  // the last override of a key wins
  }
  return origins;
}

// ---------------------------------------------------------------------------------------------------------------
// Reading documented keys out of the merged document

class Reader {
 public:
  Reader(const toml::table& root, std::string_view source, const Origins& origins)
      : root_(root), source_(source), origins_(origins) {}

  const toml::node* find(std::string_view key) const {
    const auto* t = root_.get_as<toml::table>(table_of(key));
    return t ? t->get(leaf_of(key)) : nullptr;
  }
  bool overridden(std::string_view key) const { return origins_.find(key) != origins_.end(); }
  std::string_view source() const { return source_; }
  Site site(std::string_view key) const {
    const auto it = origins_.find(key);
    return {source_, it == origins_.end() ? std::string_view() : std::string_view(it->second), std::string(key)};
  }
  // Of keys whose values disagree, the one to blame: the first of them that the user has just given (by --set, or as
  // a live setting), else the first given at all; empty when none was given.
  std::string_view blamed(std::initializer_list<std::string_view> keys) const {
    std::string_view key;
    for (const std::string_view k : keys) {
      if (!find(k)) continue;
      if (key.empty() || (overridden(k) && !overridden(key))) key = k;
    }
    return key;
  }
  // Where a given key's value came from ("file.toml:24:14" or "--set ladder.hinge=corner"); empty when not given.
  std::string where(std::string_view key) const {
    const toml::node* n = find(key);
    return n ? site(key).at(n->source().begin) : std::string();
  }

  void get(std::string_view key, int& out) const {
    if (const toml::node* n = find(key)) out = to_int(*n, site(key), key_def(key).range);
  }
  void get(std::string_view key, double& out) const {
    if (const toml::node* n = find(key)) out = to_number(*n, site(key), key_def(key).range);
  }
  void get(std::string_view key, bool& out) const {
    if (const toml::node* n = find(key)) out = to_bool(*n, site(key));
  }
  void get(std::string_view key, std::string& out) const {
    if (const toml::node* n = find(key)) out = to_text(*n, site(key));
  }
  void get(std::string_view key, Vec2& out) const {
    if (const toml::node* n = find(key)) out = to_vec2(*n, site(key));
  }
  void get(std::string_view key, std::vector<double>& out) const {
    if (const toml::node* n = find(key)) out = to_numbers(*n, site(key), key_def(key).range);
  }
  // A Kind::Choice key: `values` lists the results in the order of the key's choices.
  template <class T, size_t N>
  void get(std::string_view key, T& out, const std::array<T, N>& values) const {
    if (const toml::node* n = find(key)) out = values.at(to_choice(*n, site(key), key_def(key).choices));
  }
  // A name the core parses itself (integrator, solver), so a name it adds needs no change here.
  template <class T>
  void get(std::string_view key, T& out, T (*parse)(const std::string&)) const {
    const toml::node* n = find(key);
    if (!n) return;
    const Site s = site(key);
    try {
      out = parse(to_text(*n, s));
    } catch (const std::invalid_argument& e) {
      s.fail(*n, s.name + ": " + e.what());
    }
  }

 private:
  const toml::table& root_;
  std::string_view source_;
  const Origins& origins_;
};

// blocks and masses must agree; masses alone set blocks.
void read_blocks(const Reader& r, model::LadderSpec& l) {
  r.get("ladder.blocks", l.blocks);
  r.get("ladder.masses", l.masses);
  const toml::node* masses = r.find("ladder.masses");
  if (!masses) return;
  const Site s = r.site("ladder.masses");
  const auto count = l.masses.size();
  if (count == 0) s.fail(*masses, "ladder.masses must not be empty");
  if (!r.find("ladder.blocks")) {
    if (count > static_cast<size_t>(kMaxBlocks))
      s.fail(*masses, "ladder.masses must have at most " + std::to_string(kMaxBlocks) + " entries");
    l.blocks = static_cast<int>(count);
    return;
  }
  if (count == static_cast<size_t>(l.blocks)) return;
  const std::string message = "ladder.masses has " + std::to_string(count) + " entries but ladder.blocks is " +
                              std::to_string(l.blocks);
  // Blame whichever of the two the user just changed on the command line.
  const std::string_view key = r.blamed({"ladder.masses", "ladder.blocks"});
  r.site(key).fail(*r.find(key), message);
}

// The rolling hinge's keys against each other and the thickness. Each error is at the key that makes it, or at the
// other key of the pair when only that one came from the command line; the message then says where the first is.
void check_hinge(const Reader& r, const model::LadderSpec& l) {
  const auto fail = [&](std::string_view key, std::string_view other, const std::string& message) {
    const std::string_view at = r.blamed({key, other});
    if (at.empty()) throw SceneError(std::string(r.source()) + ": " + message);
    const std::string_view left = at == key ? other : key;
    const std::string there = r.overridden(at) && !r.overridden(left) ? r.where(left) : std::string();
    const std::string where_left = there.empty() ? "" : " (" + std::string(left) + " is given at " + there + ")";
    r.site(at).fail(*r.find(at), message + where_left);
  };
  if (l.end_radius > 0.5 * l.thickness)
    fail("ladder.end_radius", "ladder.thickness",
         "ladder.end_radius must be at most half of ladder.thickness (got " + format_number(l.end_radius) +
             " m with a thickness of " + format_number(l.thickness) + " m)");
  // A pair's two arc centres are 2 end_radius apart and their direction is the contact's: at a radius below a
  // millionth of the thickness that direction is lost in the rounding of the blocks' positions (at 1e-300 the two
  // centres are one point, and the engine could not place the hinge at all).
  if (l.end_radius > 0 && l.end_radius < 1e-6 * l.thickness)
    fail("ladder.end_radius", "ladder.thickness",
         "ladder.end_radius must be 0 (the corner hinge) or at least 1e-6 of ladder.thickness (got " +
             format_number(l.end_radius) + " m with a thickness of " + format_number(l.thickness) +
             " m): below that the contact's direction is lost in the rounding of the blocks' positions");
  if (l.end_radius > 0 && l.hinge != model::HingeKind::Rolling)
    fail("ladder.end_radius", "ladder.hinge",
         "ladder.end_radius needs ladder.hinge = \"rolling\" (a corner hinge turns about the corner itself: with "
         "ladder.hinge = \"corner\", ladder.end_radius must be 0)");
  if (l.hinge == model::HingeKind::Rolling && l.hinge_inset != 0)
    fail("ladder.hinge_inset", "ladder.hinge",
         "ladder.hinge_inset is for corner hinges; a rolling hinge's pivot is set by ladder.end_radius (with "
         "ladder.hinge = \"rolling\", ladder.hinge_inset must be 0)");
}

void read_ladder(const Reader& r, model::LadderSpec& l) {
  using model::Start;
  using model::Top;
  read_blocks(r, l);
  r.get("ladder.length", l.length);
  r.get("ladder.thickness", l.thickness);
  r.get("ladder.mass", l.mass);
  r.get("ladder.top", l.top, std::array{Top::Held, Top::Pinned, Top::Free});
  r.get("ladder.start", l.start, std::array{Start::Hanging, Start::Straight});
  r.get("ladder.logic", l.logic);
  r.get("ladder.flip_impact", l.flip_impact, std::array{model::FlipImpact::Face, model::FlipImpact::Corner});
  r.get("ladder.hinge_inset", l.hinge_inset);
  r.get("ladder.hinge", l.hinge, std::array{model::HingeKind::Corner, model::HingeKind::Rolling});
  r.get("ladder.end_radius", l.end_radius);
  check_hinge(r, l);
  r.get("ladder.tip_duration", l.tip_duration);
  r.get("ladder.unlock_threshold", l.unlock_threshold);
  r.get("ladder.capture_distance", l.capture_distance);
  r.get("initial.kick_omega", l.kick_omega);
  r.get("initial.tilt", l.tilt);
}

}  // namespace

std::string format_number(double v) {
  if (std::isnan(v)) return "nan";
  if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
  // Whole numbers print as integers: to_chars would pick "1e+07" for ten million.
  if (v == std::trunc(v) && std::abs(v) < 1e15) return std::to_string(static_cast<long long>(v));
  std::array<char, 32> buf{};
  const auto r = std::to_chars(buf.data(), buf.data() + buf.size(), v);
  return std::string(buf.data(), r.ptr);
}

const std::vector<AccuracyPreset>& accuracy_presets() {
  using core::Integrator, core::Stabilization, core::SolverKind;
  static const std::vector<AccuracyPreset> presets{
      {"fast", Integrator::SymplecticEuler, Stabilization::Position, SolverKind::Newton, 1e-6, 20, 1},
      {"balanced", Integrator::Midpoint, Stabilization::Position, SolverKind::Newton, 1e-12, 30, 1},
      {"accurate", Integrator::RK4, Stabilization::Position, SolverKind::Newton, 1e-12, 20, 4},
  };
  return presets;
}

void apply_accuracy(std::string_view name, Scene& s) {
  for (const AccuracyPreset& p : accuracy_presets()) {
    if (p.name != name) continue;
    s.options.integrator = p.integrator;
    s.options.stabilization = p.stabilization;
    s.options.solver = p.solver;
    s.options.tolerance = p.tolerance;
    s.options.max_iterations = p.max_iterations;
    s.substeps = p.substeps;
    return;
  }
  throw std::invalid_argument("unknown accuracy preset '" + std::string(name) + "' (expected fast, balanced or accurate)");
}

std::string accuracy_of(const Scene& s) {
  const core::Options& o = s.options;
  if (o.adaptive) return "custom";  // no preset steps adaptively
  for (const AccuracyPreset& p : accuracy_presets())
    if (o.integrator == p.integrator && o.stabilization == p.stabilization && o.solver == p.solver &&
        o.tolerance == p.tolerance && o.max_iterations == p.max_iterations && s.substeps == p.substeps)
      return std::string(p.name);
  return "custom";
}

namespace {

// |g| beyond kMaxGravity is refused: at 1e308 the first step's velocities overflow, and every step fails.
void check_gravity(const Reader& r, const Vec2& g) {
  const toml::node* n = r.find("sim.gravity");
  if (!n || g.norm() <= kMaxGravity) return;
  r.site("sim.gravity").fail(*n, "sim.gravity must have |g| <= " + format_number(kMaxGravity) +
                                     " m/s^2, about 100 g (got [" + format_number(g.x()) + ", " +
                                     format_number(g.y()) + "])");
}

// A step of sim.dt runs sim.substeps steps in the server's tick: a sub-step below the smallest sim.dt would make one
// tick's step take up to 1000 times as long as the finest time step allowed, for no gain in accuracy.
void check_substep(const Reader& r, const Scene& s) {
  if (s.dt / s.substeps >= kMinSubstep * (1 - 1e-12)) return;  // 1e-4 / 1000 is 1e-7 up to rounding
  // Blame the key that the user just gave (a --set, or a live setting), else the file's substeps, dt or preset.
  const std::string_view key = r.blamed({"sim.substeps", "sim.dt", "sim.accuracy"});
  const toml::node* n = key.empty() ? nullptr : r.find(key);
  const std::string message = "sim.dt / sim.substeps must be >= 1e-07 s, the smallest time step (got " +
                              format_number(s.dt) + " / " + std::to_string(s.substeps) + " = " +
                              format_number(s.dt / s.substeps) + " s)";
  if (!n) throw SceneError(std::string(r.source()) + ": " + message);  // cannot happen: one of the three set it
  r.site(key).fail(*n, message);
}

// The drags are explicit: a step may take away at most a block's whole velocity, c dt / substeps <= 1 (measured:
// every integrator steps the classic scene at c h = 1 for dt 0.1 and 0.01 s; at c h = 100 all fail).
void check_drag(const Reader& r, const Scene& s) {
  const double h = s.dt / s.substeps;
  for (const auto& [key, c] : {std::pair<std::string_view, double>{"damping.linear", s.options.linear_damping},
                               {"damping.angular", s.options.angular_damping}}) {
    if (c * h <= 1 + 1e-12) continue;  // 1000 /s at 1 ms is 1 up to rounding
    const std::string message = std::string(key) + " must be <= 1 / (sim.dt / sim.substeps) = " +
                                format_number(1 / h) + " /s, so that one step takes at most a block's whole " +
                                "velocity (got " + format_number(c) + " at sim.dt = " + format_number(s.dt) +
                                " s, sim.substeps = " + std::to_string(s.substeps) + ")";
    // Blame the drag when it was given here, else the step that was (a live `set sim.dt` under a strong drag).
    std::string_view blame = key;
    if (!r.find(key) || (!r.overridden(key) && (r.overridden("sim.dt") || r.overridden("sim.substeps"))))
      blame = r.blamed({"sim.dt", "sim.substeps", "sim.accuracy"});
    if (const toml::node* n = blame.empty() ? nullptr : r.find(blame)) r.site(blame).fail(*n, message);
    throw SceneError(std::string(r.source()) + ": " + message);  // cannot happen: one of them was given
  }
}

void read_options(const Reader& r, Scene& s) {
  core::Options& o = s.options;
  r.get("sim.dt", s.dt);
  r.get("sim.substeps", s.substeps);
  r.get("sim.integrator", o.integrator, &core::integrator_from_string);
  r.get("sim.stabilization", o.stabilization, &core::stabilization_from_string);
  r.get("solver.kind", o.solver, &core::solver_from_string);
  r.get("solver.tolerance", o.tolerance);
  r.get("solver.max_iterations", o.max_iterations);
  r.get("solver.threads", o.threads);
  if (r.find("sim.accuracy")) {
    // The preset sets its knobs; a knob given in the same place (the file, or --set) or a later one (--set over a
    // file's preset) wins over it, so `--set sim.accuracy=fast` overrides a scene file's integrator.
    const Scene given = s;
    std::string name;
    r.get("sim.accuracy", name, std::array<std::string, 3>{"fast", "balanced", "accurate"});
    apply_accuracy(name, s);
    const bool preset_set = r.overridden("sim.accuracy");
    const auto wins = [&](std::string_view key) { return r.find(key) && (!preset_set || r.overridden(key)); };
    if (wins("sim.substeps")) s.substeps = given.substeps;
    if (wins("sim.integrator")) o.integrator = given.options.integrator;
    if (wins("sim.stabilization")) o.stabilization = given.options.stabilization;
    if (wins("solver.kind")) o.solver = given.options.solver;
    if (wins("solver.tolerance")) o.tolerance = given.options.tolerance;
    if (wins("solver.max_iterations")) o.max_iterations = given.options.max_iterations;
  }
  r.get("sim.adaptive", o.adaptive);
  r.get("sim.error_tolerance", o.error_tolerance);
  r.get("sim.gravity", o.gravity);
  r.get("damping.linear", o.linear_damping);
  r.get("damping.angular", o.angular_damping);
  r.get("damping.hinge", o.hinge_friction);
  check_gravity(r, o.gravity);
  check_substep(r, s);
  check_drag(r, s);
}

const CommandDef& command_def(std::string_view name) {
  for (const CommandDef& c : kCommands)
    if (c.name == name) return c;
  throw std::logic_error("scene: no command " + std::string(name));
}

// Refuses fields the command does not take, and requires the ones it needs.
void check_fields(const toml::table& e, const Site& s, const CommandDef& def) {
  for (auto&& [k, v] : e) {
    const std::string_view f = k.str();
    if (f == "t" || f == "command" || contains_word(def.required, f) || contains_word(def.optional, f)) continue;
    s.fail(k.source().begin, s.name + "." + std::string(f) + " does not apply to command '" + std::string(def.name) +
                                 "'");
  }
  for (std::string_view f : split(def.required, ' '))
    if (!e.contains(f)) s.fail(e, s.name + ": command '" + std::string(def.name) + "' needs '" + std::string(f) + "'");
}

TimedCommand read_entry(const toml::table& e, const Site& s, int blocks) {
  TimedCommand c;
  c.where = position(s.source, e.source().begin);
  const toml::node* command = e.get("command");
  if (!command) s.fail(e, s.name + " needs a command (tip, poke, push, break or join)");
  const std::string_view choices = key_def("timeline.command").choices;
  const std::string_view name = split(choices, '|').at(to_choice(*command, s.field("command"), choices));
  const toml::node* t = e.get("t");
  if (!t) s.fail(e, s.name + " needs a time t [s]");
  c.t = to_number(*t, s.field("t"), key_def("timeline.t").range);
  check_fields(e, s, command_def(name));

  // The fields each command needs were required by check_fields; the optional `at` defaults to the centre.
  const Range index{0, static_cast<double>(blocks), false, true};  // blocks and hinges are both 0 .. blocks-1
  const auto integer = [&](const char* f) { return to_int(*e.get(f), s.field(f), index); };
  const auto pair = [&](const char* f) { return to_vec2(*e.get(f), s.field(f)); };
  const auto sized = [&](const char* f, double limit, const char* unit, const char* what) {
    const core::Vec2 v = pair(f);
    const double size = std::hypot(v.x(), v.y());  // (hypot: the sum of squares of 1e300 would overflow)
    if (!(size <= limit))
      s.fail(*e.get(f), s.field(f).name + " must be at most " + format_number(limit) + " " + unit + " " + what +
                            " (got " + format_number(size) + " " + unit + ")");
    return v;
  };
  const toml::node* at = e.get("at");
  if (name == "tip") {
    c.action = model::Tip{};
  } else if (name == "poke") {
    const int block = integer("block");
    const core::Vec2 impulse = sized("impulse", kMaxImpulse, "N s", "in size");
    c.action = model::Poke{block, impulse,
                           at ? std::optional(sized("at", kReach, "m", "from the origin")) : std::nullopt};
  } else if (name == "push") {
    const int block = integer("block");
    const core::Vec2 force = sized("force", kMaxForce, "N", "in size");
    const double duration = to_number(*e.get("duration"), s.field("duration"), key_def("timeline.duration").range);
    c.action = model::Push{block, force, at ? pair("at") : core::Vec2::Zero(), duration};
  } else if (name == "break") {
    c.action = model::Break{integer("hinge")};
  } else {
    c.action = model::Join{integer("hinge")};
  }
  return c;
}

std::vector<TimedCommand> read_timeline(const toml::table& root, std::string_view source, int blocks) {
  std::vector<TimedCommand> out;
  const auto* entries = root.get_as<toml::array>("timeline");  // its shape was checked by check_structure
  if (!entries) return out;
  for (size_t i = 0; i < entries->size(); ++i) {
    const Site s{source, {}, "timeline[" + std::to_string(i) + "]"};
    out.push_back(read_entry(*entries->get_as<toml::table>(i), s, blocks));
  }
  std::stable_sort(out.begin(), out.end(), [](const TimedCommand& a, const TimedCommand& b) { return a.t < b.t; });
  return out;
}

toml::table parse_document(std::string_view text, const std::string& source) {
  try {
    return toml::parse(text, std::string_view(source));
  } catch (const toml::parse_error& e) {
    throw SceneError(position(source, e.source().begin) + ": " + std::string(e.description()));
  }
}

std::string read_file(const std::string& path) {
  const auto fail = [&](const std::string& reason) -> void {
    throw SceneError(path + ": cannot open scene file (" + reason + ")");
  };
  std::error_code ec;
  // An ifstream opens a directory without complaint and then reads nothing.
  if (std::filesystem::is_directory(path, ec)) fail("it is a directory");
  // (A session log holds a scene's text up to this size: a larger one would be recorded and then refused.)
  const std::string too_large = "it is larger than " + std::to_string(kMaxSceneFile >> 20) + " MiB";
  if (const auto size = std::filesystem::file_size(path, ec); !ec && size > kMaxSceneFile) fail(too_large);
  errno = 0;
  std::ifstream in(path, std::ios::binary);
  if (!in) fail(errno != 0 ? std::generic_category().message(errno) : "unknown error");
  std::ostringstream text;
  text << in.rdbuf();
  if (in.bad()) fail("read error");
  if (text.view().size() > kMaxSceneFile) fail(too_large);  // (a file whose size was not known before)
  return text.str();
}

std::string pad(std::string_view s, size_t width) {
  std::string out(s);
  out.resize(std::max(width, s.size()), ' ');
  return out;
}

std::string type_name(const KeyDef& k) {
  switch (k.kind) {
    case Kind::Integer: return "int";
    case Kind::Number: return "number";
    case Kind::Boolean: return "bool";
    case Kind::String: return "string";
    case Kind::Choice: return std::string(k.choices);
    case Kind::Pair: return "[x, y]";
    case Kind::Numbers: return "[number, ...]";
  }
  return "?";
}

}  // namespace

Scene parse_scene(std::string_view toml_text, const std::string& source_name,
                  const std::vector<std::string>& overrides) {
  toml::table root = parse_document(toml_text, source_name);
  check_structure(root, source_name);
  const Origins origins = apply_overrides(root, overrides);
  const Reader r(root, source_name, origins);
  Scene s;
  s.source = source_name;
  r.get("scene.name", s.name);
  if (s.name.size() > kMaxSceneName)
    r.site("scene.name").fail(*r.find("scene.name"), "scene.name must be at most " + std::to_string(kMaxSceneName) +
                                                         " bytes long (got " + std::to_string(s.name.size()) + ")");
  if (s.name.empty()) s.name = std::filesystem::path(source_name).stem().string();  // a title all the same
  r.get("scene.description", s.description);
  read_ladder(r, s.ladder);
  r.get("ladder.depth", s.depth);
  read_options(r, s);
  s.timeline = read_timeline(root, source_name, s.ladder.blocks);
  s.text = std::string(toml_text);
  s.overrides = overrides;
  return s;
}

Scene remake_scene(const std::string& text, const std::string& source, const std::vector<std::string>& overrides,
                   bool timeline_dropped) {
  Scene s = parse_scene(text, source, overrides);
  if (timeline_dropped) {
    s.timeline.clear();
    s.timeline_dropped = true;
  }
  return s;
}

bool is_scene_table(std::string_view name) {
  return name == "timeline" || std::find(kTables.begin(), kTables.end(), name) != kTables.end();
}

bool is_live_key(std::string_view key) {
  const std::string_view table = table_of(key);
  return find_key(key) && (table == "sim" || table == "solver" ||
                           table == "damping");
}

Scene with_live_setting(const Scene& scene, const std::string& setting, std::string_view also_live) {
  toml::table root;
  Scene s = scene;
  try {
    const Origins origins = apply_overrides(root, {setting});
    const std::string key = origins.begin()->first;
    if (!is_live_key(key))
      throw SceneError("--set " + setting + ": " + key + " cannot change while the ladder runs (live keys: sim.*, " +
                       "solver.*, damping.*" + (also_live.empty() ? "" : ", ") + std::string(also_live) +
                       "); set it in the scene file and load the scene again");
    read_options(Reader(root, scene.source, origins), s);
  } catch (const SceneError& e) {
    const std::string_view what = e.what();
    throw SceneError(std::string(what.starts_with("--set ") ? what.substr(6) : what));
  }
  return s;
}

std::string live_settings(const Scene& s) {
  const core::Options& o = s.options;
  std::string out;
  const auto line = [&](std::string_view key, const std::string& value) {
    out += std::string(key) + "=" + value + "\n";
  };
  line("sim.dt", format_number(s.dt));
  line("sim.substeps", std::to_string(s.substeps));
  line("sim.accuracy", accuracy_of(s));
  line("sim.integrator", core::to_string(o.integrator));
  line("sim.stabilization", core::to_string(o.stabilization));
  line("sim.adaptive", o.adaptive ? "true" : "false");
  line("sim.error_tolerance", format_number(o.error_tolerance));
  line("sim.gravity", "[" + format_number(o.gravity.x()) + ", " + format_number(o.gravity.y()) + "]");
  line("solver.kind", core::to_string(o.solver));
  line("solver.tolerance", format_number(o.tolerance));
  line("solver.max_iterations", std::to_string(o.max_iterations));
  line("solver.threads", std::to_string(o.threads));
  line("damping.linear", format_number(o.linear_damping));
  line("damping.angular", format_number(o.angular_damping));
  line("damping.hinge", format_number(o.hinge_friction));
  line("ladder.depth", format_number(s.depth));  // not live: carried here for the viewer, which draws it
  line("ladder.hinge", s.ladder.hinge == model::HingeKind::Rolling ? "rolling" : "corner");  // likewise
  // To the last bit, in the shortest form that reads back the same: the viewer draws the ends from it
  // (format_number keeps 3 digits).
  char radius[32];
  const auto written = std::to_chars(radius, radius + sizeof radius, s.ladder.end_radius);
  line("ladder.end_radius", std::string(radius, written.ptr));
  return out;
}

Scene load_scene(const std::string& path, const std::vector<std::string>& overrides) {
  const std::string text = read_file(path);
  // An empty file (or one of comments only) would be the defaults, which is almost always a mistake: the wrong file,
  // or one cut short. (parse_scene takes "" for the built-in scene and tests: it is only a file that must say so.)
  if (parse_document(text, path).empty())
    throw SceneError(path + ":1:1: the scene file is empty; a scene needs at least one table, e.g. [ladder] with "
                            "blocks = 6 (docs/scenes.md lists every key)");
  return parse_scene(text, path, overrides);
}

std::string keys_help() {
  size_t name_width = 0, type_width = 0;
  for (const KeyDef& k : kKeys) {
    name_width = std::max(name_width, k.name.size());
    type_width = std::max(type_width, type_name(k).size());
  }
  std::string out = "Scene keys, each usable with --set KEY=VALUE:\n";
  bool timeline = false;
  for (const KeyDef& k : kKeys) {
    if (!timeline && table_of(k.name) == "timeline") {
      timeline = true;
      out += "\nThe fields of a [[timeline]] entry, in a scene file only (not with --set):\n";
    }
    const std::string range = k.range_text.empty() ? describe(k.range) : std::string(k.range_text);
    out += "  " + pad(k.name, name_width) + "  " + pad(type_name(k), type_width) + "  " + std::string(k.help);
    if (!range.empty()) out += " (" + range + ")";
    out += "\n";
  }
  return out;
}

}  // namespace ladder::scene
