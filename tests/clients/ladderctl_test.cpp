// ladderctl against a real ladderd over Cyclone DDS on loopback: exit codes, printed answers, the timeout
// message, and the interactive prompt driven through a pseudo-terminal.
#include "client.hpp"
#include "netns.hpp"
#include "process.hpp"
#include "plot.hpp"
#include "pty.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <sstream>
#include <set>
#include <string>
#include <thread>
#include <tuple>

namespace ladder::test {
namespace {

using Clock = std::chrono::steady_clock;
const std::string kLadderctl = std::string(LADDER_BINARY_DIR) + "/clients/ladderctl";

Result run(const std::string& args) { return shell(kLadderctl + " " + args); }

// Writes the shipped loopback configuration (config/cyclonedds.xml) to `path` with `from` replaced by `to`; false
// when `from` is not in it.
bool write_config_with(const std::string& path, const std::string& from, const std::string& to) {
  std::ifstream in(std::string(LADDER_SOURCE_DIR) + "/config/cyclonedds.xml");
  std::stringstream text;
  text << in.rdbuf();
  std::string xml = text.str();
  const std::size_t at = xml.find(from);
  if (at == std::string::npos) return false;
  std::ofstream(path) << xml.replace(at, from.size(), to);
  return true;
}

class Ladderctl : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    const std::string name = std::string("ctl-") + info->name();
    domain_ = 1 + static_cast<int>(std::hash<std::string>{}(name) % 230);
    sim_id_ = name + "-" + std::to_string(getpid());
    server_.emplace(std::vector<std::string>{std::string(LADDER_BINARY_DIR) + "/server/ladderd", "--domain",
                                             std::to_string(domain_), "--sim-id", sim_id_},
                    std::string(LADDER_BINARY_DIR) + "/tests/" + name + ".log");
    where_ = " --domain " + std::to_string(domain_) + " --sim-id " + sim_id_ + " --timeout 15";
  }
  // ladderctl ARGS against this test's server.
  Result ctl(const std::string& args) { return run(args + where_); }

  int domain_ = 0;
  std::string sim_id_, where_;
  std::optional<Process> server_;
};

TEST_F(Ladderctl, EveryCommandKindRoundTripsWithItsAnswer) {
  struct Case {
    std::string args;
    int code;
    std::string words;
  };
  const Case cases[] = {
      {"pause", 0, "accepted at t = "},
      {"poke 3", 0, "accepted"},
      {"poke 3 --impulse 0,0.002 --at 0.013,-0.23", 0, "accepted"},
      {"push 4 --force 0.01,0 --for 0.05", 0, "accepted"},
      {"grab 5", 0, "accepted"},
      {"drag 5 0.05,-0.4,0.3", 0, "accepted"},
      {"grab 4 --to 0.02,-0.3 --stiffness 50", 0, "accepted"},
      {"release 4", 0, "accepted"},
      {"release 5", 0, "accepted"},
      {"break 5", 0, "accepted"},
      {"join 5", 0, "accepted"},
      {"step 10", 0, "accepted"},
      {"poke 3 --impulse 1e-400,0.001", 0, "accepted"},  // 1e-400 is 0 to a double, not an error (it was)
      {"set damping.linear 0.2", 0, "accepted"},
      {"set sim.gravity [0,-9.81]", 0, "accepted"},
      {"tip", 0, "accepted"},
      {"reset", 0, "accepted"},
      {"load free-chain", 0, "accepted"},
      {"resume", 0, "accepted"},
      // Refusals: exit code 1 and the server's reason.
      {"poke 9", 1, "refused: no block 9"},
      {"join 1", 1, "refused: hinge 1 is not broken"},
      {"set solver.tolerence 1e-9", 1, "did you mean 'solver.tolerance'"},
      {"release 1", 1, "refused: nothing is grabbed"},
      {"step 5", 1, "refused: step works while paused"},
      {"tip", 1, "refused: the top block is not held"},  // free-chain's top block is pinned
      {"load ../secret", 1, "refused: not permitted"},
      // Usage errors: exit code 2, nothing sent.
      {"poke", 2, "BLOCK is required"},
      {"drag 3 1,x", 2, "is not a list of finite numbers"},
      {"watch everything", 2, "WHAT"},
      {"watch state --rate -1", 2, "--rate: must be a number of 0 or more, not -1"},
      {"--timeout 1e10 status", 2, "--timeout: must be at most 1e+06, not 1e10"},
      {"frobnicate", 2, "ladderctl: unknown command 'frobnicate'\ncommands: tip poke push"},
      // A mistyped option (of the command or of the connection), named with the nearest one; stray words named.
      {"poke 3 --impuls 0,0.01", 2, "ladderctl: unknown option '--impuls' (did you mean '--impulse'?)\nRun with"},
      {"tip --domian 5", 2, "ladderctl: unknown option '--domian' (did you mean '--domain'?)\nRun with"},
      {"tip now", 2, "ladderctl: unexpected 'now'\nRun with"},
      {"watch state --kinds lock", 2, "only watch events takes --kinds"},
      {"step 0", 2, "N: must be 1 or more, not 0"},
      {"step 1e3", 2, "N: '1e3' is not a whole number (1 to 4294967295)"},
      {"step 4294967297", 2, "N: must be at most 4294967295, not 4294967297"},
      {"replay /dev/null --speed -1", 2, "--speed: must be a number of 0 or more, not -1"},
      {"watch events --kinds flip,lock", 2, "'flip' is not an event kind (flip_flop, impact, lock, unlock, break, "
                                            "join, solver_warning, solver_failure, command_refused)"},
      // The server's own kinds pass (the kinds are checked in order: the first unknown one is named).
      {"watch events --kinds solver_failure,command_refused,flip", 2, "'flip' is not an event kind"},
  };
  for (const Case& c : cases) {
    const Result r = ctl(c.args);
    EXPECT_EQ(r.code, c.code) << "ladderctl " << c.args << "\n" << r.output;
    EXPECT_NE(r.output.find(c.words), std::string::npos) << "ladderctl " << c.args << "\n" << r.output;
  }
  const Result status = ctl("status");
  EXPECT_EQ(status.code, 0) << status.output;
  EXPECT_NE(status.output.find("2 blocks"), std::string::npos) << status.output;  // free-chain, loaded above
  // Live settings last until the next load: free-chain's own (no damping) replaced damping.linear = 0.2.
  EXPECT_NE(status.output.find("damping.linear=0\n"), std::string::npos) << status.output;
  // What the viewer draws from but `set` cannot change is listed apart from the live settings.
  const std::size_t live = status.output.find("live settings (set KEY VALUE):\n");
  const std::size_t fixed = status.output.find("fixed for this scene (load it again to change them):\n");
  ASSERT_NE(live, std::string::npos) << status.output;
  ASSERT_NE(fixed, std::string::npos) << status.output;
  EXPECT_LT(live, status.output.find("  damping.linear=0\n"));
  EXPECT_LT(status.output.find("  damping.linear=0\n"), fixed);
  for (const char* key : {"  ladder.depth=", "  ladder.hinge=corner\n", "  ladder.end_radius=0\n"})
    EXPECT_GT(status.output.find(key), fixed) << key << " in\n" << status.output;
}

