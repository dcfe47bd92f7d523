// The installed layout (docs/install.md): `cmake --install` into a prefix of the test's own, then the installed
// programs, run from another directory, find their scenes and configuration there; the systemd units pass
// systemd-analyze verify.
#include "process.hpp"

#include <gtest/gtest.h>

#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>

namespace ladder::test {
namespace {

namespace fs = std::filesystem;

const std::string kBuild = LADDER_BINARY_DIR;

// One install for the file's tests, into a fresh folder.
class Installed : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    prefix_ = fs::temp_directory_path() / ("ladder-install-" + std::to_string(getpid()));
    fs::remove_all(prefix_);
    install_ = shell(std::string(CMAKE_COMMAND) + " --install " + kBuild + " --prefix " + prefix_.string());
  }
  static void TearDownTestSuite() { fs::remove_all(prefix_); }
  void SetUp() override { ASSERT_EQ(install_.code, 0) << install_.output; }

  static std::string bin(const std::string& name) { return (prefix_ / "bin" / name).string(); }
  // A command run from / (not the build or source tree), its output with standard error.
  static Result from_root(const std::string& command) { return shell("cd / && " + command); }

  static fs::path prefix_;
  static Result install_;
};
fs::path Installed::prefix_;
Result Installed::install_;

TEST_F(Installed, TheLayoutIsThere) {
  for (const char* f : {"bin/ladderd", "bin/ladderctl", "bin/ladder-view", "etc/ladder/ladderd.toml",
                        "share/ladder/scenes/classic.toml", "share/ladder/scenes/double-ripple.toml",
                        "share/ladder/scenes/long.toml", "share/ladder/scenes/free-chain.toml",
                        "share/ladder/scenes/toy-1889.toml", "share/ladder/scenes/tall.toml",
                        "share/ladder/scenes/tall-double-ripple.toml",
                        "share/ladder/cyclonedds.xml", "share/ladder/cyclonedds-network.xml",
                        "share/ladder/ladder.idl", "share/doc/ladder/examples/c-client/ladder_client.c",
                        "share/doc/ladder/examples/c-client/CMakeLists.txt",
                        "lib/systemd/system/ladderd.service", "lib/systemd/system/ladderd@.service",
                        "share/doc/ladder/install.md"})
    EXPECT_TRUE(fs::is_regular_file(prefix_ / f)) << f;
  // The configuration's scene folder is the installed one.
  std::ifstream in(prefix_ / "etc/ladder/ladderd.toml");
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_NE(text.find("scenes_dir = \"" + (prefix_ / "share/ladder/scenes").string() + "\""), std::string::npos)
      << text;
}

TEST_F(Installed, EveryProgramPrintsTheOneVersion) {
  for (const char* p : {"ladderd", "ladderctl", "ladder-view"}) {
    const Result r = from_root(bin(p) + " --version");
    EXPECT_EQ(r.code, 0) << r.output;
    EXPECT_EQ(r.output, std::string(p) + " " + LADDER_VERSION + "\n");
  }
}

// From /, `--scene NAME` finds the installed scene by name, and a name that is none says where it looked.
TEST_F(Installed, SceneByNameFromAnywhere) {
  const Result r = from_root(bin("ladderd") + " --offline --scene double-ripple --duration 0.01 --quiet");
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find((prefix_ / "share/ladder/scenes/double-ripple.toml").string()), std::string::npos)
      << r.output;
  const Result bad = from_root(bin("ladderd") + " --offline --scene no-such-scene --duration 0.01");
  EXPECT_EQ(bad.code, 2) << bad.output;
  EXPECT_NE(bad.output.find("--scene no-such-scene: no such file, and no scene of that name in " +
                            (prefix_ / "share/ladder/scenes").string()),
            std::string::npos)
      << bad.output;
}

