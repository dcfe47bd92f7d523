#include "daemon/tick_log.hpp"

#include "daemon/server.hpp"

#include <cerrno>
#include <cstring>

namespace ladder::daemon {

TickLog::TickLog(const ServerConfig& config) : path_(config.tick_log) {
  if (path_.empty()) return;
  file_.reset(std::fopen(path_.c_str(), "w"));
  if (!file_) throw OutputError("cannot create the tick log '" + path_ + "': " + std::strerror(errno));
  std::fprintf(file_.get(),
               "# %s tick log, sim id '%s', physics rate %g Hz: one line per tick of the real-time loop.\n"
               "# start_ns: when the tick started, on CLOCK_MONOTONIC [ns]; late_ns: how late that was against its "
               "deadline [ns]\n"
               "# (0 while running at real-time factor 0); step_ns, steps: time in and number of physics steps in the "
               "tick;\n"
               "# commands: commands applied since the previous tick's end; published: 1 if the tick handed a state "
               "over.\n"
               "# tick start_ns late_ns step_ns steps commands published\n",
               kServerVersion.c_str(), config.sim_id.c_str(), config.rates.physics);
}

void TickLog::write(const std::vector<TickRecord>& ticks) {
  if (!file_ || ticks.empty()) return;
  for (const TickRecord& t : ticks)
    std::fprintf(file_.get(), "%llu %lld %lld %lld %u %u %d\n", static_cast<unsigned long long>(t.tick),
                 static_cast<long long>(t.start_ns), static_cast<long long>(t.late_ns),
                 static_cast<long long>(t.step_ns), t.steps, t.commands, t.published ? 1 : 0);
  std::fflush(file_.get());
}

bool TickLog::complete() { return !file_ || (std::fflush(file_.get()) == 0 && !std::ferror(file_.get())); }

}  // namespace ladder::daemon