// A domain with no room left on this host (here a configuration that allows one participant index, 0, which the
// server or this test's client holds): a command, `list` (which makes participants of its own) and `watch` each say
// so and why, and exit 2. (`list` and `replay` ended in an uncaught exception, exit 134, and every program blamed
// CYCLONEDDS_URI, with Cyclone's own reason only on the line above.)
TEST_F(Ladderctl, AFullDomainIsSaidToBeFull) {
  client::Client holder(domain_, sim_id_, "holder");
  ASSERT_TRUE(holder.wait_for_server(std::chrono::milliseconds(15000)));
  const std::string xml = std::string(LADDER_BINARY_DIR) + "/tests/ctl-full-" + std::to_string(getpid()) + ".xml";
  ASSERT_TRUE(write_config_with(xml, "<MaxAutoParticipantIndex>64</MaxAutoParticipantIndex>",
                                "<MaxAutoParticipantIndex>0</MaxAutoParticipantIndex>"));
  for (const char* args : {"status", "list", "watch events"}) {
    const Result r = shell("CYCLONEDDS_URI=file://" + xml + " " + kLadderctl + " " + args + where_);
    EXPECT_EQ(r.code, 2) << args << "\n" << r.output;
    EXPECT_NE(r.output.find("ladderctl: create DDS participant on domain " + std::to_string(domain_) +
                            " (Cyclone: \"Failed to find a free participant index for domain " +
                            std::to_string(domain_) + "\": this host already has as many participants on the domain "
                            "as the configuration allows"),
              std::string::npos)
        << args << "\n" << r.output;
  }
  std::filesystem::remove(xml);
}

TEST_F(Ladderctl, NoServerGivesTheTimeoutMessageAndCodeThree) {
  const auto t0 = Clock::now();
  const Result r = run("tip --domain 231 --sim-id nobody-here --timeout 1");  // the tests use domains 1 to 230
  const double took = std::chrono::duration<double>(Clock::now() - t0).count();
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_NE(r.output.find("no ladderd with sim id 'nobody-here' on DDS domain 231 after 1 s; is it running, and is "
                          "CYCLONEDDS_URI the same on both sides?"),
            std::string::npos)
      << r.output;
  EXPECT_LT(took, 3.0);
}

