// ladder-server-bench: starts a real ladderd per configuration and measures it over DDS on loopback:
// command-to-ack latency, the lateness of every tick at the physics rate (from the server's --tick-log), and state
// delivery (rate, latency, gaps) to 1 and 8 subscribers, for several ladder sizes, with the CPU time the hypervisor
// took meanwhile. Prints one table row per configuration (docs/benchmarks.md).
#include "client.hpp"
#include "process.hpp"

#include <CLI/CLI.hpp>

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <fstream>
#include <functional>
#include <memory>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <thread>
#include <vector>

#include <unistd.h>

namespace {

using ladder::client::Client;
using ladder::client::Millis;
using Clock = std::chrono::steady_clock;

// The middle value, or the mean of the two middle ones.
double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(q * static_cast<double>(v.size() - 1))];
}

struct Delivery {
  std::size_t states = 0, gaps = 0;
  std::vector<double> latency_ms;
};

// One tick of the server's tick log (ladderd --tick-log): start and lateness on CLOCK_MONOTONIC [ns], the time
// of its steps [ns].
struct Tick {
  long long start = 0, late = 0, step = 0;
};

// The ticks in the log that started within [from, to] (steady_clock, which is CLOCK_MONOTONIC in this process as in
// the server's).
std::vector<Tick> read_ticks(const std::string& path, Clock::time_point from, Clock::time_point to) {
  const auto ns = [](Clock::time_point t) {
    return static_cast<long long>(std::chrono::nanoseconds(t.time_since_epoch()).count());
  };
  std::vector<Tick> out;
  std::ifstream in(path);
  for (std::string line; std::getline(in, line);) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream f(line);
    long long tick = 0;
    Tick t;
    if ((f >> tick >> t.start >> t.late >> t.step) && t.start >= ns(from) && t.start <= ns(to)) out.push_back(t);
  }
  return out;
}

// The time the hypervisor gave this machine's virtual CPUs to others ("steal", all CPUs together) since boot [ms],
// from /proc/stat; 0 where it is not counted (no virtual machine). During a stolen interval no thread of the machine
// runs, whatever its priority.
double steal_ms() {
  std::ifstream in("/proc/stat");
  std::string cpu;
  double user, nice, system, idle, iowait, irq, softirq, steal = 0;
  in >> cpu >> user >> nice >> system >> idle >> iowait >> irq >> softirq >> steal;
  return 1e3 * steal / static_cast<double>(sysconf(_SC_CLK_TCK));
}

// One subscriber: counts the states it takes for `seconds`, their latency and the sequence numbers it missed.
Delivery subscribe(int domain, const std::string& sim_id, double seconds) {
  Client c(domain, sim_id, "sub");
  Delivery d;
  if (!c.wait_for_server(Millis(20000))) return d;
  std::uint64_t last = 0;
  const auto end = Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(seconds));
  while (Clock::now() < end) {
    const auto s = c.wait_state([&](const ladder::client::State& st) { return st.seq > last; }, Millis(100));
    if (!s) continue;
    if (last && s->seq > last + 1) d.gaps += s->seq - last - 1;
    last = s->seq;
    ++d.states;
    d.latency_ms.push_back(1e3 * s->latency);
  }
  return d;
}

// The subscriber's figures as a file: "states gaps" on the first line, then one latency [ms] per line.
void write_delivery(const Delivery& d, const std::string& path) {
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (!f) return;
  std::fprintf(f, "%zu %zu\n", d.states, d.gaps);
  for (double l : d.latency_ms) std::fprintf(f, "%.6f\n", l);
  std::fclose(f);
}
// The figures a subscriber process wrote, or nothing (and why) if it did not.
std::optional<Delivery> read_delivery(const std::string& path) {
  Delivery d;
  std::ifstream in(path);
  if (!(in >> d.states >> d.gaps)) return std::nullopt;
  for (double l; in >> l;) d.latency_ms.push_back(l);
  return d;
}

// This program's own path, to start subscribers as processes of their own.
std::string self_path() {
  char buf[4096];
  const ssize_t n = readlink("/proc/self/exe", buf, sizeof buf - 1);
  if (n <= 0) throw std::runtime_error("cannot find this program's path (/proc/self/exe) to start subscribers");
  return std::string(buf, static_cast<std::size_t>(n));
}

