// ave-viewer: the control-room viewer. A window when DISPLAY is set, or --headless to render
// offscreen (EGL) to a PNG / a PNG sequence / an OpenEXR depth image. Keys: see kKeys below.
#include <cstdlib>
#include <iostream>
#include <optional>
#include <sstream>

#include "model_store/common/cli.h"
#include "model_store/common/log.h"
#include "viewer_client/client/viewer_app.h"

namespace {

constexpr char kKeys[] = R"(
Window controls (browse view, top left):
  W/S A/D E/Q   fly forward/back, left/right, up/down (Shift: 4x faster)
  right drag    mouse look (turn the view about the eye)
  left drag     orbit about the pivot (default: the --target point)
  middle click  or 'o': pick the pivot under the cursor (orbit about that point)
  wheel         move towards / away from the pivot
  left click    on a camera's marker in any view: select it (highlighted in every view)
  1-9 / 0       select camera N of the list / clear the selection
  f  frustums   k  paths   l  labels   t  age tint   h  panel
  r             the panel with its Replay section open (drag on its time line to go back)
  p             write --snapshot now;  Esc: quit
The panel (top left) lists the cameras with status (live / stale / lost) and a time line of
frames received; its 1 2 3 buttons lock a camera to the top-right, bottom-left, bottom-right view.
)";

}  // namespace

int main(int argc, char** argv) {
  ave::viewer::ViewerOptions options;
  if (const char* t = std::getenv("AVE_VIEWER_TOKEN")) options.token = t;
  if (const char* ca = std::getenv("AVE_TLS_CA")) options.tls_ca = ca;
  std::string eye, target, size = "1280x720";
  std::vector<std::string> servers;
  CLI::App app{"ave-viewer: AVE control-room viewer (quad view: browse + three camera-locked views)"};
  app.footer(kKeys);
  app.add_option("--server", servers,
                 "fusion server host:port; repeat to subscribe to several (cameras merged; default 127.0.0.1:50051)");
  app.add_option("--token", options.token, "viewer bearer token (env AVE_VIEWER_TOKEN)");
  app.add_option("--tls-ca", options.tls_ca, "PEM CA of the server certificate: use TLS (env AVE_TLS_CA)");
  app.add_option("--tls-cert", options.tls_cert, "PEM client certificate (mutual TLS)");
  app.add_option("--tls-key", options.tls_key, "PEM client key (mutual TLS)");
  app.add_option("--tls-server-name", options.tls_server_name, "name the server certificate carries, if not the host dialled");
  app.add_flag("--insecure-plaintext", options.insecure_plaintext,
               "send the viewer token in plaintext to a non-loopback server (without --tls-ca)");
  app.add_option("--id", options.viewer_id, "this viewer's name in the server log")->capture_default_str();
  app.add_flag("--headless", options.headless, "render offscreen (EGL) and exit");
  app.add_option("--snapshot", options.snapshot_path, "PNG to write (headless: at the end; window: on 'p' and at close)");
  app.add_option("--depth", options.depth_path, "OpenEXR of the browse view's linear depth in metres (with the snapshot)");
  app.add_option("--record", options.record_dir, "write every frame drawn as DIR/frame_NNNNNN.png");
  app.add_option("--size", size, "framebuffer WIDTHxHEIGHT")->capture_default_str();
  app.add_option("--layout", options.layout, "quad or browse")->capture_default_str();
  app.add_option("--lock", options.locked_cameras, "camera ids for the three locked views")->expected(0, 3);
  app.add_option("--cameras", options.camera_filter, "subscribe to these camera ids only");
  app.add_option("--select", options.selected_camera, "camera highlighted in every view from the start");
  app.add_option("--wait-cameras", options.wait_cameras, "headless: cameras with a frame before rendering (0 = 3)");
  app.add_option("--timeout", options.timeout_s, "headless: seconds to wait for frames")->capture_default_str();
  app.add_option("--max-rate", options.max_rate_hz, "updates per second to ask for")->capture_default_str();
  app.add_option("--eye", eye, "browse view eye x,y,z (m, site frame)");
  app.add_option("--target", target, "browse view target x,y,z (the first orbit pivot)");
  app.add_option("--frames", options.max_frames, "window: close after N frames (0 = when closed); headless: draw N frames");
  app.add_flag("!--no-frustums", options.draw_frustums, "do not draw camera frustums");
  app.add_flag("!--no-panel", options.panel, "no on-screen panel or labels");
  app.add_flag("!--no-avatars", options.avatars, "draw people as boxes/cylinders, not avatars (key v toggles)");
  app.add_flag("--avatars-only", options.avatars_only,
               "privacy export: every person as its avatar, no live video projected onto people");
  app.add_flag("!--no-lidar-points", options.lidar_points,
               "start with the LiDAR point layer off (key n; the server then sends no points)");
  app.add_flag("!--no-select", options.select_data,
               "ask for every camera's frames (default: only cameras whose frustum meets a view)");
  std::optional<double> replay_from_s, replay_to_s;
  app.add_option("--replay-from", replay_from_s,
                 "replay the recording from this server time: seconds since the Unix epoch, or <= 0 for "
                 "seconds before now (-60: a minute ago)");
  app.add_option("--replay-to", replay_to_s, "replay until this time (same forms; 0 = now)");
  app.add_option("--replay-rate", options.replay_rate, "replay speed, 0.25 .. 16")->capture_default_str();
  app.add_option("--video", options.video_path,
                 "headless replay: also write the frames drawn as a Motion-JPEG .mkv or .avi at the recorded timing");
  app.add_option("--video-fps", options.video_fps, "--video frames per recorded second")->capture_default_str();
  if (auto exit_code = ave::cli::Parse(app, argc, argv, "ave-viewer")) return *exit_code;
  if (replay_from_s.has_value() != replay_to_s.has_value()) {
    std::cerr << "ave-viewer: --replay-from and --replay-to go together\n";
    return 2;
  }
  if (replay_from_s) {
    const double now_s = ave::NowNs() * 1e-9;
    auto absolute_ns = [&](double s) { return static_cast<int64_t>((s <= 0 ? now_s + s : s) * 1e9); };
    options.replay_from_ns = absolute_ns(*replay_from_s);
    options.replay_to_ns = absolute_ns(*replay_to_s);
  }
  if (!servers.empty()) options.servers = servers;
  if (!eye.empty() && !ave::cli::ParseVec3(eye, options.eye)) {
    std::cerr << "ave-viewer: --eye must be x,y,z\n";
    return 2;
  }
  if (!target.empty() && !ave::cli::ParseVec3(target, options.target)) {
    std::cerr << "ave-viewer: --target must be x,y,z\n";
    return 2;
  }
  char x = 0;
  std::stringstream ss(size);
  if (!(ss >> options.width >> x >> options.height) || x != 'x') {
    std::cerr << "ave-viewer: --size must be WIDTHxHEIGHT\n";
    return 2;
  }
  if (const std::string why = options.Check(); !why.empty()) {
    std::cerr << "ave-viewer: " << why << "\n";
    return 2;
  }
  const absl::Status status = ave::viewer::RunViewer(options);
  if (!status.ok()) {
    std::cerr << "ave-viewer: " << status.message() << "\n";
    return 1;
  }
  return 0;
}
