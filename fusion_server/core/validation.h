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
};

// Camera ids: [A-Za-z0-9_.-], 1..64 characters.
bool IsValidCameraId(std::string_view id);

// Hello: id, token presence, intrinsics. Errors name the field.
absl::Status ValidateHello(const v1::SensorHello& hello);

// Pose: finite position, finite unit quaternion (|1 - |q|| <= 1e-3), covariance empty or 36 finite
// values with a non-negative diagonal. `field` prefixes messages ("frame 12: pose.orientation ...").
absl::Status ValidatePose(const v1::Pose& pose, const std::string& field);

// One frame of an accepted stream. `last_sequence` is the last accepted sequence (0: none yet).
// capture_time_ns must be in (0, 4e18] and clock_offset_ns within one day either way.
absl::Status ValidateFrame(const v1::SensorFrame& frame, const v1::Intrinsics& intrinsics, uint64_t last_sequence,
                           const FrameLimits& limits);

}  // namespace ave
