// What the physics thread hands over, made from the session: the state frame, the scene's description, the
// percentiles of the Stats, and the final guard that keeps a non-finite number from reaching a client.
#pragma once

#include "daemon/handoff.hpp"
#include "daemon/outbox.hpp"
#include "daemon/session.hpp"

#include <cstdint>
#include <string>
#include <vector>

namespace ladder::daemon {

// Percentiles of a window of samples [us]; the window is cleared.
struct Percentiles {
  double p50 = 0, p99 = 0, max = 0;
};
Percentiles percentiles(std::vector<double>& v);

// The session's state as State publishes it; commands_applied counts the commands taken so far.
void fill_frame(const Session& s, std::uint64_t commands_applied, StateFrame& f);

// The final guard before a State is handed over: the name of its first non-finite number, or "" when all are
// finite. The commands' checks and the step's watchdog should leave none; one that slips through must not reach
// a client (a viewer that divides by it, or a controller that feeds it back, fails far from the cause).
std::string non_finite_in(const StateFrame& f);
// The same for the session's state as State would publish it (a re-run's and a resumed session's check).
std::string non_finite_in(const Session& s);

// Replaces a non-finite number by 0 and counts it, naming the field in `fields` (Stats and events are figures for
// people and plots: a 0 there with a log line is better than a NaN that breaks every reader).
void finite_or_zero(double& v, const char* name, std::string& fields, std::uint64_t& count);

// The running scene as SceneInfo and the log describe it.
SceneOut scene_out(const Session& s);

}  // namespace ladder::daemon
