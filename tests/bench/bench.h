#pragma once
// Shared pieces of ave-bench subcommands: a subcommand adds its options to its CLI11 app and
// returns the function that runs it (after parsing).
#include <cmath>
#include <cstdio>
#include <functional>
#include <string>

#include <CLI/CLI.hpp>

#include "model_store/common/cli.h"

namespace ave::bench {

// A number for a JSON summary line ("%.3f"), or null where it was not measured (NaN, inf).
inline std::string JsonNumber(double v) {
  if (!std::isfinite(v)) return "null";
  char text[64];
  std::snprintf(text, sizeof(text), "%.3f", v);
  return text;
}

using Runner = std::function<int()>;

// `ave-bench sim`: simulated campus camera video, per-stage cost (sim_bench.cc).
Runner AddSimBench(CLI::App& sub);

// `ave-bench pose`: backpack-camera misregistration per pose mode vs time per frame (pose_bench.cc).
Runner AddPoseBench(CLI::App& sub);

// `ave-bench detect`: detection/tracking accuracy per background model vs fps, next to MOG2 (detect_bench.cc).
Runner AddDetectBench(CLI::App& sub);

// `ave-bench render`: quad-view frame time vs projected cameras and shadow-map size, visibility
// error vs ray-cast truth (render_bench.cc).
Runner AddRenderBench(CLI::App& sub);

// `ave-bench model` (issue 4): static model from airborne LiDAR, accuracy vs resolution, filter and cost.
Runner AddModelBench(CLI::App& sub);

// `ave-bench select` (issue 7): data selection, streams and bytes a viewer receives with its view
// frusta vs without, next to ray-cast truth; server cost of the frustum test (select_bench.cc).
Runner AddSelectBench(CLI::App& sub);

// `ave-bench environment` (issue 4): i4D environment from a rotating LiDAR, time per stage vs
// frames accumulated, wall/vegetation accuracy, RANSAC and HoughLinesP peers (environment_bench.cc).
Runner AddEnvironmentBench(CLI::App& sub);

// `ave-bench lidar-decode` (issue 16): Velodyne pcap source sweeps/s, points/s and realtime factor
// on the simulator's HDL-64E capture, libpcap reading next to our reader, RSS over a long replay
// (lidar_decode_bench.cc).
Runner AddLidarDecodeBench(CLI::App& sub);

// `ave-bench lidar` (issue 16): LiDAR people detection and tracking vs simulator truth, per chain
// configuration vs ms per sweep, next to OpenCV MOG2 on the range image (lidar_bench.cc).
Runner AddLidarBench(CLI::App& sub);

// `ave-bench lidar-wire` (issue 16): a rotating LiDAR's stream (tracks, labelled points) in bytes
// and server time, next to a camera frame of the same scene (lidar_wire_bench.cc).
Runner AddLidarWireBench(CLI::App& sub);

// `ave-bench studio` (issue 17): 4D studio reconstruction vs the simulator's truth: silhouette,
// volume IoU, Chamfer, texture error per voxel size vs ms per frame set, VTK and flat-carving peers
// (studio_bench.cc).
Runner AddStudioBench(CLI::App& sub);
// `ave-bench record` (issue 18): server CPU with recording on vs off under ave-loadgen's load, MB/s
// written, recorder drops, seek and replay start-up latency, index bytes per hour (record_bench.cc).
Runner AddRecordBench(CLI::App& sub);
// `ave-bench avatars` (issue 17): viewer ms per frame for 0..100 walking avatars, cylinders as the
// peer, PNG of the largest count, JSON with viewer_ms_per_100_avatars (avatar_bench.cc).
Runner AddAvatarBench(CLI::App& sub);
// ave-bench avatars' measurement of 0 and 100 walking people as avatars at 1280x720 (three campus
// cameras projecting, the procedural walker, `frames` timed frames each, no cylinder peer, no
// PNG), for other benches' summaries (ave-bench studio): wall and CPU ms per frame; error set
// (and the figures NaN) when no context or renderer could be made.
struct ViewerAvatarCost {
  double ms_0 = std::nan(""), ms_100 = std::nan(""), cpu_ms_0 = std::nan(""), cpu_ms_100 = std::nan("");
  std::string sequence;  // the avatar sequence's name
  std::string error;
};
ViewerAvatarCost MeasureViewerAvatarCost(int frames);

// Pins the process to one CPU and keeps OpenCV single-threaded, so figures are per core.
void UseOneCore();

}  // namespace ave::bench
