#pragma once
// The viewer's on-screen layer (issue 7 item 4, AVE §8): a Dear ImGui panel with the camera list
// (status live / stale / lost, lock to a view, select), a time line of the frames received, and
// display toggles; plus annotations drawn into each view (camera names, object ids, paths). It is
// drawn over the rendered views in a window and headless alike, so snapshots show it.
// ImGui and GL stay in overlay.cc.
#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "absl/status/statusor.h"
#include "viewer_client/client/scene_client.h"
#include "viewer_client/render/gl_context.h"
#include "viewer_client/render/renderer.h"

namespace ave::viewer {

// What the user sets through the panel and by picking.
struct OverlayState {
  DisplayOptions display;  // sent to Renderer::SetDisplayOptions when it changes
  bool frustums = true;
  bool paths = true;
  bool annotations = true;
  bool panel = true;
  bool select_data = true;  // data selection: ask the server for frames of cameras in view only
  // The LiDARs' newest sweep of people points, coloured by track (issue 16); the subscription asks
  // for points only while this is on. The toggle shows once a LiDAR is registered.
  bool lidar_points = true;
  // People (kind person) as their server-assigned avatars (issue 17) instead of boxes/cylinders;
  // key v. Locked on by --avatars-only.
  bool avatars = true;
  bool avatars_locked = false;
  std::string selected_camera;                  // highlighted in every view
  std::array<std::string, 3> locked;            // cameras of the three locked views ("" = plan view)
  // Replay (issue 18), the panel's "Replay" section: a time line of each camera's recorded
  // intervals (`recorded`, refreshed by the viewer from SceneService.RecordedSpans) ending at
  // timeline_now_ns; a drag on it seeks (kSeek at replay_seek_ns, on release), "play" resumes a
  // pause (or starts replay_back_s before now), "pause" stops where it is, "live" goes back to
  // live; rate presets 0.25x .. 16x. The viewer consumes replay_command each frame and sets
  // replay_status, replay_time_ns (the recorded time shown, 0 when live) and the rest.
  enum class ReplayCommand { kNone, kPlay, kPause, kLive, kSeek, kRate };
  ReplayCommand replay_command = ReplayCommand::kNone;
  int64_t replay_seek_ns = 0;
  float replay_back_s = 60;
  float replay_rate = 1;
  std::string replay_status = "live";
  RecordedSpans recorded;
  int64_t timeline_now_ns = 0;  // the time line's right end (the viewer's clock)
  int64_t replay_time_ns = 0;
  int timeline_zoom = 1;  // index of the shown span: 1 min, 10 min, 1 h, everything recorded
  bool open_replay = false;  // set: the Replay section opens on the next panel (then cleared)
  std::array<float, 4> timeline_rect_px{};  // where the time line was last drawn: x, y, width, height
  std::array<float, 4> live_button_rect_px{};   // where the "live" button was last drawn (same form)
  std::array<float, 4> pause_button_rect_px{};  // where the "pause" button was last drawn (same form)
};

// Figures the panel shows.
struct OverlayStats {
  double fps = 0;
  int cameras_receiving = 0;  // cameras whose frames arrived in the last 2 s
  double jpeg_bytes_per_s = 0;
  uint64_t subscriptions = 0;
  int servers = 1;
};

// Where a local-frame point lands in the framebuffer: pixels from the top-left corner; nullopt
// when behind the eye or outside the view's viewport.
std::optional<Eigen::Vector2d> ProjectToScreen(const View& view, int framebuffer_height, const Eigen::Vector3d& p_local);

// The camera whose position is drawn nearest `cursor_px` (top-left pixels) in `view`, within
// `radius_px`; empty when none.
std::string PickCamera(const View& view, int framebuffer_height, const std::vector<CameraView>& cameras,
                       const Eigen::Vector2d& cursor_px, double radius_px = 16);

// The ray through a framebuffer pixel (top-left pixels) of `view`: origin on the near plane and
// unit direction, local frame.
std::pair<Eigen::Vector3d, Eigen::Vector3d> PixelRayOfView(const View& view, int framebuffer_height,
                                                           const Eigen::Vector2d& cursor_px);

// How often the overlay's pixels are redrawn (issue 7 performance). ImGui's triangles are
// rasterised into a cached RGBA texture that is composited over the views every frame (one
// textured pass over the 32-pixel tiles the overlay covers); the texture is redrawn only when the
// overlay's triangles changed, and then at once on window input, when the views moved (labels
// follow the scene), on a size change, or when 1 / content_refresh_hz has passed since the last
// redraw (the frame rate, byte rate and time line tick at that rate).
struct OverlayOptions {
  double content_refresh_hz = 0;  // 0: redraw on every change
};

class Overlay {
 public:
  // Needs the current GL context (it compiles ImGui's GL 3.3 shaders and uploads the font).
  static absl::StatusOr<std::unique_ptr<Overlay>> Create(const OverlayOptions& options = {});
  ~Overlay();
  Overlay(const Overlay&) = delete;
  Overlay& operator=(const Overlay&) = delete;

  // Starts a frame of the given framebuffer size; `input` (window mode) feeds mouse and typing.
  void BeginFrame(int framebuffer_width, int framebuffer_height, const WindowInput* input, double dt_s);
  // Whether the panel took the mouse in this frame (then the 3D views ignore it).
  bool WantsMouse() const;
  // The panel; edits `state`. `now_ns`: the server clock of the newest update (time line).
  // `lidars` are listed under the cameras with their own status line (issue 16).
  void Panel(const std::vector<CameraView>& cameras, const OverlayStats& stats, int64_t now_ns, OverlayState& state,
             const std::vector<LidarView>& lidars = {});
  // Camera names, object ids and paths in one view.
  void Annotate(const View& view, int framebuffer_height, const std::vector<CameraView>& cameras,
                const std::vector<ObjectView>& objects, const OverlayState& state);
  // Draws everything into the currently bound framebuffer (from the cache when it may).
  // `views_moved`: a view's pose or projection changed since the last frame.
  void EndFrame(bool views_moved = false);
  // Times the overlay's texture was redrawn (the rest of EndFrame calls composited the cache).
  uint64_t redraws() const;
  // Headless: builds one frame and throws it away so auto-sized windows have their size.
  void DiscardFrame();

 private:
  Overlay() = default;
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace ave::viewer
