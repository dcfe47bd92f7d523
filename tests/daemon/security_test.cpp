// DDS Security (docs/security.md): a real ladderd and real clients with identities from scripts/make-pki, over
// Cyclone's security plugins on loopback; and, without security, clients that take answers only from their server.
#include "server_fixture.hpp"

#include <arpa/inet.h>
#include <linux/if_ether.h>
#include <linux/if_packet.h>
#include <net/if.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <thread>

namespace ladder::test {
namespace {

namespace fs = std::filesystem;

const std::string kBin = std::string(LADDER_BINARY_DIR);
const std::string kCtl = kBin + "/clients/ladderctl";
const std::string kView = kBin + "/clients/ladder-view";
const std::string kDaemon = kBin + "/server/ladderd";

// Two deployments made once for the suite: ours (a server, a controller, a viewer, an expired controller and an
// expired server), and another CA's with a controller of the same name as ours.
class Security : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    pki_ = kBin + "/tests/security-pki-" + std::to_string(getpid());
    fs::remove_all(pki_);
    const std::string make = std::string(LADDER_SOURCE_DIR) + "/scripts/make-pki ";
    for (const std::string& args :
         {pki_ + "/ours --server srv --controller ctl --viewer v1",
          pki_ + "/ours --controller old --server oldsrv --not-before 20240101000000Z --not-after 20250101000000Z",
          pki_ + "/rogue --controller ctl"}) {
      const Result r = shell(make + args);
      ASSERT_EQ(r.code, 0) << r.output;
    }
  }
  static void TearDownTestSuite() { fs::remove_all(pki_); }

  static std::string id(const std::string& who) { return pki_ + "/ours/" + who; }
  static std::string rogue(const std::string& who) { return pki_ + "/rogue/" + who; }

  // Starts ladderd (with `security` unless empty) and a controller client on the test's own domain and sim id.
  void start(const std::string& security) {
    const std::string name = test_name();
    sim_id_ = sim_id_for(name);
    domain_ = domain_for(name);
    log_path_ = kBin + "/tests/" + name + ".log";
    std::vector<std::string> args{kDaemon, "--domain", std::to_string(domain_), "--sim-id", sim_id_, "--log-level",
                                  "debug"};
    if (!security.empty()) args.insert(args.end(), {"--security", security});
    server_.emplace(args, log_path_);
    if (!security.empty()) controller_id_ = transport::load_identity(id("ctl"));
    client_.emplace(domain_, sim_id_, "test", controller_id_ ? &*controller_id_ : nullptr);
    ASSERT_TRUE(client_->wait_for_server(kStart)) << "no ladderd on domain " << domain_ << "; its log:\n"
                                                  << server_->log();
  }

  // ladderctl with these arguments against the test's server.
  Result ctl(const std::string& args, double timeout = 5) {
    char t[32];
    std::snprintf(t, sizeof t, "%g", timeout);
    return shell(kCtl + " --domain " + std::to_string(domain_) + " --sim-id " + sim_id_ + " --timeout " + t + " " +
                 args);
  }

  // The server's command counter, from the first Stats that counts at least `at_least` (a Stats taken just after a
  // command was answered may have been written before it was received).
  std::uint64_t commands_received(std::uint64_t at_least) {
    const auto s =
        client_->wait_stats([&](const ladder_msg_Stats& x) { return x.commands_received >= at_least; }, kAnswer);
    EXPECT_TRUE(s.has_value()) << "no Stats counting " << at_least << " commands";
    return s ? s->commands_received : ~0ull;
  }
  // The same from the second Stats from now (Stats come once a second): written well after anything sent before.
  std::uint64_t commands_received() {
    EXPECT_TRUE(client_->wait_stats([](const ladder_msg_Stats&) { return true; }, kAnswer).has_value()) << "no Stats";
    return commands_received(0);
  }

  static inline std::string pki_;
  std::string sim_id_, log_path_;
  int domain_ = 0;
  std::optional<Process> server_;
  std::optional<transport::Identity> controller_id_;
  std::optional<Client> client_;
};

TEST_F(Security, ControllersCommandsAreAcknowledged) {
  ASSERT_NO_FATAL_FAILURE(start(id("srv")));
  EXPECT_NE(server_->log().find("DDS Security on: the server 'srv'"), std::string::npos) << server_->log();
  const client::Ack a = client_->call(cmd::pause(), kAnswer);
  EXPECT_TRUE(a.accepted) << a.reason;
  const Result r = ctl("--security " + id("ctl") + " tip");
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("accepted at t = "), std::string::npos) << r.output;
  EXPECT_EQ(commands_received(2), 2u);
  EXPECT_EQ(client_->forged(), 0u);
}

