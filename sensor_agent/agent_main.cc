// ave-agent: a sensor node. Captures frames from a source and streams them to ave-server.
//   ave-agent --camera cam1 --source sim:campus#cam1 --server 127.0.0.1:50051 --token T
#include <csignal>
#include <cstdlib>
#include <iostream>
#include <sstream>
#include <thread>

#include "model_store/common/cli.h"
#include "model_store/common/log.h"
#include "sensor_agent/stream/agent_streamer.h"

namespace {

std::atomic<bool> g_stop{false};

void OnSignal(int) { g_stop = true; }

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
  app.add_option("--camera", options.camera_id, "this camera's registered id")->required();
  app.add_option("--token", options.token, "sensor bearer token (env AVE_SENSOR_TOKEN)");
  app.add_option("--source", source_spec, "sim:campus#ID, file:PATH, rtsp://..., v4l2:/dev/videoN")->required();
  app.add_option("--fps", options.fps, "frames per second to send")->capture_default_str()->check(CLI::Range(0.1, 240.0));
  app.add_option("--jpeg-quality", options.jpeg_quality, "JPEG quality 1..100")->capture_default_str()->check(CLI::Range(1, 100));
  app.add_option("--max-frames", options.max_frames, "stop after N frames (0 = never)")->capture_default_str();
  app.add_option("--duration", options.duration_s, "stop after S seconds (0 = never)")->capture_default_str();
  app.add_option("--tls-ca", options.tls.ca_file, "PEM CA of the server certificate: use TLS (env AVE_TLS_CA)");
  app.add_option("--tls-cert", options.tls.cert_file, "PEM client certificate of this sensor node (mutual TLS)");
  app.add_option("--tls-key", options.tls.key_file, "PEM client key of this sensor node (mutual TLS)");
  app.add_option("--tls-server-name", options.tls.server_name, "name the server certificate carries, if not the host dialled");
  app.add_option("--spill", options.spill_path,
                 "file for metadata buffered during long outages (default: temp dir; '-' = memory only)");
  app.add_option("--metadata-buffer", options.metadata_in_memory, "metadata records kept in memory during an outage")
      ->capture_default_str()->check(CLI::Range(1, 1 << 24));
  app.add_option("--position", position, "mounting position x,y,z (m, site frame) for sources without a pose");
  app.add_option("--look-at", look_at, "point x,y,z the mounted camera looks at");
  app.add_option("--fov", fov_deg, "horizontal field of view (deg) for sources without intrinsics")->capture_default_str();
  if (auto exit_code = ave::cli::Parse(app, argc, argv, "ave-agent")) return *exit_code;
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
  auto source = ave::OpenSource(source_spec, {.fps = options.fps, .default_fov_deg = fov_deg});
  if (!source.ok()) {
    std::cerr << "ave-agent: " << source.status().message() << "\n";
    return 1;
  }
  std::signal(SIGINT, OnSignal);
  std::signal(SIGTERM, OnSignal);
  AVE_LOG(INFO) << "camera '" << options.camera_id << "': streaming " << (*source)->description() << " to "
                << options.server << " at " << options.fps << " fps";
  ave::AgentStreamer streamer(options, std::move(*source));
  const absl::Status status = streamer.Run(g_stop);
  const ave::AgentStats s = streamer.stats();
  std::cout << "{\"camera\":\"" << options.camera_id << "\",\"frames_sent\":" << s.frames_sent
            << ",\"frames_acked\":" << s.frames_acked << ",\"connects\":" << s.connects
            << ",\"bytes_sent\":" << s.bytes_sent << ",\"metadata_buffered\":" << s.metadata_buffered
            << ",\"metadata_replayed\":" << s.metadata_replayed << ",\"metadata_dropped\":" << s.metadata_dropped
            << ",\"clock_offset_ms\":" << s.clock_offset_ns / 1e6 << "}" << std::endl;
  if (!status.ok()) {
    std::cerr << "ave-agent: " << status.message() << "\n";
    return 1;
  }
  return 0;
}
