// Two network namespaces joined by a veth pair, for tests that put ladderd on one side and its clients on the other,
// and random loss or a partition between them (a BPF classifier on each end's egress, tests/net/drop.c).
//
// No /run/netns: `ip netns add` bind-mounts that folder and every namespace into it, and whatever a test does not
// delete (a failed test, a killed one) stays mounted. Here each namespace belongs to a child process that unshares
// a new one and sleeps; the kernel kills it when the test process ends, however it ends (PR_SET_PDEATHSIG), and the
// namespace, its veth end and so the pair go with it. Nothing is mounted. Programs run in a namespace through
// nsenter --net=/proc/PID/ns/net (and die with the test too); the test's own thread can enter side b to run a
// client library Client there (Cyclone makes its sockets and threads in the namespace of the thread that creates
// the domain's first participant).
#pragma once

#include "process.hpp"

#include <fcntl.h>
#include <sched.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdint>
#include <cstring>
#include <initializer_list>
#include <optional>
#include <regex>
#include <stdexcept>
#include <string>
#include <vector>

namespace ladder::test {

// The first of `paths` that can be run; throws naming the package when none can (a missing tool is a broken test
// machine, not a reason to skip).
inline std::string tool(std::initializer_list<const char*> paths, const std::string& package) {
  for (const char* p : paths)
    if (access(p, X_OK) == 0) return p;
  throw std::runtime_error(std::string("no ") + *paths.begin() + ": install " + package + " (scripts/install-deps)");
}
inline std::string ip_tool() { return tool({"/usr/sbin/ip", "/sbin/ip", "/usr/bin/ip", "/bin/ip"}, "iproute2"); }
inline std::string tc_tool() { return tool({"/usr/sbin/tc", "/sbin/tc", "/usr/bin/tc"}, "iproute2"); }
inline std::string nsenter_tool() { return tool({"/usr/bin/nsenter", "/bin/nsenter"}, "util-linux"); }
inline std::string setpriv_tool() { return tool({"/usr/bin/setpriv", "/bin/setpriv"}, "util-linux"); }

class NetnsPair {
 public:
  // Side a (the server's) and side b (the clients'): device and address.
  static constexpr const char* kDevA = "nfa";
  static constexpr const char* kDevB = "nfb";
  static constexpr const char* kAddrA = "10.77.0.1";
  static constexpr const char* kAddrB = "10.77.0.2";

  NetnsPair() = default;
  NetnsPair(const NetnsPair&) = delete;
  NetnsPair& operator=(const NetnsPair&) = delete;
  ~NetnsPair() {
    leave_b();
    for (pid_t p : {holder_a_, holder_b_})
      if (p > 0) {
        kill(p, SIGKILL);
        waitpid(p, nullptr, 0);
      }
  }

  // Makes the namespaces and the link. nullopt when it worked; otherwise why this machine cannot (not root, or the
  // kernel refused): a reason to skip. Throws when a tool is missing.
  std::optional<std::string> create() {
    if (geteuid() != 0)
      return "not root (euid " + std::to_string(geteuid()) + "): network namespaces, veth pairs and BPF classifiers "
             "need root";
    const std::string ip = ip_tool();
    nsenter_tool();
    setpriv_tool();
    tc_tool();
    for (pid_t* holder : {&holder_a_, &holder_b_})
      if (auto why = hold_new_namespace(*holder)) return "the kernel refused a network namespace: " + *why;
    const std::string veth = ip + " link add " + kDevA + " netns " + std::to_string(holder_a_) +
                             " type veth peer name " + kDevB + " netns " + std::to_string(holder_b_);
    if (const Result r = shell(veth); r.code != 0) return "the kernel refused a veth pair: " + veth + ": " + r.output;
    for (const auto& [side, dev, addr] : {std::tuple{'a', kDevA, kAddrA}, std::tuple{'b', kDevB, kAddrB}}) {
      for (const std::string& step : {std::string("addr add ") + addr + "/24 dev " + dev,
                                      std::string("link set ") + dev + " up", std::string("link set lo up")}) {
        const Result r = in(side, ip + " " + step);
        if (r.code != 0) throw std::runtime_error("ip " + step + " in namespace " + side + ": " + r.output);
      }
    }
    return std::nullopt;
  }

  // Drops packets on both ends' egress with the classifier in `bpf_object` (replacing any other). nullopt when it
  // worked, else what the kernel (or tc) said: a reason to skip.
  std::optional<std::string> set_loss(const std::string& bpf_object) {
    const std::string tc = tc_tool();
    for (const auto& [side, dev] : {std::pair{'a', kDevA}, std::pair{'b', kDevB}}) {
      if (!clsact_) {
        if (const Result r = in(side, tc + " qdisc add dev " + dev + " clsact"); r.code != 0)
          return "tc qdisc add dev " + std::string(dev) + " clsact: " + r.output;
      }
      in(side, tc + " filter del dev " + std::string(dev) + " egress");  // fails harmlessly when there is none
      const std::string add = tc + " filter add dev " + dev + " egress bpf da obj " + bpf_object + " sec classifier";
      if (const Result r = in(side, add); r.code != 0) return add + ": " + r.output;
    }
    clsact_ = true;
    return std::nullopt;
  }
  // Removes the classifiers: every packet passes again.
  void clear_loss() {
    const std::string tc = tc_tool();
    for (const auto& [side, dev] : {std::pair{'a', kDevA}, std::pair{'b', kDevB}}) {
      const Result r = in(side, tc + " filter del dev " + std::string(dev) + " egress");
      if (r.code != 0) throw std::runtime_error("tc filter del dev " + std::string(dev) + " egress: " + r.output);
    }
  }

