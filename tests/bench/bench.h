#pragma once
// Shared pieces of ave-bench subcommands: a subcommand adds its options to its CLI11 app and
// returns the function that runs it (after parsing).
#include <functional>

#include <CLI/CLI.hpp>

namespace ave::bench {

using Runner = std::function<int()>;

// `ave-bench sim`: simulated campus camera video, per-stage cost (sim_bench.cc).
Runner AddSimBench(CLI::App& sub);

// Pins the process to one CPU and keeps OpenCV single-threaded, so figures are per core.
void UseOneCore();

}  // namespace ave::bench
