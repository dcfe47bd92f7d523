// The study's outputs: a CSV of every run, a Markdown report and a PNG plot of error against cost.
#pragma once

#include "study.hpp"

#include <string>
#include <vector>

namespace ladder::tradeoff {

struct CaseReport {
  Case scene;
  Reference reference;
  std::vector<Result> results;
};

void write_csv(const std::string& path, const std::vector<CaseReport>& reports);
void write_markdown(const std::string& path, const std::vector<CaseReport>& reports, const std::string& command,
                    const std::string& machine, double wall_seconds);
// One log-log panel per scene: max block-angle error [rad] against wall time per simulated second, one line per
// knob, the Pareto front marked. Throws std::runtime_error if the file cannot be written.
void write_plot(const std::string& path, const std::vector<CaseReport>& reports);

}  // namespace ladder::tradeoff