// A mistyped --sim-id: the message names the ladder that is there (a fresh-eyes run found only "is it running?"
// while `list` knew the answer).
TEST_F(Ladderctl, AMistypedSimIdIsToldTheLaddersThatAreThere) {
  ASSERT_EQ(ctl("status").code, 0);  // this test's server is up
  for (const char* command : {"tip", "status"}) {
    const Result r =
        run(std::string(command) + " --domain " + std::to_string(domain_) + " --sim-id nobody-here --timeout 2");
    EXPECT_EQ(r.code, 3) << r.output;
    EXPECT_NE(r.output.find("no ladderd with sim id 'nobody-here' on DDS domain " + std::to_string(domain_) +
                            " after 2 s; the ladder there is '" + sim_id_ + "' (choose one with --sim-id)"),
              std::string::npos)
        << command << ": " << r.output;
  }
}

TEST_F(Ladderctl, WatchEventsPrintsTheRippleAsJson) {
  ASSERT_EQ(ctl("tip").code, 0);
  const Result r = run("watch events --json" + where_ + " & pid=$!; sleep 3; kill -INT $pid; wait $pid");
  EXPECT_NE(r.output.find("\"kind\":\"flip_flop\",\"hinge\":5"), std::string::npos) << r.output;
}

// A mistyped command: the nearest command, then every command, and nothing sent.
TEST_F(Ladderctl, AMistypedCommandSuggestsTheNearestAndListsThemAll) {
  const Result r = ctl("tpi");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("ladderctl: unknown command 'tpi'; did you mean 'tip'?\n"
                          "commands: tip poke push grab drag release break join pause resume step reset set load "
                          "status watch list plot replay help quit\n"),
            std::string::npos)
      << r.output;
  EXPECT_NE(ctl("stat").output.find("did you mean 'status'?"), std::string::npos);  // a prefix
  EXPECT_EQ(ctl("xyzzy").output.find("did you mean"), std::string::npos);            // nothing near
  EXPECT_EQ(server_->log().find(" from "), std::string::npos) << "a command reached the server:\n" << server_->log();
}

