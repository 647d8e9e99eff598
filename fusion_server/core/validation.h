#pragma once
// Validation of everything a sensor or an administrator sends (MISSION part G: every input
// validated with a clear error). Messages name the camera and the field; nothing here decodes
// image data: JPEG headers are parsed for their dimensions only.
#include <cstdint>
#include <string>
#include <string_view>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "ave/v1/ave.pb.h"

namespace ave {

struct JpegInfo {
  int width = 0;
  int height = 0;
  int components = 0;
  bool progressive = false;
};

// Walks the JPEG marker segments up to the start-of-frame and checks the end-of-image marker.
// Truncated data, a missing SOI/EOI, zero or oversize dimensions are errors.
absl::StatusOr<JpegInfo> ParseJpegHeader(std::string_view bytes);

struct FrameLimits {
  size_t max_jpeg_bytes = 8u << 20;  // 8 MiB
  int max_boxes = 1024;
  // Rotating LiDARs (issue 16): people per sweep, and foreground points per sweep (8 bytes each:
  // 2 MiB; a 64-beam sensor returns ~130 k points a sweep, people are a small part of them).
  int max_foot_tracks = 1024;
  uint32_t max_lidar_points = 262144;
};

// Camera ids: [A-Za-z0-9_.-], 1..64 characters.
bool IsValidCameraId(std::string_view id);

// Hello: id, token presence, kind, intrinsics (a camera's; a LiDAR must send none). Errors name
// the field.
absl::Status ValidateHello(const v1::SensorHello& hello);

// Pose: finite position, finite unit quaternion (|1 - |q|| <= 1e-3), covariance empty or 36 finite
// values with a non-negative diagonal. `field` prefixes messages ("frame 12: pose.orientation ...").
absl::Status ValidatePose(const v1::Pose& pose, const std::string& field);

// One frame of an accepted stream. `last_sequence` is the last accepted sequence (0: none yet).
// capture_time_ns must be in (0, 4e18] and clock_offset_ns within one day either way.
absl::Status ValidateFrame(const v1::SensorFrame& frame, const v1::Intrinsics& intrinsics, uint64_t last_sequence,
                           const FrameLimits& limits);

// The fastest foot track a LiDAR sweep may carry (m/s): agents leave out a track over it rather
// than send a sweep the server refuses whole.
inline constexpr float kMaxTrackSpeedMps = 100;

// One sweep of a rotating LiDAR's stream (issue 16). Same sequence, time and offset rules as
// ValidateFrame; world_from_sensor as ValidatePose; every track with an id > 0 unique in the sweep,
// a finite position within 1e7 m of the local origin, a finite velocity under 100 m/s, a
// covariance of exactly 3 finite values (xx, xy, yy) that is positive semi-definite; foreground
// points within the limit, packed as exactly count * 8 bytes (not decoded). Errors start
// "sweep N: " and name the field ("sweep 12: tracks[3].covariance ...").
absl::Status ValidateLidarSweep(const v1::LidarSweepFrame& sweep, uint64_t last_sequence, const FrameLimits& limits);

}  // namespace ave
