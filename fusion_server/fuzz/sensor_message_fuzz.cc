// libFuzzer target: a SensorMessage as the sensor service receives it, through the same checks
// (hello validation, frame validation with the JPEG header, scene-state ingest and a viewer update;
// for a rotating LiDAR's sweep (issue 16), sweep validation, fusion of its tracks and a viewer
// update with its points).
#include <cstddef>
#include <cstdint>
#include <memory>

#include "ave/v1/ave.pb.h"
#include "fusion_server/core/scene_state.h"
#include "fusion_server/core/validation.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  ave::v1::SensorMessage message;
  if (!message.ParseFromArray(data, static_cast<int>(size))) return 0;
  ave::v1::Intrinsics intrinsics;
  if (message.has_hello()) {
    if (!ave::ValidateHello(message.hello()).ok()) return 0;
    intrinsics = message.hello().intrinsics();
  } else {
    intrinsics.set_width(64);
    intrinsics.set_height(48);
    intrinsics.set_fx(50);
    intrinsics.set_fy(50);
    intrinsics.set_cx(32);
    intrinsics.set_cy(24);
  }
  if (message.has_lidar_sweep()) {
    ave::FrameLimits limits;
    limits.max_lidar_points = 4096;
    if (!ave::ValidateLidarSweep(message.lidar_sweep(), 0, limits).ok()) return 0;
    // An accepted sweep must be safe to fuse, keep and turn into a viewer update, twice (the
    // second sweep's tracks meet the first's objects).
    ave::SceneState state;
    ave::CameraEntry lidar;
    lidar.id = "hdl";
    lidar.kind = ave::SensorKind::kRotatingLidar;
    state.UpsertCamera(lidar);
    auto sweep = std::make_shared<ave::v1::LidarSweepFrame>(message.lidar_sweep());
    if (!state.AcceptLidarSweep("hdl", sweep, 1, 1).ok()) __builtin_trap();
    auto again = std::make_shared<ave::v1::LidarSweepFrame>(*sweep);
    again->set_sequence(sweep->sequence() + 1);
    if (!state.AcceptLidarSweep("hdl", again, 100'000'001, 1).ok()) __builtin_trap();
    ave::ViewerCursor cursor;
    cursor.include_lidar_points = true;
    (void)state.BuildUpdate({}, true, 100'000'002, cursor);
    return 0;
  }
  if (!message.has_frame()) return 0;
  ave::FrameLimits limits;
  limits.max_jpeg_bytes = 1 << 20;
  if (!ave::ValidateFrame(message.frame(), intrinsics, 0, limits).ok()) return 0;
  // An accepted frame must be safe to keep and to turn into a viewer update.
  ave::SceneState state;
  ave::CameraEntry camera;
  camera.id = "cam";
  camera.intrinsics.width = static_cast<int>(intrinsics.width());
  camera.intrinsics.height = static_cast<int>(intrinsics.height());
  camera.intrinsics.fx = intrinsics.fx();
  camera.intrinsics.fy = intrinsics.fy();
  camera.intrinsics.cx = intrinsics.cx();
  camera.intrinsics.cy = intrinsics.cy();
  state.UpsertCamera(camera);
  if (!state.AcceptFrame("cam", std::make_shared<ave::v1::SensorFrame>(message.frame()), 1).ok()) __builtin_trap();
  ave::ViewerCursor cursor;
  (void)state.BuildUpdate({}, true, 2, cursor);
  return 0;
}
