// ave-agent: a sensor node. Captures frames from a source and streams them to ave-server.
//   ave-agent --camera cam1 --source sim:campus#cam1 --server 127.0.0.1:50051 --token T
#include <chrono>
#include <csignal>
#include <sys/resource.h>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <sstream>
#include <thread>

#include "model_store/common/cli.h"
#include "model_store/common/log.h"
#include "sensor_agent/detect/detect_run.h"
#include "sensor_agent/lidar/lidar_detect_only.h"
#include "sensor_agent/lidar/lidar_source.h"
#include "sensor_agent/lidar_track/people_tracker.h"
#include "sensor_agent/stream/lidar_streamer.h"
#include "model_store/scene/intrinsics_file.h"
#include "sensor_agent/pose/pose_source.h"
#include "sensor_agent/stream/agent_streamer.h"

namespace {

std::atomic<bool> g_stop{false};

void OnSignal(int) { g_stop = true; }

// --detect-only: detection and tracking on the source without a server (issue 6).
int RunDetectOnly(const std::string& source_spec, const ave::AgentOptions& options, double fov_deg,
                  const ave::detect::DetectorOptions& detector_options, const std::string& tracks_out,
                  double latency_s) {
  if (tracks_out.empty()) {
    std::cerr << "ave-agent: --detect-only needs --out FILE (or '-')\n";
    return 2;
  }
  auto source = ave::OpenSource(source_spec, {.fps = options.fps, .default_fov_deg = fov_deg});
  if (!source.ok()) {
    std::cerr << "ave-agent: " << source.status().message() << "\n";
    return 1;
  }
  std::ofstream file;
  if (tracks_out != "-") {
    file.open(tracks_out);
    if (!file) {
      std::cerr << "ave-agent: cannot write --out " << tracks_out << "\n";
      return 1;
    }
  }
  std::ostream& out = tracks_out == "-" ? std::cout : file;
  auto summary = ave::detect::RunDetectOnly(**source, detector_options, out, options.max_frames, latency_s);
  if (!summary.ok()) {
    std::cerr << "ave-agent: " << summary.status().message() << "\n";
    return 1;
  }
  std::cout << summary->ToJson() << std::endl;
  return 0;
}

// ---- LiDAR mode (issue 16): --source pcap:FILE, udp:[ADDR:]PORT or sim:SCENARIO#LIDAR ----

// The one place where ave-agent's SweepTracker is constructed: the LiDAR people tracker
// (sensor_agent/lidar_track, i4D §3.1-3.2) with its default options (docs/LIDAR.md).
ave::lidar::SweepTracker MakeSweepTracker() { return ave::lidar_track::MakeSweepTracker(); }

// Streams a LiDAR's foot tracks (and its people's points) to the server (issue 16).
int StreamLidarSource(std::unique_ptr<ave::lidar::LidarSource> source, const ave::AgentOptions& options,
                      bool send_points, uint32_t max_points) {
  if (options.camera_id.empty()) {
    std::cerr << "ave-agent: --camera is required (the LiDAR's registered id) unless --detect-only\n";
    return 2;
  }
  ave::LidarStreamOptions l;
  l.server = options.server;
  l.sensor_id = options.camera_id;
  l.token = options.token;
  l.tls = options.tls;
  l.max_sweeps = options.max_frames;
  l.duration_s = options.duration_s;
  // A replay or the simulator delivers sweeps as fast as asked: pace them at the sensor's spin
  // rate and stamp them on arrival (their own times are a file's or a scenario's).
  l.stamp_on_arrival = !source->live();
  l.pace_hz = source->live() ? 0 : source->rate_hz();
  l.send_points = send_points;
  l.max_points = max_points;
  if (const std::string bad = l.Check(); !bad.empty()) {
    std::cerr << "ave-agent: " << bad << "\n";
    return 2;
  }
  ave::lidar::LidarSource* raw = source.get();
  ave::LidarStreamer streamer(l, [raw] { return raw->Next(); }, MakeSweepTracker());
  const absl::Status status = streamer.Run(g_stop);
  const ave::LidarStreamStats st = streamer.stats();
  std::cout << "{\"sensor\":\"" << l.sensor_id << "\",\"sweeps_read\":" << st.sweeps_read << ",\"sweeps_sent\":" << st.sweeps_sent
            << ",\"sweeps_acked\":" << st.sweeps_acked << ",\"tracks_sent\":" << st.tracks_sent << ",\"points_sent\":"
            << st.points_sent << ",\"connects\":" << st.connects << "}" << std::endl;
  if (!status.ok()) {
    std::cerr << "ave-agent: " << status.message() << "\n";
    return 1;
  }
  return 0;
}

int RunLidarMode(const std::string& source_spec, bool detect_only, const std::string& tracks_out,
                 const std::string& calibration_file, const ave::AgentOptions& options, bool send_points,
                 uint32_t max_points) {
  if (!detect_only) {
    ave::lidar::KeepSweepBuffersInProcess();
    auto source = ave::lidar::OpenLidarSource(source_spec, {.calibration_file = calibration_file});
    if (!source.ok()) {
      std::cerr << "ave-agent: " << source.status().message() << "\n";
      return 1;
    }
    return StreamLidarSource(std::move(*source), options, send_points, max_points);
  }
  const int64_t max_sweeps = options.max_frames;
  if (tracks_out.empty()) {
    std::cerr << "ave-agent: --detect-only needs --out FILE (or '-')\n";
    return 2;
  }
  ave::lidar::KeepSweepBuffersInProcess();
  auto source = ave::lidar::OpenLidarSource(source_spec, {.calibration_file = calibration_file});
  if (!source.ok()) {
    std::cerr << "ave-agent: " << source.status().message() << "\n";
    return 1;
  }
  const ave::lidar::SweepTracker tracker = MakeSweepTracker();
  if (!tracker) {
    std::cerr << "ave-agent: " << (*source)->description()
              << ": the LiDAR people tracker (sensor_agent/lidar_track) is not built into ave-agent yet\n";
    return 2;
  }
  std::ofstream file;
  if (tracks_out != "-") {
    file.open(tracks_out);
    if (!file) {
      std::cerr << "ave-agent: cannot write --out " << tracks_out << "\n";
      return 1;
    }
  }
  std::ostream& out = tracks_out == "-" ? std::cout : file;
  auto summary = ave::lidar::RunLidarDetectOnly(**source, tracker, out, max_sweeps);
  if (!summary.ok()) {
    std::cerr << "ave-agent: " << summary.status().message() << "\n";
    return 1;
  }
  std::cout << summary->ToJson() << std::endl;
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  ave::AgentOptions options;
  if (const char* t = std::getenv("AVE_SENSOR_TOKEN")) options.token = t;
  if (const char* ca = std::getenv("AVE_TLS_CA")) options.tls.ca_file = ca;
  std::string source_spec;
  std::string position, look_at;
  double fov_deg = 60;
  CLI::App app{"ave-agent: AVE sensor agent (capture, JPEG, pose, stream to the fusion server)"};
  app.add_option("--server", options.server, "fusion server host:port")->capture_default_str();
  app.add_option("--camera", options.camera_id, "this camera's registered id (required unless --detect-only)");
  app.add_option("--token", options.token, "sensor bearer token (env AVE_SENSOR_TOKEN)");
  app.add_option("--source", source_spec,
                 "sim:campus#ID, file:PATH, rtsp://..., v4l2:/dev/videoN; LiDAR: pcap:FILE, udp:[ADDR:]PORT, sim:SCENARIO#LIDAR")
      ->required();
  std::string lidar_calibration;
  app.add_option("--calibration", lidar_calibration, "LiDAR sources: Velodyne db.xml or ROS velodyne YAML (default: the model's built-in)");
  bool no_lidar_points = false;
  app.add_flag("--no-lidar-points", no_lidar_points, "LiDAR sources: stream foot tracks only, not the people's points");
  uint32_t lidar_max_points = 2048;
  app.add_option("--lidar-max-points", lidar_max_points, "LiDAR sources: at most this many people points a sweep (thinned evenly)")
      ->capture_default_str()->check(ave::cli::Range(1, 65535));
  app.add_option("--fps", options.fps, "frames per second to send")->capture_default_str()->check(ave::cli::Range(0.1, 240.0));
  int64_t pace_max_lag_ms = options.pace_max_lag.count();
  app.add_option("--pace-max-lag", pace_max_lag_ms,
                 "ms a paced source (sim, file) may run behind its frame schedule and catch up (0: a late frame restarts it)")
      ->capture_default_str()->check(ave::cli::Range(0, 10000));
  app.add_option("--jpeg-quality", options.jpeg_quality, "JPEG quality 1..100")->capture_default_str()->check(ave::cli::Range(1, 100));
  app.add_option("--max-frames", options.max_frames, "stop after N frames (0 = never)")->capture_default_str();
  app.add_option("--duration", options.duration_s, "stop after S seconds (0 = never)")->capture_default_str();
  app.add_option("--tls-ca", options.tls.ca_file, "PEM CA of the server certificate: use TLS (env AVE_TLS_CA)");
  app.add_option("--tls-cert", options.tls.cert_file, "PEM client certificate of this sensor node (mutual TLS)");
  app.add_option("--tls-key", options.tls.key_file, "PEM client key of this sensor node (mutual TLS)");
  app.add_option("--tls-server-name", options.tls.server_name, "name the server certificate carries, if not the host dialled");
  app.add_flag("--insecure-plaintext", options.tls.insecure_plaintext,
               "send the sensor token in plaintext to a non-loopback server (without --tls-ca)");
  app.add_option("--spill", options.spill_path,
                 "file for metadata buffered during long outages (default: temp dir; '-' = memory only)")->check(ave::cli::WritableFile());
  app.add_option("--metadata-buffer", options.metadata_in_memory, "metadata records kept in memory during an outage")
      ->capture_default_str()->check(ave::cli::Range(1, 1 << 24));
  app.add_option("--position", position, "mounting position x,y,z (m, site frame) for sources without a pose");
  app.add_option("--look-at", look_at, "point x,y,z the mounted camera looks at");
  app.add_option("--fov", fov_deg, "horizontal field of view (deg) for sources without intrinsics")->capture_default_str();
  std::string sim_footage;
  app.add_option("--sim-footage", sim_footage,
                 "sim sources: play this pre-rendered footage file (ave-sim footage) instead of rendering, while it lasts");
  std::string pose_mode = "truth", pose_log, intrinsics_file;
  app.add_option("--pose-mode", pose_mode, "pose of sim sources: truth, gps-imu or gps-imu-vision (fused, with covariance)")
      ->capture_default_str()->check(CLI::IsMember({"truth", "gps-imu", "gps-imu-vision"}));
  app.add_option("--pose-log", pose_log, "DIR with gps.csv and imu.csv for --pose-mode (default: simulated)");
  double carrier_height_m = -1;
  app.add_option("--carrier-height", carrier_height_m,
                 "gps-imu-vision: the carried camera's height above the ground in m (-1: a walking sim camera's own, 0: none)")
      ->capture_default_str()->check(ave::cli::Range(-1.0, 100.0));
  app.add_option("--intrinsics", intrinsics_file, "intrinsics YAML (ave-calibrate --out) for sources without intrinsics");
  bool detect = false, detect_only = false;
  std::string tracks_out, background = "average";
  app.add_flag("--detect", detect, "detect and track moving objects; their boxes go with each frame");
  app.add_flag("--detect-only", detect_only, "detect and track without a server: one JSON per frame to --out");
  app.add_option("--out", tracks_out, "--detect-only: tracks file, one JSON object per frame ('-' = stdout)")->check(ave::cli::WritableFile());
  app.add_option("--background", background, "background model: average, gaussian or mixture")
      ->capture_default_str()->check(CLI::IsMember({"average", "gaussian", "mixture"}));
  // Offline files need no live output: by default --detect-only holds each record for the
  // validation time, so every frame of a track's validation second gets its box (near-online).
  double latency_s = -1;
  app.add_option("--latency", latency_s,
                 "--detect-only: hold each frame's record S seconds (source time) and write back the boxes of tracks "
                 "validated meanwhile (default: the validation time, 1 s; 0 = live output)")
      ->check(ave::cli::Range(0.0, 3600.0));
  if (auto exit_code = ave::cli::Parse(app, argc, argv, "ave-agent")) return *exit_code;
  // A scenario knows whether an id names a camera or a rotating LiDAR; pcap: and udp: are LiDAR.
  absl::StatusOr<bool> lidar = ave::lidar::IsLidarSourceSpec(source_spec);
  if (lidar.ok() && *lidar) {
    return RunLidarMode(source_spec, detect_only, tracks_out, lidar_calibration, options, !no_lidar_points, lidar_max_points);
  }
  ave::detect::DetectorOptions detector_options;
  ave::detect::ParseBackgroundKind(background, detector_options.background);
  if (detect_only) {
    return RunDetectOnly(source_spec, options, fov_deg, detector_options, tracks_out,
                         latency_s < 0 ? detector_options.tracker.validate_s : latency_s);
  }
  options.pace_max_lag = std::chrono::milliseconds(pace_max_lag_ms);
  if (options.camera_id.empty()) {
    std::cerr << "ave-agent: --camera is required (unless --detect-only)\n";
    return 2;
  }
  if (detect) {
    auto detector = std::make_shared<ave::detect::Detector>(detector_options);
    options.detector = [detector](const ave::CapturedFrame& frame) {
      std::vector<ave::FrameBox> boxes;
      for (const auto& d : detector->Process(frame.bgr.data(), frame.width, frame.height, frame.scene_time_s)) {
        boxes.push_back({d.track_id, d.corners, d.score});
      }
      return boxes;
    };
  }
  if (position.empty() != look_at.empty()) {
    std::cerr << "ave-agent: --position and --look-at go together\n";
    return 2;
  }
  if (!position.empty()) {
    Eigen::Vector3d eye, target;
    if (!ave::cli::ParseVec3(position, eye) || !ave::cli::ParseVec3(look_at, target)) {
      std::cerr << "ave-agent: --position/--look-at must be x,y,z\n";
      return 2;
    }
    options.mounting_pose = ave::LookAt(eye, target);
  }
  if (const std::string why = options.Check(); !why.empty()) {
    std::cerr << "ave-agent: " << why << "\n";
    return 2;
  }
  // Streaming: a simulated camera renders its next frame while this one is processed and sent.
  ave::SourceOptions source_options{.fps = options.fps, .default_fov_deg = fov_deg, .sim_render_ahead = true, .sim_footage = sim_footage};
  if (!intrinsics_file.empty()) {
    auto intrinsics = ave::calib::ReadIntrinsicsFile(intrinsics_file);
    if (!intrinsics.ok()) {
      std::cerr << "ave-agent: --intrinsics: " << intrinsics.status().message() << "\n";
      return 2;
    }
    source_options.intrinsics = *intrinsics;
  }
  auto source = ave::OpenSource(source_spec, source_options);
  if (source.ok()) {
    source = ave::pose::WithFusedPose(std::move(*source), source_spec,
                                      {.mode = *ave::pose::ParsePoseMode(pose_mode), .log_dir = pose_log, .carrier_height_m = carrier_height_m});
  }
  if (!source.ok()) {
    std::cerr << "ave-agent: " << source.status().message() << "\n";
    return 1;
  }
  std::signal(SIGINT, OnSignal);
  std::signal(SIGTERM, OnSignal);
  AVE_LOG(INFO) << "camera '" << options.camera_id << "': streaming " << (*source)->description() << " to "
                << options.server << " at " << options.fps << " fps";
  ave::AgentStreamer streamer(options, std::move(*source));
  // Process CPU time (every thread: the render-ahead camera, encoding, pose) per frame sent.
  auto cpu_s = [] {
    rusage u{};
    getrusage(RUSAGE_SELF, &u);
    return u.ru_utime.tv_sec + u.ru_stime.tv_sec + 1e-6 * (u.ru_utime.tv_usec + u.ru_stime.tv_usec);
  };
  const double cpu_start = cpu_s();
  const auto run_start = std::chrono::steady_clock::now();
  const absl::Status status = streamer.Run(g_stop);
  const double run_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - run_start).count();
  const double run_cpu_s = cpu_s() - cpu_start;
  const ave::AgentStats s = streamer.stats();
  std::cout << "{\"camera\":\"" << options.camera_id << "\",\"frames_sent\":" << s.frames_sent
            << ",\"frames_acked\":" << s.frames_acked << ",\"connects\":" << s.connects
            << ",\"bytes_sent\":" << s.bytes_sent << ",\"metadata_buffered\":" << s.metadata_buffered
            << ",\"metadata_replayed\":" << s.metadata_replayed << ",\"metadata_dropped\":" << s.metadata_dropped
            << ",\"clock_offset_ms\":" << s.clock_offset_ns / 1e6 << ",\"source_outages\":" << s.source_outages
            << ",\"source_errors\":" << s.source_errors << ",\"source_down_s\":" << s.source_down_s
            << ",\"source_drop_outs\":" << s.source_drop_outs << ",\"source_reconnects\":" << s.source_reconnects
            << ",\"seconds\":" << run_s << ",\"frames_per_s\":" << (run_s > 0 ? s.frames_sent / run_s : 0.0)
            << ",\"cpu_ms_per_frame\":" << (s.frames_sent > 0 ? 1e3 * run_cpu_s / s.frames_sent : 0.0) << "}" << std::endl;
  if (!status.ok()) {
    std::cerr << "ave-agent: " << status.message() << "\n";
    return 1;
  }
  return 0;
}