// The subscribers of one configuration: each a thread of this program (same_process; they share one Cyclone domain
// instance and its receive threads with the control client), or each a process of its own, as separate viewers on
// this machine are (more processes and threads on the same cores: docs/benchmarks.md has both).
std::vector<Delivery> subscribers_run(int subs, bool same_process, int domain, const std::string& sim_id,
                                      double seconds, const std::function<void()>& meanwhile) {
  std::vector<Delivery> delivered(static_cast<std::size_t>(subs));
  if (same_process) {
    std::vector<std::thread> threads;
    for (int i = 0; i < subs; ++i)
      threads.emplace_back([&, i] { delivered[static_cast<std::size_t>(i)] = subscribe(domain, sim_id, seconds); });
    // A failure meanwhile (a server that stops answering) waits for the subscribers, which end on their own, and is
    // then passed on: a joinable thread destroyed would end the program without stopping the server it started.
    std::exception_ptr failed;
    try {
      meanwhile();
    } catch (...) {
      failed = std::current_exception();
    }
    for (auto& t : threads) t.join();
    if (failed) std::rethrow_exception(failed);
    return delivered;
  }
  std::vector<std::unique_ptr<ladder::test::Process>> children;
  std::vector<std::string> stems;
  const std::string self = self_path();
  for (int i = 0; i < subs; ++i) {
    stems.push_back("/tmp/" + sim_id + "-" + std::to_string(getpid()) + "-sub" + std::to_string(i));
    children.push_back(std::make_unique<ladder::test::Process>(
        std::vector<std::string>{self, "--subscriber", std::to_string(domain), sim_id, std::to_string(seconds),
                                 stems.back() + ".txt"},
        stems.back() + ".log"));
  }
  meanwhile();
  for (std::size_t i = 0; i < children.size(); ++i) {
    const auto status = children[i]->wait_exit(Millis(static_cast<long>(1e3 * seconds) + 30000));
    const auto d = read_delivery(stems[i] + ".txt");
    if (!status || !WIFEXITED(*status) || WEXITSTATUS(*status) != 0 || !d) {
      // Counted as a subscriber that received nothing, so that the row shows it; its log says why.
      std::fprintf(stderr, "subscriber %zu failed (its log: %s.log)\n", i, stems[i].c_str());
      continue;
    }
    delivered[i] = *d;
    std::remove((stems[i] + ".txt").c_str());
    std::remove((stems[i] + ".log").c_str());
  }
  return delivered;
}

}  // namespace

// --security: the identities this run makes (scripts/make-pki) and uses; the bench and its subscriber processes (which
// inherit the variable) all use the controller's (Cyclone wants one security setting per domain in a process).
constexpr const char* kSecurityEnv = "LADDER_BENCH_SECURITY";
std::optional<ladder::transport::Identity> g_identity;

void use_security_of_env() {
  const char* dir = std::getenv(kSecurityEnv);
  if (dir == nullptr) return;
  g_identity = ladder::transport::load_identity(dir);
  ladder::transport::set_default_identity(&*g_identity);
}

// Makes a server and a controller identity in a folder of its own; returns the folder.
std::string make_pki() {
  const std::string dir = "/tmp/ladder-bench-pki-" + std::to_string(getpid());
  const std::string cmd = std::string(LADDER_SOURCE_DIR) + "/scripts/make-pki " + dir +
                          " --server server --controller control > /dev/null";
  if (std::system(cmd.c_str()) != 0) throw std::runtime_error("scripts/make-pki failed: " + cmd);
  setenv(kSecurityEnv, (dir + "/control").c_str(), 1);
  use_security_of_env();
  return dir;
}

int run_bench(int argc, char** argv);

// A failure ends the run with its message, after the destructors have stopped the server it started (an uncaught
// exception would leave it running: at real-time priority, holding both processors).
int main(int argc, char** argv) {
  try {
    return run_bench(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "ladder-server-bench: %s\n", e.what());
    return 1;
  }
}