TEST_F(Security, AViewerMayNotCommandButStillDraws) {
  ASSERT_NO_FATAL_FAILURE(start(id("srv")));
  const Result r = ctl("--security " + id("v1") + " tip");
  EXPECT_EQ(r.code, 4) << r.output;  // kDenied: its own exit code
  EXPECT_NE(r.output.find("permission denied: this identity's DDS Security permissions do not allow publishing "
                          "ladder/Command"),
            std::string::npos)
      << r.output;
  EXPECT_EQ(r.output.find("accepted"), std::string::npos) << r.output;
  EXPECT_EQ(commands_received(), 0u) << "the server took a command from a viewer";
  const std::string png = kBin + "/tests/" + test_name() + ".png";
  fs::remove(png);
  const Result v = shell(kView + " --domain " + std::to_string(domain_) + " --sim-id " + sim_id_ + " --timeout 20" +
                         " --security " + id("v1") + " --png " + png);
  EXPECT_EQ(v.code, 0) << v.output;
  EXPECT_NE(v.output.find("6 blocks"), std::string::npos) << v.output;
  EXPECT_GT(fs::exists(png) ? fs::file_size(png) : 0, 1000u);
}

// Cyclone takes a domain's security settings from the process's first participant on it, so the participant with
// no identity runs in a process of its own: this binary again, running only the next test (a helper, skipped else).
TEST(SecurityHelper, UnsecuredPeer) {
  const char* env = std::getenv("LADDER_UNSECURED_PEER");  // "DOMAIN SIM_ID"
  if (env == nullptr) GTEST_SKIP() << "a helper of Security.AParticipantWithNoIdentitySeesNoServerAndReachesNoOne";
  int domain = 0;
  char sim[80] = {};
  ASSERT_EQ(std::sscanf(env, "%d %79s", &domain, sim), 2);
  BareSender bare(domain, sim);  // waits (in vain) for a match
  transport::Writer<ladder_msg_State> state_w(bare.participant, bare.topics.state, transport::Profile::State);
  const std::vector<double> poses(18, 0.5);
  const std::vector<std::uint8_t> corner(6, 0);
  const std::vector<ladder_msg_HingeStatus> status(6, ladder_msg_HINGED);
  const std::vector<std::uint32_t> flips(6, 0);
  for (std::uint64_t k = 1; k <= 20; ++k) {
    bare.pause(k);
    ladder_msg_State st{};
    transport::copy_text(st.sim_id, bare.sim_id);
    st.seq = k;
    st.step = 123456789;
    st.paused = true;
    transport::lend_blocks(st, poses, corner, status, flips);
    state_w.write(st);
    std::this_thread::sleep_for(Millis(50));
  }
  std::printf("unsecured peer: wrote 20 commands and 20 States; command writer matched %u readers, state writer %u\n",
              bare.command_w.matched(), state_w.matched());
}

TEST_F(Security, AParticipantWithNoIdentitySeesNoServerAndReachesNoOne) {
  ASSERT_NO_FATAL_FAILURE(start(id("srv")));
  const Result r = ctl("pause", 3);
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_NE(r.output.find("no ladderd with sim id '" + sim_id_ + "'"), std::string::npos) << r.output;
  // An unauthenticated participant that writes commands and States anyway: none reaches anyone.
  const Result peer = shell("LADDER_UNSECURED_PEER='" + std::to_string(domain_) + " " + sim_id_ + "' " +
                            fs::read_symlink("/proc/self/exe").string() +
                            " --gtest_filter=SecurityHelper.UnsecuredPeer");
  EXPECT_EQ(peer.code, 0) << peer.output;
  EXPECT_NE(peer.output.find("command writer matched 0 readers, state writer 0"), std::string::npos) << peer.output;
  EXPECT_EQ(commands_received(), 0u);
  const auto st = client_->wait_state([](const client::State& s) { return s.seq > 0; }, kAnswer);
  ASSERT_TRUE(st.has_value());
  EXPECT_FALSE(st->paused);
  EXPECT_NE(st->step, 123456789u);
  EXPECT_EQ(client_->forged(), 0u) << "an unauthenticated participant's samples reached the controller";
}