// The installed server with the installed configuration, started from /: it serves the default scene, and loads
// an installed one by name.
TEST_F(Installed, ServesTheDefaultSceneAndLoadsInstalledOnes) {
  const std::string domain = std::to_string(1 + getpid() % 230), id = "installed-" + std::to_string(getpid());
  Process server({"/bin/sh", "-c",
                  "cd / && exec " + bin("ladderd") + " --config " + (prefix_ / "etc/ladder/ladderd.toml").string() +
                      " --domain " + domain + " --sim-id " + id},
                 kBuild + "/tests/Installed.server.log");
  const std::string ctl = bin("ladderctl") + " --domain " + domain + " --sim-id " + id + " --timeout 15 ";
  const Result status = from_root(ctl + "status");
  EXPECT_EQ(status.code, 0) << status.output << server.log();
  EXPECT_NE(status.output.find("scene 'classic (at rest)': 6 blocks"), std::string::npos) << status.output;
  const Result load = from_root(ctl + "load long");
  EXPECT_EQ(load.code, 0) << load.output << server.log();
  EXPECT_NE(server.log().find("scene 'Long ladder' started (1000 blocks)"), std::string::npos) << server.log();
  server.signal(SIGTERM);
  EXPECT_TRUE(server.wait_exit(std::chrono::milliseconds(10000)).has_value());
}

// A client of your own (docs/server.md, "Your own client"): the installed C example, built on its own against the
// installed ladder.idl and Cyclone DDS with CMake, run with the installed Cyclone configuration against the
// installed server. It sees the ladder, its tip is accepted and the ripple's first flip-flop comes as an event, and
// its poke of a block that does not exist is refused with the server's reason.
TEST_F(Installed, AClientOfYourOwnBuiltFromTheInstalledExampleTipsAndHearsARefusal) {
  const fs::path example = prefix_ / "share/doc/ladder/examples/c-client", build = prefix_ / "example-build";
  const std::string cmake = CMAKE_COMMAND;
  const Result made = from_root(cmake + " -S " + example.string() + " -B " + build.string() + " && " + cmake +
                                " --build " + build.string());
  ASSERT_EQ(made.code, 0) << made.output;
  const std::string domain = std::to_string(1 + (getpid() + 7) % 230), id = "own-" + std::to_string(getpid());
  Process server({"/bin/sh", "-c",
                  "cd / && exec " + bin("ladderd") + " --config " + (prefix_ / "etc/ladder/ladderd.toml").string() +
                      " --domain " + domain + " --sim-id " + id},
                 kBuild + "/tests/Installed.own-client.server.log");
  const Result r = from_root("CYCLONEDDS_URI=file://" + (prefix_ / "share/ladder/cyclonedds.xml").string() + " " +
                             (build / "ladder-c-client").string() + " " + domain + " " + id);
  EXPECT_EQ(r.code, 0) << r.output << server.log();
  EXPECT_NE(r.output.find("scene 'classic (at rest)': 6 blocks of 64 x 13 mm, top block held, dt 1 ms\n"),
            std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("state: t = "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find(" s, 6 blocks, block 0 at ("), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("tip: accepted at t = "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("event: flip_flop at hinge 1, t = "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("poke block 99: refused: no block 99 (blocks are 0..5)\n"), std::string::npos) << r.output;
  server.signal(SIGTERM);
  EXPECT_TRUE(server.wait_exit(std::chrono::milliseconds(10000)).has_value());
}

// systemd-analyze verify has nothing to say about either unit (it warns, and still exits 0, on an unknown key), with
// their paths pointed at this prefix so that it finds the binary.
TEST_F(Installed, SystemdUnitsVerify) {
  if (shell("command -v systemd-analyze").code != 0) GTEST_SKIP() << "systemd-analyze is not installed (systemd)";
  for (const char* unit : {"ladderd.service", "ladderd@.service"}) {
    const fs::path copy = fs::path(kBuild) / "tests" / unit;
    const Result sed = shell("sed 's|" + std::string(LADDER_INSTALL_PREFIX) + "|" + prefix_.string() + "|g' " +
                             (prefix_ / "lib/systemd/system" / unit).string() + " > " + copy.string());
    ASSERT_EQ(sed.code, 0) << sed.output;
    const Result r = shell("systemd-analyze verify " + copy.string());
    EXPECT_EQ(r.code, 0) << r.output;
    EXPECT_EQ(r.output, "") << unit;
  }
}

}  // namespace
}  // namespace ladder::test