  // Packets that reached one end's egress classifier, and those it dropped (the clsact qdisc's counters).
  struct Egress {
    std::uint64_t packets = 0, dropped = 0;
  };
  Egress egress(char side) const {
    const Result r = in(side, tc_tool() + " -s qdisc show dev " + (side == 'a' ? kDevA : kDevB));
    std::smatch m;
    static const std::regex clsact(R"(qdisc clsact[^\n]*\n\s*Sent \d+ bytes (\d+) pkt \(dropped (\d+))");
    if (!std::regex_search(r.output, m, clsact)) throw std::runtime_error("no clsact counters in: " + r.output);
    return {std::stoull(m[1]), std::stoull(m[2])};
  }

  // A shell command run in namespace a or b; its exit code and output.
  Result in(char side, const std::string& command) const { return shell(prefix(side) + command); }
  // The argument list that runs `args` in namespace a or b with this CYCLONEDDS_URI (XML text or file://). The program
  // is killed when the thread that starts it ends (setpriv --pdeathsig), so that a test that dies leaves no server
  // holding a namespace.
  std::vector<std::string> run_in(char side, const std::string& cyclone_uri, std::vector<std::string> args) const {
    std::vector<std::string> all{nsenter_tool(), net_option(side), setpriv_tool(), "--pdeathsig", "KILL",
                                 "/usr/bin/env", "CYCLONEDDS_URI=" + cyclone_uri};
    all.insert(all.end(), args.begin(), args.end());
    return all;
  }

  // The same as a prefix for shell(); the URI must need no quoting (a file:// path without spaces).
  std::string shell_prefix(char side, const std::string& cyclone_uri) const {
    std::string out;
    for (const std::string& a : run_in(side, cyclone_uri, {})) out += a + " ";
    return out;
  }

  // Moves the calling thread into namespace b (and back). Threads it starts afterwards (Cyclone's) are in b too.
  void enter_b() {
    if (home_ >= 0) return;
    home_ = open("/proc/thread-self/ns/net", O_RDONLY | O_CLOEXEC);
    const int b = open(("/proc/" + std::to_string(holder_b_) + "/ns/net").c_str(), O_RDONLY | O_CLOEXEC);
    const int rc = b < 0 ? -1 : setns(b, CLONE_NEWNET);
    const int err = errno;
    if (b >= 0) close(b);
    if (home_ < 0 || rc != 0) throw std::runtime_error(std::string("entering namespace b: ") + std::strerror(err));
  }
  void leave_b() {
    if (home_ < 0) return;
    setns(home_, CLONE_NEWNET);
    close(home_);
    home_ = -1;
  }

  // A Cyclone configuration for one side: its veth only, no multicast, the other side as a unicast peer.
  static std::string cyclone_xml(const std::string& interface, const std::string& peer) {
    return "<CycloneDDS xmlns=\"https://cdds.io/config\"><Domain id=\"any\"><General><Interfaces>"
           "<NetworkInterface name=\"" + interface + "\"/></Interfaces><AllowMulticast>false</AllowMulticast>"
           "</General><Discovery><ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>32"
           "</MaxAutoParticipantIndex><Peers><Peer address=\"" + peer + "\"/></Peers></Discovery></Domain>"
           "</CycloneDDS>";
  }
  static std::string xml_a() { return cyclone_xml(kDevA, kAddrB); }
  static std::string xml_b() { return cyclone_xml(kDevB, kAddrA); }

 private:
  std::string net_option(char side) const {
    return "--net=/proc/" + std::to_string(side == 'a' ? holder_a_ : holder_b_) + "/ns/net";
  }
  std::string prefix(char side) const { return nsenter_tool() + " " + net_option(side) + " "; }

  // Starts a child in a new network namespace, which lives until the child is killed; nullopt or the error.
  static std::optional<std::string> hold_new_namespace(pid_t& holder) {
    int report[2];
    if (pipe2(report, O_CLOEXEC) != 0) return std::string("pipe: ") + std::strerror(errno);
    const pid_t parent = getpid();
    holder = fork();
    if (holder == 0) {  // only system calls here: the test process may have threads
      prctl(PR_SET_PDEATHSIG, SIGKILL);
      if (getppid() != parent) _exit(1);  // the test ended before prctl
      int err = unshare(CLONE_NEWNET) == 0 ? 0 : errno;
      (void)!write(report[1], &err, sizeof err);
      if (err != 0) _exit(1);
      while (true) pause();
    }
    close(report[1]);
    int err = -1;
    const bool got = holder > 0 && read(report[0], &err, sizeof err) == static_cast<ssize_t>(sizeof err);
    close(report[0]);
    if (got && err == 0) return std::nullopt;
    if (holder > 0) {
      kill(holder, SIGKILL);
      waitpid(holder, nullptr, 0);
    }
    holder = -1;
    return std::string("unshare(CLONE_NEWNET): ") + (got ? std::strerror(err) : "the child did not answer");
  }

  pid_t holder_a_ = -1, holder_b_ = -1;
  bool clsact_ = false;
  int home_ = -1;  // the thread's own namespace while it is in b
};

}  // namespace ladder::test