TEST_F(Security, AnIdentityOfAnotherCaIsRejected) {
  ASSERT_NO_FATAL_FAILURE(start(id("srv")));
  // Its own folder is consistent (its CA signed it), so it starts; the server's handshake refuses it.
  const Result r = ctl("--security " + rogue("ctl") + " pause", 4);
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_EQ(commands_received(), 0u);
  // The other CA's certificate in a folder of ours: refused before DDS starts, naming the file.
  const std::string mixed = pki_ + "/mixed";
  fs::create_directories(mixed);
  for (const char* f : {"ca.pem", "governance.p7s", "permissions.p7s"})
    fs::copy_file(id("ctl") + "/" + f, mixed + "/" + f, fs::copy_options::overwrite_existing);
  for (const char* f : {"cert.pem", "key.pem"})
    fs::copy_file(rogue("ctl") + "/" + f, mixed + "/" + f, fs::copy_options::overwrite_existing);
  const Result m = ctl("--security " + mixed + " pause");
  EXPECT_EQ(m.code, 2) << m.output;
  EXPECT_NE(m.output.find(mixed + "/cert.pem: not signed by " + mixed + "/ca.pem"), std::string::npos) << m.output;
}

TEST_F(Security, EveryWayTheFilesCanBeWrongIsNamed) {
  const auto daemon = [](const std::string& args) { return shell(kDaemon + " --domain 230 " + args); };
  // Expired: refused with its date, by a client and by the server.
  Result r = shell(kCtl + " --security " + id("old") + " pause");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find(id("old") + "/cert.pem: the identity 'old' expired on 2025-01-01 00:00:00 UTC"),
            std::string::npos)
      << r.output;
  r = daemon("--security " + id("oldsrv"));
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("the identity 'oldsrv' expired on 2025-01-01 00:00:00 UTC"), std::string::npos) << r.output;
  // Wrong role.
  r = daemon("--security " + id("ctl"));
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("ladderd needs a server identity, but " + id("ctl") + " is the controller 'ctl'"),
            std::string::npos)
      << r.output;
  r = shell(kView + " --security " + id("srv") + " --png /dev/null");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("ladder-view needs a viewer or controller identity, but"), std::string::npos) << r.output;
  // Missing folder, missing file, a document changed after signing.
  r = daemon("--security " + pki_ + "/nobody");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find(pki_ + "/nobody: no such folder"), std::string::npos) << r.output;
  const std::string broken = pki_ + "/broken";
  fs::remove_all(broken);
  fs::copy(id("srv"), broken);
  fs::remove(broken + "/permissions.p7s");
  r = daemon("--security " + broken);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find(broken + "/permissions.p7s: missing"), std::string::npos) << r.output;
  {
    std::ifstream in(id("srv") + "/permissions.p7s");
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const auto at = text.find("<subscribe>");
    ASSERT_NE(at, std::string::npos);
    text.replace(at, 11, "<publish>  ");  // same length; the signature no longer matches
    std::ofstream(broken + "/permissions.p7s") << text;
  }
  r = daemon("--security " + broken);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find(broken + "/permissions.p7s: its signature does not verify with"), std::string::npos)
      << r.output;
  // The configuration file's key, with its position.
  const std::string toml = kBin + "/tests/" + test_name() + ".toml";
  std::ofstream(toml) << "[server]\nsecurity = \"" << id("v1") << "\"\n";
  r = daemon("--config " + toml);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find(toml + ":2:12: server.security security: ladderd needs a server identity, but " + id("v1") +
                          " is the viewer 'v1'"),
            std::string::npos)
      << r.output;
}

// Without security: a participant that reads every command and answers each with 100 forged refusals, and
// publishes States of its own under the server's sim id.
struct Forger {
  Forger(int domain, std::string id)
      : sim_id(std::move(id)),
        participant(transport::make_participant(static_cast<dds_domainid_t>(domain))),
        topics(participant),
        command_r(participant, topics.command, transport::Profile::Command),
        ack_w(participant, topics.ack, transport::Profile::CommandAck),
        state_w(participant, topics.state, transport::Profile::State),
        thread([this] { run(); }) {}
  ~Forger() {
    stop = true;
    thread.join();
  }
  void run() {
    transport::Waiter w(participant);
    w.attach(command_r.entity());
    const std::vector<double> poses(18, 0.5);
    const std::vector<std::uint8_t> corner(6, 0);
    const std::vector<ladder_msg_HingeStatus> status(6, ladder_msg_HINGED);
    const std::vector<std::uint32_t> flips(6, 0);
    std::uint64_t seq = 0;
    while (!stop) {
      w.wait(Millis(5));
      command_r.take([&](const ladder_msg_Command& c, const dds_sample_info_t&) {
        ladder_msg_CommandAck a{};
        transport::copy_text(a.sim_id, transport::text_of(c.sim_id));
        transport::copy_text(a.client_id, transport::text_of(c.client_id));
        a.command_id = c.command_id;
        a.accepted = false;
        transport::copy_text(a.reason, "FORGED refusal");
        for (int k = 0; k < 100; ++k) {
          ack_w.try_write(a);
          ++acks;
        }
      });
      ladder_msg_State s{};
      transport::copy_text(s.sim_id, sim_id);
      s.seq = ++seq;
      s.step = kForgedStep;
      transport::lend_blocks(s, poses, corner, status, flips);
      state_w.try_write(s);
    }
  }
  static constexpr std::uint64_t kForgedStep = 123456789;
  std::string sim_id;
  transport::Entity participant;
  transport::Topics topics;
  transport::Reader<ladder_msg_Command> command_r;
  transport::Writer<ladder_msg_CommandAck> ack_w;
  transport::Writer<ladder_msg_State> state_w;
  std::atomic<bool> stop{false};
  std::atomic<std::uint64_t> acks{0};
  std::thread thread;
};

