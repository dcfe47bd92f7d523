// ladder-tradeoff: measures what each speed/accuracy knob costs and how wrong it is (docs/tradeoff.md).
#include "report.hpp"
#include "study.hpp"

#include <CLI/CLI.hpp>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <unistd.h>

namespace {

using namespace ladder::tradeoff;

// A progress bar on a terminal (redrawn in place), one line per run otherwise (CI logs).
class Progress {
 public:
  explicit Progress(size_t total) : total_(total), tty_(isatty(STDERR_FILENO) != 0) {}
  void next(const std::string& what) {
    ++done_;
    const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
    const int width = 30, filled = static_cast<int>(width * done_ / total_);
    std::fprintf(stderr, "%s[%s%s] %zu/%zu %5.0f s  %-60.60s%s", tty_ ? "\r" : "", std::string(filled, '#').c_str(),
                 std::string(width - filled, '.').c_str(), done_, total_, elapsed, what.c_str(), tty_ ? "" : "\n");
    std::fflush(stderr);
  }
  void finish() {
    if (tty_) std::fputc('\n', stderr);
  }

 private:
  size_t total_, done_ = 0;
  bool tty_;
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
};

std::string machine() {
  std::ifstream cpu("/proc/cpuinfo");
  std::string line, model = "unknown CPU";
  while (std::getline(cpu, line))
    if (line.rfind("model name", 0) == 0) {
      model = line.substr(line.find(':') + 2);
      break;
    }
  return model + ", " + std::to_string(sysconf(_SC_NPROCESSORS_ONLN)) + " logical CPUs (one used)";
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"ladder-tradeoff: the speed/accuracy study. For each knob setting (integrator and time step, solver, "
               "tolerance, stabilisation, sub-steps, the adaptive step, accuracy presets, and the 3-D model of the "
               "free chains) on the reference scenes, measures the cost "
               "and the error against a converged reference, and writes tradeoff.csv, tradeoff.md and tradeoff.png "
               "to the output directory."};
  Options o;
  o.scenes_dir = LADDER_SOURCE_DIR "/config/scenes";
  std::string out = "docs/tradeoff";
  app.add_option("--out", out, "output directory (created if missing)")->capture_default_str();
  app.add_option("--scenes-dir", o.scenes_dir, "where the shipped scene files are")->capture_default_str();
  app.add_option("--only", o.cases, "scenes to study: free2, free100, classic, long (default all)")->delimiter(',');
  app.add_flag("--quick", o.quick, "a small study of the free chain N = 2 (seconds; used by the tests)");
  app.add_option("--min-timing", o.min_timing, "repeat runs shorter than this [s] and keep the fastest")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
  CLI11_PARSE(app, argc, argv);

  try {
    std::filesystem::create_directories(out);
    const auto start = std::chrono::steady_clock::now();
    std::vector<CaseReport> reports;
    size_t total = 0;
    for (const Case& c : cases(o)) total += settings(c, o).size() + 2;
    Progress progress(total);
    for (const Case& c : cases(o)) {
      // Each line names the run starting now.
      progress.next(c.id + ": reference, RK4 at " + std::to_string(c.reference_dt * 1e3) + " ms");
      progress.next(c.id + ": reference, RK4 at half that (the halving check)");
      CaseReport report{c, reference(c, o), {}};
      for (const Setting& s : settings(c, o)) {
        progress.next(c.id + ": " + s.knob + " " + s.label);
        report.results.push_back(run(c, s, o, &report.reference));
      }
      mark_pareto(report.results);
      reports.push_back(std::move(report));
    }
    progress.finish();
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    std::string command = "ladder-tradeoff";
    for (int i = 1; i < argc; ++i) command += std::string(" ") + argv[i];
    write_csv(out + "/tradeoff.csv", reports);
    write_markdown(out + "/tradeoff.md", reports, command, machine(), wall);
    write_plot(out + "/tradeoff.png", reports);
    std::cout << "wrote " << out << "/tradeoff.csv, tradeoff.md and tradeoff.png (" << static_cast<int>(wall)
              << " s)\n";
  } catch (const std::exception& e) {
    std::cerr << "ladder-tradeoff: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
