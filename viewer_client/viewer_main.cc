// ave-viewer: the control-room viewer. A window when DISPLAY is set, or --headless to render once
// to a PNG. Window keys: drag to orbit, wheel to zoom, WASD/QE to move, 1-9 highlight a camera,
// 0 clear, f frustums, p snapshot, Esc quit.
#include <cstdlib>
#include <iostream>
#include <sstream>

#include "model_store/common/cli.h"
#include "viewer_client/client/viewer_app.h"

int main(int argc, char** argv) {
  ave::viewer::ViewerOptions options;
  if (const char* t = std::getenv("AVE_VIEWER_TOKEN")) options.token = t;
  if (const char* ca = std::getenv("AVE_TLS_CA")) options.tls_ca = ca;
  std::string eye, target, size = "1280x720";
  CLI::App app{"ave-viewer: AVE control-room viewer (quad view: browse + three camera-locked views)"};
  app.add_option("--server", options.server, "fusion server host:port")->capture_default_str();
  app.add_option("--token", options.token, "viewer bearer token (env AVE_VIEWER_TOKEN)");
  app.add_option("--tls-ca", options.tls_ca, "PEM CA of the server certificate: use TLS (env AVE_TLS_CA)");
  app.add_option("--tls-cert", options.tls_cert, "PEM client certificate (mutual TLS)");
  app.add_option("--tls-key", options.tls_key, "PEM client key (mutual TLS)");
  app.add_option("--tls-server-name", options.tls_server_name, "name the server certificate carries, if not the host dialled");
  app.add_option("--id", options.viewer_id, "this viewer's name in the server log")->capture_default_str();
  app.add_flag("--headless", options.headless, "render offscreen (EGL) once and exit");
  app.add_option("--snapshot", options.snapshot_path, "PNG to write (headless: required)");
  app.add_option("--size", size, "framebuffer WIDTHxHEIGHT")->capture_default_str();
  app.add_option("--layout", options.layout, "quad or browse")->capture_default_str();
  app.add_option("--lock", options.locked_cameras, "camera ids for the three locked views")->expected(0, 3);
  app.add_option("--cameras", options.camera_filter, "subscribe to these camera ids only");
  app.add_option("--wait-cameras", options.wait_cameras, "headless: cameras with a frame before rendering (0 = 3)");
  app.add_option("--timeout", options.timeout_s, "headless: seconds to wait for frames")->capture_default_str();
  app.add_option("--max-rate", options.max_rate_hz, "updates per second to ask for")->capture_default_str();
  app.add_option("--eye", eye, "browse view eye x,y,z (m, site frame)");
  app.add_option("--target", target, "browse view target x,y,z");
  app.add_option("--frames", options.max_frames, "window: close after N frames (0 = when closed)");
  app.add_flag("!--no-frustums", options.draw_frustums, "do not draw camera frustums");
  if (auto exit_code = ave::cli::Parse(app, argc, argv, "ave-viewer")) return *exit_code;
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
