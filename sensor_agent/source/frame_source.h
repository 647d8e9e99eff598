#pragma once
// Where an agent's frames come from, behind one interface: a video file, an RTSP/HTTP stream or a
// V4L2 device (all through OpenCV VideoCapture), or the simulated campus camera.
//
// Source specs:
//   sim:SCENARIO#CAMERA  a scenario camera through the simulator (bundled name or .yaml path;
//                        its effects apply, moving cameras walk their path; true pose attached)
//   file:/path/video.mp4 a video file (ends at its last frame)
//   rtsp://host/stream   a network stream (also http://, https://, e.g. an MJPEG camera); a
//                        drop-out (the read fails) closes it and the next Next() reconnects
//   v4l2:/dev/video0     a local capture device (or v4l2:0)
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "model_store/geometry/camera.h"
#include "model_store/geometry/rigid3.h"

namespace ave {

struct CapturedFrame {
  int64_t capture_time_ns = 0;  // sensor clock (system clock here)
  double scene_time_s = 0;      // simulated time for sim sources; seconds since the first frame otherwise
  int width = 0;
  int height = 0;
  std::vector<uint8_t> bgr;  // 3 bytes per pixel, top row first
  std::optional<Rigid3d> world_from_camera;  // the source's own pose, if it knows one
  // Row-major 6x6 covariance of world_from_camera (position m, world rotation vector rad), as the
  // wire Pose carries it; empty = unknown (sensor_agent/pose fills it, issue 5).
  std::vector<double> pose_covariance;
  // The frame as the camera delivered it, JPEG-encoded at `jpeg_quality` (pre-rendered sim
  // footage, issue 19); `bgr` is then its decoded image. Empty: the source delivered pixels only.
  // The agent sends these bytes as they are unless it asks for a lower quality.
  std::vector<uint8_t> jpeg;
  int jpeg_quality = 0;
};

class FrameSource {
 public:
  virtual ~FrameSource() = default;
  // The next frame; OutOfRange at the end of a finite source, Unavailable on a read failure.
  virtual absl::StatusOr<CapturedFrame> Next() = 0;
  virtual PinholeIntrinsics intrinsics() const = 0;
  virtual std::string description() const = 0;
  // True when the device delivers frames at its own rate (live cameras); false when the caller
  // must pace them (files, the simulator).
  virtual bool live() const = 0;
  // Network streams (rtsp://, http(s)://): drop-outs seen (reads that failed after the stream
  // delivered) and reconnections that delivered again; 0 for other sources.
  virtual int64_t drop_outs() const { return 0; }
  virtual int64_t reconnects() const { return 0; }
};

struct SourceOptions {
  double fps = 10;  // simulated frame rate (sim sources step scene time by 1/fps)
  double sim_start_s = 0;
  // Intrinsics for sources that cannot know them (files, devices); width 0 = derive from the first
  // frame with `default_fov_deg`.
  PinholeIntrinsics intrinsics;
  double default_fov_deg = 60;
  // Sim sources: render the next frame on a thread of its own while the caller processes this one,
  // as a real camera exposes the next frame while the agent encodes the last (issue 19: the
  // backpack camera's render alone takes most of a 30 Hz frame's time). Costs no extra CPU per
  // frame; one frame is rendered ahead of need.
  bool sim_render_ahead = false;
  // Sim sources: a footage file of this camera (sensor_agent/sim/footage.h, made by `ave-sim
  // footage`) to play instead of rendering: frame k is the file's frame k, JPEG bytes and their
  // decoded image, at the same scene time k / fps; the true pose still comes from the scenario.
  // Frames past the file's end are rendered live. A missing, corrupt or stale file (another
  // scenario text, camera, fps or start; a first or last frame that no longer equals a fresh
  // render) is logged with the reason and the file's name, and every frame is rendered live.
  std::string sim_footage;
};

absl::StatusOr<std::unique_ptr<FrameSource>> OpenSource(const std::string& spec, const SourceOptions& options);

}  // namespace ave
