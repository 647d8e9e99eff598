// ave-bench: cost benchmarks, one subcommand each (docs/BENCHMARKS.md).
//   ave-bench sim [--scenario campus --camera cam1 --seconds 10 --fps 15]
// Later issues add subcommands (pose, detect, render ...) by writing <name>_bench.cc with an
// Add<Name>Bench(CLI::App&) and registering it below.
#include <map>
#include <string>

#include "model_store/common/cli.h"
#include "tests/bench/bench.h"

int main(int argc, char** argv) {
  CLI::App app{"ave-bench: what realism and accuracy cost in time (docs/BENCHMARKS.md)"};
  app.require_subcommand(1);
  std::map<std::string, ave::bench::Runner> runners;
  runners["sim"] = ave::bench::AddSimBench(*app.add_subcommand("sim", "simulated camera video: time per stage and effect vs real time"));
  if (auto exit_code = ave::cli::Parse(app, argc, argv, "ave-bench")) return *exit_code;
  for (auto& [name, run] : runners) {
    if (app.got_subcommand(name)) return run();
  }
  return 2;
}
