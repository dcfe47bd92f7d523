// ladder-tradeoff as a user runs it: the real binary's quick study (the free chain N = 2), its CSV, Markdown and PNG
// checked for what a wrong study would get wrong, and its refusal of a bad argument.
#include "process.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <unistd.h>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <utility>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;
const std::string kTool = std::string(LADDER_BINARY_DIR) + "/bench/ladder-tradeoff";

std::vector<std::string> split(const std::string& line, char sep) {
  std::vector<std::string> out;
  std::string cell;
  bool quoted = false;
  for (char c : line) {
    if (c == '"') quoted = !quoted;
    else if (c == sep && !quoted) out.push_back(std::exchange(cell, {}));
    else cell += c;
  }
  out.push_back(cell);
  return out;
}

class QuickStudy : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = fs::temp_directory_path() / ("ladder-tradeoff-" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    result_ = ladder::test::shell(kTool + " --quick --min-timing 0 --out " + dir_.string());
    std::ifstream in(dir_ / "tradeoff.csv");
    std::string line;
    std::getline(in, line);
    header_ = split(line, ',');
    while (std::getline(in, line)) {
      std::map<std::string, std::string> row;
      const auto cells = split(line, ',');
      widths_.push_back(cells.size());
      for (size_t i = 0; i < header_.size() && i < cells.size(); ++i) row[header_[i]] = cells[i];
      rows_.push_back(row);
    }
  }
  static void TearDownTestSuite() { fs::remove_all(dir_); }

  // The angle error of `knob` at `dt` [s].
  static double error(const std::string& knob, double dt) {
    for (const auto& r : rows_)
      if (r.at("knob") == knob && std::abs(std::stod(r.at("dt_s")) - dt) < 1e-12)
        return std::stod(r.at("angle_error_max_rad"));
    ADD_FAILURE() << "no row for " << knob << " at dt " << dt;
    return NAN;
  }

  static inline fs::path dir_;
  static inline ladder::test::Result result_;
  static inline std::vector<std::string> header_;
  static inline std::vector<std::map<std::string, std::string>> rows_;
  static inline std::vector<size_t> widths_;  // cells per row
};

TEST_F(QuickStudy, WritesEveryRunWithItsCostAndError) {
  ASSERT_EQ(result_.code, 0) << result_.output;
  EXPECT_NE(result_.output.find("26/26"), std::string::npos) << result_.output;  // the progress reached the end
  ASSERT_GE(header_.size(), 20u);
  EXPECT_EQ(header_[0], "scene");
  // Two reference runs, then 7 integrators and the paper's solver at 3 steps each.
  ASSERT_EQ(rows_.size(), 2u + 8 * 3);
  for (size_t w : widths_) EXPECT_EQ(w, header_.size());  // text with commas (knob names, failures) is quoted
  for (const auto& r : rows_) {
    EXPECT_EQ(r.at("ok"), "1") << r.at("knob") << " " << r.at("setting");
    EXPECT_GT(std::stod(r.at("wall_per_sim_second")), 0);
    EXPECT_GT(std::stod(r.at("block_steps_per_second")), 0);
  }
}

// The reference is converged: RK4 at twice its step differs from it by under 1e-11 rad.
TEST_F(QuickStudy, TheReferenceIsShownConvergedByHalving) {
  ASSERT_GE(rows_.size(), 2u);
  EXPECT_EQ(rows_[0].at("knob"), "reference");
  EXPECT_LT(std::stod(rows_[0].at("angle_error_max_rad")), 1e-11);
  EXPECT_EQ(std::stod(rows_[1].at("angle_error_max_rad")), 0.0);  // the reference against itself
}

// The errors the study reports have each integrator's order: halving 1 ms divides them by about 2, 4 and 16.
TEST_F(QuickStudy, ErrorsShowEachIntegratorsOrder) {
  const auto ratio = [](const std::string& knob) { return error(knob, 1e-3) / error(knob, 5e-4); };
  EXPECT_NEAR(ratio("symplectic_euler"), 2.0, 0.4);
  EXPECT_NEAR(ratio("euler"), 2.0, 0.6);
  EXPECT_NEAR(ratio("rattle"), 4.0, 0.6);
  EXPECT_NEAR(ratio("rk4"), 16.0, 4.0);
  EXPECT_NEAR(ratio("reduced"), 2.0, 0.4);
  EXPECT_NEAR(ratio("midpoint"), 4.0, 0.6);
  // The paper's solver changes the cost, not the answer (both converge to 1e-12 m).
  EXPECT_NEAR(error("symplectic_euler + newton_linesearch", 1e-3), error("symplectic_euler", 1e-3), 1e-9);
  // RK4 at 1 ms is more accurate than any first-order method at 0.5 ms.
  EXPECT_LT(error("rk4", 1e-3), 1e-3 * error("symplectic_euler", 5e-4));
}

TEST_F(QuickStudy, MarkdownAndPlotAreWritten) {
  std::ifstream md(dir_ / "tradeoff.md");
  std::stringstream text;
  text << md.rdbuf();
  EXPECT_NE(text.str().find("| knob | setting | cost [s/s]"), std::string::npos);
  EXPECT_NE(text.str().find("Error ratio when dt halves"), std::string::npos);
  // A real PNG: the signature, then the IHDR chunk with the image's width (one 700-pixel panel).
  std::ifstream png(dir_ / "tradeoff.png", std::ios::binary);
  std::vector<unsigned char> head(24);
  png.read(reinterpret_cast<char*>(head.data()), 24);
  ASSERT_TRUE(png) << "tradeoff.png";
  const unsigned char signature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  EXPECT_TRUE(std::equal(signature, signature + 8, head.begin()));
  const std::uint32_t width = (head[16] << 24) | (head[17] << 16) | (head[18] << 8) | head[19];
  EXPECT_EQ(width, 700u);
}

TEST(Tradeoff, RefusesAnUnknownScene) {
  const auto r = ladder::test::shell(kTool + " --only nosuch --out " + (fs::temp_directory_path() / "x").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("no scene 'nosuch' in the study (free2, free100, classic, long)"), std::string::npos)
      << r.output;
}

}  // namespace
