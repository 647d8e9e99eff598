#pragma once
// The viewer application: connects to the server, renders the quad view (a free browse view plus
// three views locked to chosen cameras, AVE §8) in a window or headless, and writes snapshots.
#include <array>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "absl/status/status.h"
#include "viewer_client/client/scene_client.h"
#include "viewer_client/render/renderer.h"

namespace ave::viewer {

struct ViewerOptions {
  // Fusion servers (host:port); cameras of all are merged (the static model comes from the first).
  std::vector<std::string> servers = {"127.0.0.1:50051"};
  std::string token;  // viewer bearer token
  std::string viewer_id = "ave-viewer";
  bool headless = false;
  std::string snapshot_path;  // PNG written after the headless render, or on 'p' / close in a window
  std::string depth_path;     // OpenEXR of the browse view's linear depth (metres), with the snapshot
  std::string record_dir;     // a PNG per frame drawn: DIR/frame_000000.png, ...
  int width = 1280, height = 720;
  std::string layout = "quad";               // "quad" or "browse" (browse view only)
  std::vector<std::string> locked_cameras;   // up to 3 for the locked views; default: the first by id
  std::vector<std::string> camera_filter;    // subscribe to these only (empty = all)
  std::string selected_camera;               // highlighted in every view from the start
  int wait_cameras = 0;                      // headless: wait until this many cameras have frames (0: all locked)
  double timeout_s = 30;                     // headless: give up waiting after this long
  float max_rate_hz = 30;
  Eigen::Vector3d eye = Eigen::Vector3d(-150, -170, 130);  // browse view, local frame (m)
  Eigen::Vector3d target = Eigen::Vector3d(0, 0, 0);
  double browse_fov_deg = 55;
  bool draw_frustums = true;
  bool panel = true;        // the on-screen panel and annotations (ImGui)
  bool select_data = true;  // data selection: frames only of cameras whose frustum meets a view
  bool lidar_points = true;  // the LiDAR point layer (key n) at start; off: no points subscribed
  bool avatars = true;       // people as avatars (key v) at start, where the server assigns them
  // The privacy export (issue 17): every person drawn as its avatar with its own texture and no
  // projected video on people; a person without an avatar ends the run with an error.
  bool avatars_only = false;
  int max_frames = 0;  // window: close after this many frames (0 = until the user closes it); headless: frames to draw (0 = 1)
  // TLS to the server (issue 8): PEM CA of the server certificate (empty = plaintext), and an
  // optional client certificate and key for mutual TLS.
  std::string tls_ca, tls_cert, tls_key, tls_server_name;
  bool insecure_plaintext = false;  // send the token in plaintext to non-loopback servers (issue 14)
  // Replay (issue 18): show the recorded interval [from, to) (server clock, ns since the Unix
  // epoch) at replay_rate instead of the live scene; headless, frames are drawn until it ends.
  int64_t replay_from_ns = 0, replay_to_ns = 0;
  float replay_rate = 1;
  // Headless replay: the frames drawn also as a Motion-JPEG video (.mkv or .avi) at the recorded
  // timing, video_fps frames per recorded second (replay_video.h).
  std::string video_path;
  double video_fps = 10;

  std::string Check() const;
};

// Runs until the window closes (window mode) or after one snapshot (headless).
absl::Status RunViewer(const ViewerOptions& options);

// Building blocks, shared with tests.
// Projectors for the cameras that have a frame; images are referenced, not copied, so `cameras`
// must outlive the call to Renderer::SetProjectors.
std::vector<Projector> MakeProjectors(const std::vector<CameraView>& cameras);
// A perspective view from `eye` towards `target` filling `viewport`.
View BrowseView(const Viewport& viewport, const Eigen::Vector3d& eye, const Eigen::Vector3d& target, double fov_deg);
// The quad layout: browse view top-left, then views locked to `locked` (ids of projectors).
std::vector<View> QuadViews(int width, int height, const View& browse, const std::vector<Projector>& projectors,
                            const std::vector<std::string>& locked);
// The locked views' cameras while the operator has not chosen them (no --lock, no lock button
// pressed): a cell showing a camera keeps it, and an empty cell takes the first camera by id that no
// other cell shows. A viewer started before every camera has reported so fills its cells as the
// cameras come, instead of leaving plan views for good. `camera_ids`: sorted by id.
std::array<std::string, 3> FillLockedViews(std::array<std::string, 3> locked, const std::vector<std::string>& camera_ids);
// The frusta the server should select cameras by: every view's clip-from-local matrix.
SelectionViews SelectionOf(const std::vector<View>& views);
// Every LiDAR's newest sweep of people points in one cloud for Renderer::SetPointCloud, coloured by
// track id (IdColor: a person keeps its colour from sweep to sweep; grey for unassigned points).
PointCloud LidarPointsByTrack(const std::vector<LidarView>& lidars);
// Writes RGBA8 rows-top-first pixels as a PNG.
absl::Status WritePng(const std::string& path, const std::vector<uint8_t>& rgba, int width, int height);

}  // namespace ave::viewer