TEST_F(Security, WithoutSecurityAForgedAckIsNeverTaken) {
  ASSERT_NO_FATAL_FAILURE(start(""));
  ASSERT_TRUE(client_->call(cmd::pause(), kAnswer).accepted);  // `step` needs a paused server
  Forger forger(domain_, sim_id_);
  while (forger.ack_w.matched() == 0) std::this_thread::sleep_for(Millis(5));
  for (int k = 0; k < 100; ++k) {
    const client::Ack a = client_->call(cmd::step(1), kAnswer);
    ASSERT_EQ(a.reason, "") << "command " << k << ": took a forged answer";
    ASSERT_TRUE(a.accepted);
  }
  const auto st =
      client_->wait_state([](const client::State& s) { return s.step == Forger::kForgedStep; }, Millis(500));
  EXPECT_FALSE(st.has_value()) << "took a forged State";
  EXPECT_GT(client_->forged(), 100u * 100u / 2) << "the forger's acks did not arrive: the race was not run";
  // ladderctl: never a forged answer (exit 1 or its text), and every run finds the server. (About 1 run in 25 used
  // to time out here: the paused server's one State was pushed out of ladderctl's one-sample State history by the
  // forger's, or dropped when the forger's came after it; docs/security.md.)
  for (int k = 0; k < 10; ++k) {
    const auto t0 = Clock::now();
    const Result r = ctl("step 1", 10);
    std::printf("ladderctl run %d: exit %d after %.2f s\n", k, r.code,
                std::chrono::duration<double>(Clock::now() - t0).count());
    EXPECT_EQ(r.output.find("FORGED"), std::string::npos) << "ladderctl printed a forged ack: " << r.output;
    EXPECT_EQ(r.code, 0) << r.output;
    EXPECT_NE(r.output.find("accepted at t = "), std::string::npos) << r.output;
  }
  std::printf("forged acks written: %llu, ignored by the test's client: %llu\n",
              static_cast<unsigned long long>(forger.acks.load()),
              static_cast<unsigned long long>(client_->forged()));
}

// Without DDS Security another participant may send a command under this client's id (it reads the ids off the
// domain); the server answers it, and the answer reaches this client as if it were its own. One that comes before
// this client sends that command id is not taken for its answer: here a spoofer's accepted pause arrives as "victim"
// command 1 before the victim sends its own command 1 (a break of a hinge that does not exist), whose answer is its
// own refusal.
TEST_F(Security, WithoutSecurityASpoofersAnswerThatCameFirstIsNotTaken) {
  ASSERT_NO_FATAL_FAILURE(start(""));
  Client victim(domain_, sim_id_, "victim");
  Client spoofer(domain_, sim_id_, "victim");
  ASSERT_TRUE(victim.wait_for_server(kStart));
  ASSERT_TRUE(spoofer.wait_for_server(kStart));
  ASSERT_TRUE(spoofer.call(cmd::pause(), kAnswer).accepted);  // command 1 under "victim"
  // The victim's reader has it too once a State after the pause reaches it (acks come before the next State).
  ASSERT_TRUE(victim.wait_state([](const client::State& st) { return st.paused; }, kAnswer).has_value());
  victim.wait_state([](const client::State&) { return false; }, Millis(200));
  const client::Ack mine = victim.call(cmd::break_hinge(99), kAnswer);
  EXPECT_FALSE(mine.accepted) << "took the spoofer's answer to its command 1";
  EXPECT_EQ(mine.reason, "no hinge 99 (hinges are 0..5; hinge 0 is the top block's hold)");
}

