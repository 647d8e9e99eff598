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
  runners["pose"] = ave::bench::AddPoseBench(*app.add_subcommand("pose", "camera pose: misregistration in px per mode vs ms per frame"));
  runners["detect"] = ave::bench::AddDetectBench(*app.add_subcommand("detect", "moving objects: MOTA, 3D error per background model vs fps, next to MOG2"));
  runners["render"] = ave::bench::AddRenderBench(*app.add_subcommand("render", "renderer: quad-view ms per frame vs projected cameras, shadow-map size vs visibility error"));
  runners["model"] = ave::bench::AddModelBench(*app.add_subcommand("model", "static model from LiDAR: terrain/ground/building accuracy vs resolution, filter, time, memory"));
  runners["select"] = ave::bench::AddSelectBench(*app.add_subcommand("select", "data selection: streams and kB/s a viewer receives with its view frusta vs all, server cost"));
  runners["environment"] = ave::bench::AddEnvironmentBench(*app.add_subcommand("environment", "i4D environment from a rotating LiDAR: ms per stage vs frames, wall and vegetation accuracy"));
  runners["lidar-decode"] = ave::bench::AddLidarDecodeBench(*app.add_subcommand("lidar-decode", "Velodyne pcap source: sweeps/s, points/s, realtime factor, libpcap peer, RSS over a long replay"));
  runners["lidar"] = ave::bench::AddLidarBench(*app.add_subcommand("lidar", "LiDAR people tracking: foreground P/R, MOTA, ID switches per chain vs ms per sweep, MOG2 peer"));
  runners["avatars"] = ave::bench::AddAvatarBench(*app.add_subcommand("avatars", "viewer: ms per frame for 0, 1, 10, 100 walking avatars (cylinders as the peer), PNG, viewer_ms_per_100_avatars"));
  runners["lidar-wire"] = ave::bench::AddLidarWireBench(*app.add_subcommand("lidar-wire", "rotating LiDAR stream: bytes and server us per sweep (tracks, points) next to a camera frame"));
  runners["record"] = ave::bench::AddRecordBench(*app.add_subcommand("record", "recording: server CPU with vs without, MB/s, drops, seek and replay start-up latency, index size"));
  runners["studio"] = ave::bench::AddStudioBench(*app.add_subcommand("studio", "4D studio: silhouette and volume IoU, Chamfer, texture error per voxel size vs ms per frame set, peers"));
  if (auto exit_code = ave::cli::Parse(app, argc, argv, "ave-bench")) return *exit_code;
  for (auto& [name, run] : runners) {
    if (app.got_subcommand(name)) return run();
  }
  return 2;
}