int run_bench(int argc, char** argv) {
  use_security_of_env();
  // A subscriber process started by subscribers_run(): --subscriber DOMAIN SIM_ID SECONDS OUT_FILE.
  if (argc == 6 && std::string(argv[1]) == "--subscriber") {
    write_delivery(subscribe(std::atoi(argv[2]), argv[3], std::atof(argv[4])), argv[5]);
    return 0;
  }
  CLI::App app{"ladder-server-bench: ladderd over DDS on loopback, measured"};
  std::vector<int> sizes{6, 1000, 10000, 100000}, subscribers{1, 8};
  double seconds = 5;
  int domain = 201, commands = 200;
  std::string ladderd = std::string(LADDER_BINARY_DIR) + "/server/ladderd";
  app.add_option("--blocks", sizes, "ladder sizes")->delimiter(',');
  app.add_option("--subscribers", subscribers, "subscriber counts")->delimiter(',');
  app.add_option("--seconds", seconds, "measuring time per configuration [s]");
  app.add_option("--commands", commands, "commands sent one after another for the ack latency");
  app.add_option("--domain", domain, "DDS domain id to use")->check(CLI::Range(0, ladder::transport::kMaxDomain));
  app.add_option("--ladderd", ladderd, "the server binary");
  std::vector<std::string> settings;
  app.add_option("--set", settings, "KEY=VALUE passed to ladderd, e.g. sim.accuracy=fast (repeatable)");
  int realtime = 0;
  app.add_option("--realtime-priority", realtime, "passed to ladderd: its physics thread's SCHED_FIFO priority");
  int spin_us = 0;
  app.add_option("--spin-us", spin_us, "passed to ladderd: busy-wait the last US microseconds before each tick");
  bool processes = false;
  app.add_flag("--subscriber-processes", processes,
               "run each subscriber as a process of its own (as separate viewers) instead of a thread of this one");
  bool security = false;
  app.add_flag("--security", security,
               "DDS Security (docs/security.md): identities made with scripts/make-pki for ladderd and the clients");
  CLI11_PARSE(app, argc, argv);
  const std::string pki = security ? make_pki() : "";

  // Tick lateness and step time come from the server's tick log: every tick that started while the subscribers ran
  // and commands were sent. The p99 of the server's own Stats is also given per 1 s window (median and worst window)
  // and the real-time factor is the median window's.
  std::printf("| N | subscribers | ack p50 ms | ack p99 ms | ticks | late p50 us | late p99 us | late max us | "
              "ticks late > 200 us | missed ticks | late p99 us, median / worst 1 s | rtf | states/s per sub | "
              "state lat p50 ms | p99 ms | gaps | dropped | step p50 us | step p99 us | steal ms |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  for (int n : sizes) {
    for (int subs : subscribers) {
      const std::string sim_id = "bench-" + std::to_string(n) + "-" + std::to_string(subs);
      std::fprintf(stderr, "N = %d, %d subscriber(s): starting ladderd...\n", n, subs);
      std::vector<std::string> args{ladderd,  "--domain", std::to_string(domain), "--sim-id", sim_id, "--set",
                                    "ladder.blocks=" + std::to_string(n), "--log-level", "warn"};
      for (const std::string& s : settings) args.insert(args.end(), {"--set", s});
      if (realtime > 0) args.insert(args.end(), {"--realtime-priority", std::to_string(realtime)});
      if (spin_us > 0) args.insert(args.end(), {"--spin-us", std::to_string(spin_us)});
      const std::string tick_log = "/tmp/" + sim_id + "-" + std::to_string(getpid()) + ".ticks";
      args.insert(args.end(), {"--tick-log", tick_log});
      if (security) args.insert(args.end(), {"--security", pki + "/server"});
      ladder::test::Process server(args, "/tmp/" + sim_id + ".log");
      Client control(domain, sim_id, "control");
      if (!control.wait_for_server(Millis(60000))) {
        std::fprintf(stderr, "no server; its log:\n%s\n", server.log().c_str());
        return 1;
      }
      std::vector<double> ack_ms;
      // The server's Stats of every 1 s window while the subscribers run (not the one after: it is unloaded).
      std::vector<ladder_msg_Stats> windows;
      std::uint64_t stats_seen = 0, dropped_from = 0;
      const auto note_stats = [&] {
        if (control.stats_received() == stats_seen) return;
        stats_seen = control.stats_received();
        windows.push_back(*control.latest_stats());
      };
      const auto any = [](const ladder_msg_Stats&) { return true; };
      Clock::time_point from, to;  // the ticks measured
      double steal_from = 0, steal_to = 0;
      const std::vector<Delivery> delivered =
          subscribers_run(subs, !processes, domain, sim_id, seconds, [&] {
            const auto end =
                Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(seconds));
            std::this_thread::sleep_for(Millis(500));
            control.wait_stats(any, Millis(3000));  // the windows counted start after this one
            stats_seen = control.stats_received();
            if (control.latest_stats()) dropped_from = control.latest_stats()->states_dropped;
            from = Clock::now();
            steal_from = steal_ms();
            for (int i = 0; i < commands; ++i) {
              const auto t0 = Clock::now();
              control.call(ladder::client::cmd::set("damping.hinge=0"), Millis(10000));
              ack_ms.push_back(1e3 * std::chrono::duration<double>(Clock::now() - t0).count());
              note_stats();
              std::this_thread::sleep_for(Millis(7));  // not in phase with the 1 ms tick
            }
            while (Clock::now() < end)
              if (control.wait_stats(any, Millis(1500))) note_stats();
            to = std::min(Clock::now(), end);  // the last wait may outlast the subscribers
            steal_to = steal_ms();
          });
      std::vector<double> lat;
      std::size_t states = 0, gaps = 0;
      for (const Delivery& d : delivered) {
        lat.insert(lat.end(), d.latency_ms.begin(), d.latency_ms.end());
        states += d.states;
        gaps += d.gaps;
      }
      // Per window: the median over the windows, and for p99 also the worst window, for the max the largest.
      const auto over = [&](double ladder_msg_Stats::*field) {
        std::vector<double> v;
        for (const ladder_msg_Stats& w : windows) v.push_back(w.*field);
        return v;
      };
      const std::vector<double> p99 = over(&ladder_msg_Stats::late_p99_us);
      // States the server made but never wrote, because a newer one replaced them first (a missed publish).
      const std::uint64_t dropped = windows.empty() ? 0 : windows.back().states_dropped - dropped_from;
      server.signal(SIGTERM);
      if (!server.wait_exit(Millis(5000)))  // the tick log is complete when the server has stopped
        std::fprintf(stderr, "ladderd did not stop within 5 s: its tick log may be incomplete\n");
      std::vector<double> late_us, step_us;
      std::size_t over_200 = 0, missed = 0;
      const std::vector<Tick> ticks = read_ticks(tick_log, from, to);
      for (const Tick& t : ticks) {
        late_us.push_back(1e-3 * static_cast<double>(t.late));
        if (t.step > 0) step_us.push_back(1e-3 * static_cast<double>(t.step));
        over_200 += t.late > 200'000;
        missed += t.late > 1'000'000;  // more than one 1 ms period late
      }
      if (ticks.empty()) std::fprintf(stderr, "no ticks in the server's tick log %s\n", tick_log.c_str());
      std::remove(tick_log.c_str());
      std::printf("| %d | %d | %.3f | %.3f | %zu | %.0f | %.0f | %.0f | %zu | %zu | %.0f / %.0f | %.2f | %.1f | %.2f | "
                  "%.2f | %zu | %llu | %.0f | %.0f | %.0f |\n",
                  n, subs, percentile(ack_ms, 0.5), percentile(ack_ms, 0.99), ticks.size(), percentile(late_us, 0.5),
                  percentile(late_us, 0.99), percentile(late_us, 1.0), over_200, missed, median(p99),
                  percentile(p99, 1.0), median(over(&ladder_msg_Stats::real_time_factor)),
                  static_cast<double>(states) / subs / seconds, percentile(lat, 0.5), percentile(lat, 0.99), gaps,
                  static_cast<unsigned long long>(dropped), percentile(step_us, 0.5), percentile(step_us, 0.99),
                  steal_to - steal_from);
      std::fflush(stdout);
    }
  }
  return 0;
}