// Figures for docs/security.md (printed, not asserted): the round trip of a command with and without security.
void ack_latency(Client& c, const char* what) {
  ASSERT_TRUE(c.call(cmd::pause(), kAnswer).accepted);
  std::vector<double> ms;
  for (int k = 0; k < 200; ++k) {
    const auto t0 = Clock::now();
    const client::Ack a = c.call(cmd::step(1), kAnswer);
    ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
    ASSERT_TRUE(a.accepted) << a.reason;
  }
  std::sort(ms.begin(), ms.end());
  std::printf("ack round trip %s: p50 %.3f ms, p99 %.3f ms, max %.3f ms (200 commands)\n", what, ms[100], ms[197],
              ms.back());
}

// Every packet on the loopback interface, searched for a byte string (root only: an AF_PACKET socket). Other tests
// running at once send their own traffic over lo, under sim ids of their own.
class LoopbackCapture {
 public:
  explicit LoopbackCapture(std::string needle) : needle_(std::move(needle)) {
    fd_ = socket(AF_PACKET, SOCK_RAW | SOCK_CLOEXEC, htons(ETH_P_ALL));
    sockaddr_ll a{};
    a.sll_family = AF_PACKET;
    a.sll_protocol = htons(ETH_P_ALL);
    a.sll_ifindex = static_cast<int>(if_nametoindex("lo"));
    ok_ = fd_ >= 0 && a.sll_ifindex > 0 && bind(fd_, reinterpret_cast<const sockaddr*>(&a), sizeof a) == 0;
    if (ok_) thread_ = std::thread([this] { run(); });
  }
  ~LoopbackCapture() {
    stop_ = true;
    if (thread_.joinable()) thread_.join();
    if (fd_ >= 0) close(fd_);
  }
  bool ok() const { return ok_; }
  std::uint64_t packets() const { return packets_; }
  std::uint64_t matches() const { return matches_; }

 private:
  void run() {
    std::vector<char> buf(1 << 16);
    while (!stop_) {
      pollfd p{fd_, POLLIN, 0};
      if (poll(&p, 1, 50) <= 0) continue;
      const ssize_t n = recv(fd_, buf.data(), buf.size(), 0);
      if (n <= 0) continue;
      ++packets_;
      if (std::search(buf.begin(), buf.begin() + n, needle_.begin(), needle_.end()) != buf.begin() + n) ++matches_;
    }
  }
  std::string needle_;
  int fd_ = -1;
  bool ok_ = false;
  std::atomic<bool> stop_{false};
  std::atomic<std::uint64_t> packets_{0}, matches_{0};
  std::thread thread_;
};

// On the wire, nothing of a secure session is readable: its sim id, which every State, Command and ack carries,
// appears in no packet on lo while a controller commands the server. Without security the same capture finds it
// (so the capture itself works).
TEST_F(Security, OnTheWireNothingOfASecureSessionIsReadable) {
  if (geteuid() != 0) GTEST_SKIP() << "capturing the loopback traffic needs root (an AF_PACKET socket)";
  for (const bool secure : {false, true}) {
    std::uint64_t packets = 0, matches = 0;
    {
      LoopbackCapture capture(sim_id_for(test_name()));
      ASSERT_TRUE(capture.ok()) << "no AF_PACKET socket on lo: " << std::strerror(errno);
      ASSERT_NO_FATAL_FAILURE(start(secure ? id("srv") : ""));
      for (int i = 0; i < 20; ++i) {
        const client::Ack a = client_->call(cmd::set("damping.linear=0.5"), kAnswer);
        ASSERT_TRUE(a.accepted) << a.reason;
      }
      std::this_thread::sleep_for(Millis(300));  // the last states on the wire too
      packets = capture.packets();
      matches = capture.matches();
    }
    client_.reset();
    server_.reset();
    std::printf("%s: %llu packets on lo, %llu with the sim id\n", secure ? "with DDS Security" : "without security",
                static_cast<unsigned long long>(packets), static_cast<unsigned long long>(matches));
    EXPECT_GT(packets, 100u);
    if (secure)
      EXPECT_EQ(matches, 0u) << "the sim id is readable on the wire of a secure session";
    else
      EXPECT_GT(matches, 20u) << "without security the capture should see the sim id (in the states, commands, acks)";
  }
}

TEST_F(Security, AckLatencyWithSecurity) {
  ASSERT_NO_FATAL_FAILURE(start(id("srv")));
  ack_latency(*client_, "with DDS Security (ENCRYPT)");
}

TEST_F(Security, AckLatencyWithoutSecurity) {
  ASSERT_NO_FATAL_FAILURE(start(""));
  ack_latency(*client_, "without security");
}

}  // namespace
}  // namespace ladder::test