// watch events: a heading that says what is watched, then only the kinds asked for (here the ripple's flip-flops,
// none of the impacts, locks and unlocks that come with it).
TEST_F(Ladderctl, WatchEventsHasAHeadingAndTakesKinds) {
  ASSERT_EQ(ctl("tip").code, 0);
  const Result r = run("watch events --kinds flip_flop" + where_ + " & pid=$!; sleep 3; kill -INT $pid; wait $pid");
  EXPECT_NE(r.output.find("events of sim id '" + sim_id_ + "' on DDS domain " + std::to_string(domain_) +
                          " (only flip_flop) as they happen; hinge k joins blocks k-1 and k (Ctrl-C stops):\n"),
            std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("flip_flop       hinge 5"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find(" s  impact "), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find(" s  lock "), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find(" s  unlock "), std::string::npos) << r.output;
}

// Breaks and joins hinge 3 until a `watch events --json` prints a join (its reader may not have met the server's
// writer yet: events are not kept for readers that come later).
void break_and_join_until_printed(client::Client& c, const Process& watcher) {
  const auto deadline = Clock::now() + std::chrono::seconds(20);
  while (watcher.log().find("\"kind\":\"join\"") == std::string::npos && Clock::now() < deadline) {
    ASSERT_TRUE(c.call(client::cmd::break_hinge(3)).accepted);
    ASSERT_TRUE(c.call(client::cmd::join_hinge(3)).accepted);
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
  }
  ASSERT_NE(watcher.log().find("\"kind\":\"join\""), std::string::npos) << watcher.log();
}

// What `watch events --json` said: each event number printed ({"seq":N,...}) or in a gap said on standard error
// ("N events missed before this one (numbers A to B)", or "... since the last one ..."), counted.
struct Accounting {
  std::map<unsigned long long, int> seen;  // each number: printed (1) or in a gap said (1 each)
  unsigned long long missed_total = 0, tail_gaps = 0;  // tail_gaps: gaps said with no later event ("since")
};
Accounting account_events(const std::string& log) {
  Accounting a;
  static const std::regex gap(R"(ladderctl: (\d+) events? missed (before this one|since the last one) \(numbers (\d+) to (\d+)\))");
  std::istringstream lines(log);
  for (std::string line; std::getline(lines, line);) {
    unsigned long long n = 0;
    std::smatch m;
    if (std::sscanf(line.c_str(), "{\"seq\":%llu,", &n) == 1) {
      ++a.seen[n];
    } else if (std::regex_search(line, m, gap)) {
      const unsigned long long missed = std::stoull(m[1]), from = std::stoull(m[3]), to = std::stoull(m[4]);
      EXPECT_EQ(to - from + 1, missed) << line;
      for (unsigned long long k = from; k <= to; ++k) ++a.seen[k];
      a.missed_total += missed;
      a.tail_gaps += m[2] == "since the last one";
    }
  }
  return a;
}

// A reset starts the scene's clock again at 0; watch events marks it with a line of its own between the events of the
// two generations (text: "--- the scene starts again (generation G, ...) ---"; --json: {"kind":"scene",
// "generation":G,...}), so that a time that jumps back is not taken for a broken clock.
TEST_F(Ladderctl, WatchEventsMarksAReset) {
  ASSERT_EQ(ctl("pause").code, 0);
  const std::string base = std::string(LADDER_BINARY_DIR) + "/tests/ctl-reset-" + std::to_string(getpid());
  Process json_watcher({kLadderctl, "watch", "events", "--json", "--domain", std::to_string(domain_), "--sim-id",
                        sim_id_, "--timeout", "15"},
                       base + ".json");
  Process text_watcher({kLadderctl, "watch", "events", "--domain", std::to_string(domain_), "--sim-id", sim_id_,
                        "--timeout", "15"},
                       base + ".txt");
  client::Client c(domain_, sim_id_, "resetter");
  ASSERT_TRUE(c.wait_for_server(std::chrono::milliseconds(15000)));
  const auto printed_by_both = [&](const std::string& json_words, const std::string& text_words) {
    const auto deadline = Clock::now() + std::chrono::seconds(20);
    while ((json_watcher.log().find(json_words) == std::string::npos ||
            text_watcher.log().find(text_words) == std::string::npos) &&
           Clock::now() < deadline) {
      ASSERT_TRUE(c.call(client::cmd::break_hinge(3)).accepted);
      ASSERT_TRUE(c.call(client::cmd::join_hinge(3)).accepted);
      std::this_thread::sleep_for(std::chrono::milliseconds(200));
    }
  };
  printed_by_both("\"kind\":\"join\"", " join ");
  const std::uint32_t before = c.scene_info()->generation;
  ASSERT_TRUE(c.call(client::cmd::reset()).accepted);
  ASSERT_TRUE(c.wait_scene_info(std::chrono::milliseconds(5000),
                                [&](const client::SceneInfo& i) { return i.generation == before + 1; }));
  const std::string marker_json = "{\"kind\":\"scene\",\"generation\":" + std::to_string(before + 1) + ",";
  const std::string marker_text = "--- the scene starts again (generation " + std::to_string(before + 1) + ", a reset "
                                  "or a load): '" + c.scene_info()->scene_name + "', 6 blocks; t counts from 0 ---\n";
  const auto after = [](const std::string& log, const std::string& marker, const std::string& words) {
    const size_t at = log.find(marker);
    return at != std::string::npos && log.find(words, at) != std::string::npos;
  };
  const auto deadline = Clock::now() + std::chrono::seconds(20);
  while (!(after(json_watcher.log(), marker_json, "\"kind\":\"join\"") &&
           after(text_watcher.log(), marker_text, " join ")) &&
         Clock::now() < deadline) {
    ASSERT_TRUE(c.call(client::cmd::break_hinge(3)).accepted);
    ASSERT_TRUE(c.call(client::cmd::join_hinge(3)).accepted);
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
  }
  json_watcher.signal(SIGINT);
  text_watcher.signal(SIGINT);
  ASSERT_TRUE(json_watcher.wait_exit(std::chrono::seconds(10)).has_value());
  ASSERT_TRUE(text_watcher.wait_exit(std::chrono::seconds(10)).has_value());
  const std::string json_join = "\"kind\":\"join\"", text_join = " join ";
  for (const auto& [log, marker, join] : {std::tuple{json_watcher.log(), marker_json, json_join},
                                          std::tuple{text_watcher.log(), marker_text, text_join}}) {
    const size_t at = log.find(marker);
    ASSERT_NE(at, std::string::npos) << log;
    EXPECT_EQ(log.find(marker, at + 1), std::string::npos) << "one reset, one marker\n" << log;
    EXPECT_LT(log.find(join), at) << "events of the first generation come before it\n" << log;
    EXPECT_NE(log.find(join, at), std::string::npos) << "and of the second after it\n" << log;
  }
}

// watch events says which events it missed: a watcher stopped (Ctrl-Z) while the paused server breaks and joins a
// hinge 1000 times loses some of those 2001 events (once it runs again its DDS thread delivers the backlog into a
// reader that keeps 64, faster than ladderctl takes them; measured: 379 to 1497 lost in six runs, two of them on a
// loaded machine), and says
// on standard error which numbers it missed. Every number from the first event printed to the last is either printed
// (--json has "seq") or in exactly one of the gaps said: without the gaps said, the lost numbers would be missing.
TEST_F(Ladderctl, WatchEventsSaysHowManyEventsItMissed) {
  constexpr int kPairs = 1000;
  ASSERT_EQ(ctl("pause").code, 0);
  const std::string out = std::string(LADDER_BINARY_DIR) + "/tests/ctl-missed-" + std::to_string(getpid()) + ".txt";
  Process watcher({kLadderctl, "watch", "events", "--json", "--domain", std::to_string(domain_), "--sim-id", sim_id_,
                   "--timeout", "15"},
                  out);
  client::Client c(domain_, sim_id_, "breaker");
  ASSERT_TRUE(c.wait_for_server(std::chrono::milliseconds(15000)));
  break_and_join_until_printed(c, watcher);
  watcher.signal(SIGSTOP);
  for (int i = 0; i < kPairs; ++i) {
    ASSERT_TRUE(c.call(client::cmd::break_hinge(3)).accepted);
    ASSERT_TRUE(c.call(client::cmd::join_hinge(3)).accepted);
    if (i % 4 == 3) std::this_thread::sleep_for(std::chrono::milliseconds(10));  // below commands.rate (1000/s)
  }
  ASSERT_TRUE(c.call(client::cmd::break_hinge(3)).accepted);  // one more: 2 kPairs + 1 events in all
  watcher.signal(SIGCONT);
  const auto read_all = Clock::now() + std::chrono::seconds(20);  // until the last event (a break) is printed
  while (watcher.log().find("\"seq\":" + std::to_string(2 * kPairs + 1)) == std::string::npos &&
         watcher.log().find("numbers ") == std::string::npos && Clock::now() < read_all)
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  watcher.signal(SIGINT);
  ASSERT_TRUE(watcher.wait_exit(std::chrono::seconds(10)).has_value());
  const std::string log = watcher.log();
  const Accounting a = account_events(log);
  const std::map<unsigned long long, int>& seen = a.seen;
  const unsigned long long missed_total = a.missed_total;
  ASSERT_FALSE(seen.empty()) << log;
  const unsigned long long first = seen.begin()->first, end = seen.rbegin()->first;
  EXPECT_EQ(seen.size(), end - first + 1) << "a number neither printed nor said missing\n" << log;
  for (const auto& [k, count] : seen) EXPECT_EQ(count, 1) << "number " << k << " printed or missed twice\n" << log;
  EXPECT_GE(end - first + 1, 2u * kPairs + 1) << log;  // the burst and the last break were all accounted for
  EXPECT_LE(missed_total, 2u * kPairs + 1 - 64) << log;
#if !defined(__SANITIZE_ADDRESS__)
  // Whether events are lost depends on how fast the watcher's DDS thread fills its reader after the stop against
  // how fast it takes them: in the plain build it lost some in every run (8 of 8, two on a loaded machine); under
  // AddressSanitizer it kept up with all 2001 once, so there the test checks only the accounting above.
  EXPECT_GT(missed_total, 0u) << log;
#endif
}

// Events lost with no event after them: a watcher stopped longer than its DDS lease (1 s here, from a configuration of
// its own) is forgotten by the server, whose events then reach it no more; none follows once it runs again. The
// server's count of published events, in its Stats, shows the loss: the watcher says which numbers it missed, and
// every number up to the server's count is printed or said missed, once.
TEST_F(Ladderctl, WatchEventsSaysWhatItMissedWhenNoEventFollows) {
  ASSERT_EQ(ctl("pause").code, 0);
  const std::string base = std::string(LADDER_BINARY_DIR) + "/tests/ctl-tail-" + std::to_string(getpid());
  ASSERT_TRUE(write_config_with(base + ".xml", "</Discovery>", "<LeaseDuration>1s</LeaseDuration></Discovery>"));
  Process watcher({"/usr/bin/env", "CYCLONEDDS_URI=file://" + base + ".xml", kLadderctl, "watch", "events", "--json",
                   "--domain", std::to_string(domain_), "--sim-id", sim_id_, "--timeout", "15"},
                  base + ".txt");
  client::Client c(domain_, sim_id_, "breaker");
  ASSERT_TRUE(c.wait_for_server(std::chrono::milliseconds(15000)));
  break_and_join_until_printed(c, watcher);
  watcher.signal(SIGSTOP);
  std::this_thread::sleep_for(std::chrono::milliseconds(3000));  // three leases: the server has let it go
  for (int i = 0; i < 3; ++i) {
    ASSERT_TRUE(c.call(client::cmd::break_hinge(3)).accepted);
    ASSERT_TRUE(c.call(client::cmd::join_hinge(3)).accepted);
  }
  // The server's count once it has published them all (its Stats come once a second).
  const std::uint64_t before = c.stats_received();
  ASSERT_TRUE(c.wait_stats([&](const ladder_msg_Stats&) { return c.stats_received() > before + 1; },
                           std::chrono::milliseconds(5000)));
  const unsigned long long last = c.latest_stats()->events_published;
  watcher.signal(SIGCONT);
  Accounting a;
  const auto read_all = Clock::now() + std::chrono::seconds(20);
  while (Clock::now() < read_all) {
    a = account_events(watcher.log());
    if (!a.seen.empty() && a.seen.rbegin()->first >= last) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  watcher.signal(SIGINT);
  ASSERT_TRUE(watcher.wait_exit(std::chrono::seconds(10)).has_value());
  const std::string log = watcher.log();
  a = account_events(log);
  ASSERT_FALSE(a.seen.empty()) << log;
  EXPECT_EQ(a.seen.rbegin()->first, last) << "the server published " << last << " events\n" << log;
  EXPECT_EQ(a.seen.size(), a.seen.rbegin()->first - a.seen.begin()->first + 1) << "a number neither printed nor said "
                                                                                   "missing\n" << log;
  for (const auto& [k, count] : a.seen) EXPECT_EQ(count, 1) << "number " << k << " printed or missed twice\n" << log;
  EXPECT_GT(a.tail_gaps, 0u) << log;  // the loss was said though no event came after it
}

// watch stats prints every Stats sample (one a second), paused or not: it used to print a sample only when the step
// count had changed, so a paused server's stats never showed.
TEST_F(Ladderctl, WatchStatsShowsAPausedServersStats) {
  ASSERT_EQ(ctl("pause").code, 0);
  const Result r = run("watch stats --json" + where_ + " & pid=$!; sleep 6; kill -INT $pid; wait $pid");
  std::size_t lines = 0, steps = 0;
  std::set<std::string> counts;
  for (std::size_t at = r.output.find("{\"sim_time\""); at != std::string::npos;
       at = r.output.find("{\"sim_time\"", at + 1)) {
    ++lines;
    const std::size_t s = r.output.find("\"steps\":", at);
    counts.insert(r.output.substr(s, r.output.find(',', s) - s));
  }
  steps = counts.size();
  EXPECT_GE(lines, 3u) << r.output;  // about 5 in 6 s
  EXPECT_EQ(steps, 1u) << "paused: the step count does not move\n" << r.output;
}

// ladderctl plot: a tipped ladder's ripple (a flip-flop at each hinge, 1 to 5) and its energy, from the running
// server and then from the session it recorded; the picture has a dot per flip-flop.
TEST_F(Ladderctl, PlotWritesTheRippleFromTheServerAndFromItsRecording) {
  server_.reset();  // this test's server records
  const std::string log = std::string(LADDER_BINARY_DIR) + "/tests/ctl-plot-" + std::to_string(getpid()) + ".lcmlog";
  std::remove(log.c_str());
  server_.emplace(std::vector<std::string>{std::string(LADDER_BINARY_DIR) + "/server/ladderd", "--domain",
                                           std::to_string(domain_), "--sim-id", sim_id_, "--record", log},
                  std::string(LADDER_BINARY_DIR) + "/tests/ctl-plot.log");
  ASSERT_EQ(ctl("reset").code, 0);  // a second scene generation: the recording's plot says it shows the last
  ASSERT_EQ(ctl("tip").code, 0);
  const std::string live = std::string(LADDER_BINARY_DIR) + "/tests/ctl-plot-live.png";
  const Result a = ctl("plot " + live + " --for 4");
  ASSERT_EQ(a.code, 0) << a.output;
  EXPECT_NE(a.output.find("from 4 s of the running server: 5 flip-flops at hinges 1 to 5 over t = "), std::string::npos)
      << a.output;
  server_->signal(SIGTERM);
  ASSERT_TRUE(server_->wait_exit(std::chrono::seconds(20)).has_value());
  const std::string recorded = std::string(LADDER_BINARY_DIR) + "/tests/ctl-plot-log.png";
  const Result b = run("plot " + recorded + " --log " + log + " --size 600x400");
  ASSERT_EQ(b.code, 0) << b.output;
  EXPECT_NE(b.output.find("(600x400 px) from " + log + ": 5 flip-flops at hinges 1 to 5 over t = 0.0"),  // (from the reset)
            std::string::npos)
      << b.output;
  EXPECT_NE(b.output.find(" J (the last of 2 runs: each reset or load, or a state earlier than the one before it, "
                          "starts the plot again)\n"),
            std::string::npos)
      << b.output;
  EXPECT_EQ(a.output.find("the last of"), std::string::npos) << a.output;  // the live plot saw one
  for (const std::string& png : {live, recorded}) {
    cairo_surface_t* img = cairo_image_surface_create_from_png(png.c_str());
    ASSERT_EQ(cairo_surface_status(img), CAIRO_STATUS_SUCCESS) << png;
    const unsigned char* d = cairo_image_surface_get_data(img);
    int dots = 0;
    for (int y = 0; y < cairo_image_surface_get_height(img); ++y)
      for (int x = 0; x < cairo_image_surface_get_width(img); ++x) {
        const auto v = *reinterpret_cast<const std::uint32_t*>(d + y * cairo_image_surface_get_stride(img) + 4 * x);
        dots += ((v >> 16) & 0xff) == view::kFlipDot.r && ((v >> 8) & 0xff) == view::kFlipDot.g &&
                (v & 0xff) == view::kFlipDot.b;
      }
    cairo_surface_destroy(img);
    EXPECT_GE(dots, 5 * 12) << png << ": five dots of radius 3 px";  // each about 28 px, allow for overlap
  }
  EXPECT_EQ(run("plot " + recorded + " --log /nonexistent.lcmlog").code, 2);
}

// Bad input refused before anything is sent or read, exit code 2, with the reason: an empty argument (an unset
// variable: `break ""` broke hinge 0, `--security ""` ran without DDS Security), NaN inside a vector or as a duration
// (it reached the server, which refused it with exit 1), a replay pace that overflowed into "as fast as possible",
// /dev/zero as a log (read without end before its first bytes were checked), a picture that cannot be written (a
// live plot found out after watching for --for seconds), and a log with no state to play or plot.
TEST_F(Ladderctl, BadInputIsRefusedBeforeAnythingIsSent) {
  const std::string dir = std::string(LADDER_BINARY_DIR) + "/tests/ctl-bad-" + std::to_string(getpid());
  {
    std::ofstream cut(dir + "-cut.lcmlog", std::ios::binary);  // LCM's sync word, then no whole event
    cut << std::string("\xED\xA1\xDA\x01", 4) << std::string(40, '\0');
  }
  struct Case { std::string args, words; };
  for (const Case& c :
       {Case{"break ''", "ladderctl: argument 2 is empty (after 'break'); an unset shell variable?"},
        Case{"status --security ''", "argument 3 is empty (after '--security')"},
        Case{"poke 3 --impulse nan,0", "--impulse: 'nan,0' is not a list of finite numbers like 0.01,0"},
        Case{"drag 3 0,inf", "POSE: '0,inf' is not a list of finite numbers"},
        Case{"push 3 --force 1,0 --for nan", "--for: 'nan' is not a number greater than 0"},
        Case{"grab 3 --stiffness -5", "--stiffness: must be a number of 0 or more, not -5"},
        Case{"grab 3 --stiffness nan", "--stiffness: 'nan' is not a number of 0 or more"},
        Case{"--domain text status", "--domain: 'text' is not a DDS domain id (0 to 231)"},
        // (ctl() adds the test's --domain and --sim-id; CLI11 said "--sim-id: At Most 1 required but received 2")
        Case{"status --sim-id other", "ladderctl: --sim-id is given 2 times; give it once\n"},
        // A mistyped option before the command, with its value: the option is named ("unknown command '201'" was).
        Case{"--domian 201 tip", "ladderctl: unknown option '--domian' (did you mean '--domain'?)"},
        Case{"replay --speed 1e-15 " + dir + "-cut.lcmlog", "must be 0 (as fast as possible) or at least 1e-6"},
        Case{"replay /dev/zero", "'/dev/zero' is not an LCM event log"},
        Case{"plot " + dir + ".png --log /dev/zero", "'/dev/zero' is not an LCM event log"},
        Case{"plot /no/such/dir/p.png --for 1", "cannot write '/no/such/dir/p.png': no folder '/no/such/dir'"},
        Case{"plot " + std::string(LADDER_BINARY_DIR) + " --for 1", "it is a folder"},
        Case{"plot " + dir + ".png --log " + dir + "-cut.lcmlog", "no state in " + dir + "-cut.lcmlog"},
        Case{"replay --as cut-" + std::to_string(getpid()) + " " + dir + "-cut.lcmlog",
             "-cut.lcmlog: no state in the log; nothing to replay"},
        // A sim id no server can have: one of 65 characters was published cut to 61 and "...", under which no
        // client looked for it; one that was not UTF-8 stopped the viewer's picture.
        Case{"replay --as " + std::string(65, 'r') + " " + dir + "-cut.lcmlog", "--as: must be 1 to 64 characters"},
        Case{"replay --as 'r*' " + dir + "-cut.lcmlog", "--as: may hold only letters, digits, '-', '_' and '.'"}}) {
    const Result r = ctl(c.args);
    EXPECT_EQ(r.code, 2) << c.args << "\n" << r.output;
    EXPECT_NE(r.output.find(c.words), std::string::npos) << c.args << "\n" << r.output;
    // A replay with nothing to replay says so, not "replayed 0 states" first.
    EXPECT_EQ(r.output.find("replayed 0 states"), std::string::npos) << c.args << "\n" << r.output;
  }
  EXPECT_EQ(server_->log().find(" from "), std::string::npos) << "a command reached the server:\n" << server_->log();
}

// ladderctl list: both ladders of a domain shared by two network namespaces (joined by a veth pair), one server on
// each side, listed from side b with their sim ids, scenes and sizes; a domain with none: exit 3. Skipped, saying
// why, when not root or when the kernel refuses a namespace.
TEST_F(Ladderctl, ListShowsBothServersOfTwoNetworkNamespaces) {
  NetnsPair net;
  if (const auto why = net.create()) GTEST_SKIP() << *why;
  server_.reset();
  const std::string dir = std::string(LADDER_BINARY_DIR) + "/tests/ctl-list-";
  // Side b lists itself as a peer too, so that its two programs find each other without multicast.
  const std::string xml_a = dir + "a.xml", xml_b = dir + "b.xml";
  std::ofstream(xml_a) << NetnsPair::xml_a();
  std::string b = NetnsPair::xml_b();
  b.replace(b.find("</Peers>"), 0, std::string("<Peer address=\"") + NetnsPair::kAddrB + "\"/>");
  std::ofstream(xml_b) << b;
  const std::string d = std::to_string(domain_);
  Process far(net.run_in('a', "file://" + xml_a, {std::string(LADDER_BINARY_DIR) + "/server/ladderd", "--domain", d,
                                                  "--sim-id", sim_id_ + "-a"}),
              dir + "a.log");
  Process near(net.run_in('b', "file://" + xml_b, {std::string(LADDER_BINARY_DIR) + "/server/ladderd", "--domain", d,
                                                   "--sim-id", sim_id_ + "-b", "--set", "ladder.blocks=9"}),
               dir + "b.log");
  const std::string in_b = net.shell_prefix('b', "file://" + xml_b);
  Result r;
  const auto both = [&] {
    return r.output.find(sim_id_ + "-a ") != std::string::npos && r.output.find(sim_id_ + "-b ") != std::string::npos;
  };
  const auto deadline = Clock::now() + std::chrono::seconds(30);
  do {
    r = shell(in_b + kLadderctl + " list --domain " + d + " --timeout 3");
  } while (!both() && Clock::now() < deadline);
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("2 ladders on DDS domain " + d + ":\n"), std::string::npos) << r.output;
  std::smatch m;
  EXPECT_TRUE(std::regex_search(r.output, m, std::regex(sim_id_ + R"(-a +\S+ +classic \(at rest\) +6 +x[0-9.]+\n)")))
      << r.output;
  EXPECT_TRUE(std::regex_search(r.output, m, std::regex(sim_id_ + R"(-b +\S+ +classic \(at rest\) +9 +x[0-9.]+\n)")))
      << r.output << "\n" << near.log();
  const Result none = run("list --domain 231 --timeout 1");  // the tests use domains 1 to 230
  EXPECT_EQ(none.code, 3) << none.output;
  EXPECT_NE(none.output.find("no ladderd on DDS domain"), std::string::npos) << none.output;
}

// The prompt through a pseudo-terminal: "ti" + Tab completes to "tip", Enter sends it, the answer is printed; an
// unknown word is named as such; quit exits 0 even after a refused command.
TEST_F(Ladderctl, PromptCompletesTipsAndQuitsWithZero) {
  Pty term({kLadderctl, "--domain", std::to_string(domain_), "--sim-id", sim_id_, "--timeout", "15"}, 100, 30);
  ASSERT_TRUE(term.started());
  ASSERT_TRUE(term.read_until("ladder> ", 10)) << term.screen();
  term.type("ti\t");
  // The line editor redraws the completed word with cursor moves; "p " is the completion's tail.
  EXPECT_TRUE(term.read_until("p ", 5)) << "no completion: " << term.screen();
  term.type("\r");
  // Only "tip" (not "ti") is accepted: the answer proves the completion.
  EXPECT_TRUE(term.read_until("accepted at t = ", 20)) << term.screen();
  term.type("frobnicate\r");
  EXPECT_TRUE(term.read_until("unknown command 'frobnicate'", 10)) << term.screen();
  term.type("poke 9\r");
  EXPECT_TRUE(term.read_until("refused: no block 9", 10)) << term.screen();
  term.type("quit\r");
  const auto status = term.wait_exit(20);
  ASSERT_TRUE(status.has_value()) << term.screen();
  EXPECT_TRUE(WIFEXITED(*status) && WEXITSTATUS(*status) == 0) << *status << "\n" << term.screen();
}

}  // namespace
}  // namespace ladder::test
