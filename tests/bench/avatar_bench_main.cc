// ave-bench-avatars: `ave-bench avatars` (avatar_bench.cc) as a program of its own, linked with
// the renderer, the scene and OpenCV only, so that it can run on a machine with a GPU but without
// the server's libraries (gRPC, PCL, VTK): the figures of BENCHMARKS.md "Avatars in the viewer"
// on a hardware OpenGL driver next to llvmpipe. Same options and output as `ave-bench avatars`.
#include <CLI/CLI.hpp>

#include "tests/bench/bench.h"

int main(int argc, char** argv) {
  CLI::App app{"ave-bench-avatars: what walking avatars cost the viewer (ave-bench avatars alone)"};
  const ave::bench::Runner run = ave::bench::AddAvatarBench(app);
  if (auto exit_code = ave::cli::Parse(app, argc, argv, "ave-bench-avatars")) return *exit_code;
  return run();
}
