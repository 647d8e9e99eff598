#include "fusion_server/core/validation.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "absl/strings/str_cat.h"
#include "fusion_server/core/convert.h"
#include "model_store/image/jpeg_header.h"

namespace ave {
namespace {

constexpr int kMaxJpegSide = image::kMaxImageSide;
// Time stamps up to the year 2096 and clock offsets up to a day keep every sum of the two (and
// differences with the server's clock) far inside int64.
constexpr int64_t kMaxTimeNs = 4'000'000'000'000'000'000;
constexpr int64_t kMaxClockOffsetNs = 86'400'000'000'000;

}  // namespace

absl::StatusOr<JpegInfo> ParseJpegHeader(std::string_view b) {
  const auto byte = [&](size_t i) { return static_cast<uint8_t>(b[i]); };
  if (b.size() < 4 || byte(0) != 0xFF || byte(1) != 0xD8) {
    return absl::InvalidArgumentError(absl::StrCat("not a JPEG: missing start-of-image marker (", b.size(), " bytes)"));
  }
  if (byte(b.size() - 2) != 0xFF || byte(b.size() - 1) != 0xD9) {
    return absl::InvalidArgumentError(
        absl::StrCat("truncated JPEG: no end-of-image marker at byte ", b.size() - 2, " of ", b.size()));
  }
  absl::StatusOr<image::JpegFrameHeader> sof = image::FindJpegFrameHeader(b);
  if (!sof.ok()) return sof.status();
  JpegInfo info;
  info.width = sof->width;
  info.height = sof->height;
  info.components = sof->components;
  info.progressive = sof->progressive;
  if (info.width <= 0 || info.height <= 0 || info.width > kMaxJpegSide || info.height > kMaxJpegSide) {
    return absl::InvalidArgumentError(
        absl::StrCat("JPEG dimensions ", info.width, "x", info.height, " outside 1..", kMaxJpegSide));
  }
  if (int64_t{info.width} * info.height > image::kMaxImagePixels) {
    return absl::InvalidArgumentError(absl::StrCat("JPEG dimensions ", info.width, "x", info.height, " over ",
                                                   image::kMaxImagePixels >> 20, " Mpx (viewers could not decode it)"));
  }
  if (info.components != 1 && info.components != 3) {
    return absl::InvalidArgumentError(absl::StrCat("JPEG has ", info.components, " components (1 or 3 supported)"));
  }
  return info;
}

bool IsValidCameraId(std::string_view id) {
  if (id.empty() || id.size() > 64) return false;
  for (char c : id) {
    const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_' ||
                    c == '-' || c == '.';
    if (!ok) return false;
  }
  return true;
}

absl::Status ValidateHello(const v1::SensorHello& hello) {
  if (!IsValidCameraId(hello.camera_id())) {
    return absl::InvalidArgumentError("hello.camera_id must be 1..64 characters of [A-Za-z0-9_.-]");
  }
  if (hello.token().empty() || hello.token().size() > 4096) {
    return absl::UnauthenticatedError(absl::StrCat("camera '", hello.camera_id(), "': hello.token missing or too long"));
  }
  if (hello.software_version().size() > 128) {
    return absl::InvalidArgumentError(
        absl::StrCat("camera '", hello.camera_id(), "': hello.software_version longer than 128 characters"));
  }
  if (!v1::SensorKind_IsValid(hello.kind())) {
    return absl::InvalidArgumentError(
        absl::StrCat("sensor '", hello.camera_id(), "': hello.kind ", hello.kind(), " is not a known sensor kind"));
  }
  if (hello.kind() == v1::SENSOR_KIND_ROTATING_LIDAR) {
    if (hello.has_intrinsics()) {
      return absl::InvalidArgumentError(
          absl::StrCat("lidar '", hello.camera_id(), "': hello.intrinsics must be absent for a rotating LiDAR"));
    }
    return absl::OkStatus();
  }
  if (hello.intrinsics().distortion_size() != 0 && hello.intrinsics().distortion_size() != 5) {
    return absl::InvalidArgumentError(absl::StrCat("camera '", hello.camera_id(),
                                                   "': hello.intrinsics.distortion must have 0 or 5 values"));
  }
  const std::string why = FromProto(hello.intrinsics()).Check();
  if (!why.empty()) {
    return absl::InvalidArgumentError(absl::StrCat("camera '", hello.camera_id(), "': hello.intrinsics.", why));
  }
  return absl::OkStatus();
}

absl::Status ValidatePose(const v1::Pose& pose, const std::string& field) {
  const auto& p = pose.position();
  if (!std::isfinite(p.x()) || !std::isfinite(p.y()) || !std::isfinite(p.z())) {
    return absl::InvalidArgumentError(absl::StrCat(field, ".position must be finite"));
  }
  const auto& q = pose.orientation();
  const double norm = std::sqrt(q.w() * q.w() + q.x() * q.x() + q.y() * q.y() + q.z() * q.z());
  if (!std::isfinite(norm)) return absl::InvalidArgumentError(absl::StrCat(field, ".orientation must be finite"));
  if (std::abs(norm - 1.0) > 1e-3) {
    return absl::InvalidArgumentError(absl::StrCat(field, ".orientation must be a unit quaternion (norm ", norm, ")"));
  }
  if (pose.covariance_size() != 0) {
    if (pose.covariance_size() != 36) {
      return absl::InvalidArgumentError(
          absl::StrCat(field, ".covariance must have 0 or 36 values, not ", pose.covariance_size()));
    }
    for (int i = 0; i < 36; ++i) {
      if (!std::isfinite(pose.covariance(i))) {
        return absl::InvalidArgumentError(absl::StrCat(field, ".covariance[", i, "] must be finite"));
      }
    }
    for (int i = 0; i < 6; ++i) {
      if (pose.covariance(i * 7) < 0) {
        return absl::InvalidArgumentError(absl::StrCat(field, ".covariance diagonal [", i, "] is negative"));
      }
    }
  }
  return absl::OkStatus();
}

absl::Status ValidateFrame(const v1::SensorFrame& frame, const v1::Intrinsics& intrinsics, uint64_t last_sequence,
                           const FrameLimits& limits) {
  const std::string where = absl::StrCat("frame ", frame.sequence(), ": ");
  if (frame.sequence() <= last_sequence) {
    return absl::InvalidArgumentError(
        absl::StrCat(where, "sequence must increase (last accepted ", last_sequence, ")"));
  }
  if (frame.capture_time_ns() <= 0 || frame.capture_time_ns() > kMaxTimeNs) {
    return absl::InvalidArgumentError(absl::StrCat(where, "capture_time_ns must be in (0, ", kMaxTimeNs, "]"));
  }
  // Found by ave_fuzz_sensor_message: an unbounded offset overflowed capture + offset (UB).
  if (frame.clock_offset_ns() < -kMaxClockOffsetNs || frame.clock_offset_ns() > kMaxClockOffsetNs) {
    return absl::InvalidArgumentError(
        absl::StrCat(where, "clock_offset_ns must be within +-", kMaxClockOffsetNs, " ns (one day)"));
  }
  if (frame.metadata_only() && !frame.jpeg().empty()) {
    return absl::InvalidArgumentError(absl::StrCat(where, "a metadata_only frame must not carry a jpeg"));
  }
  if (frame.has_pose()) {
    if (absl::Status s = ValidatePose(frame.pose(), absl::StrCat(where, "pose")); !s.ok()) return s;
  }
  if (frame.boxes_size() > limits.max_boxes) {
    return absl::InvalidArgumentError(absl::StrCat(where, frame.boxes_size(), " boxes (at most ", limits.max_boxes, ")"));
  }
  for (int i = 0; i < frame.boxes_size(); ++i) {
    const auto& box = frame.boxes(i);
    if (box.corners_size() != 4) {
      return absl::InvalidArgumentError(absl::StrCat(where, "boxes[", i, "] must have 4 corners"));
    }
    for (const auto& c : box.corners()) {
      if (!std::isfinite(c.x()) || !std::isfinite(c.y())) {
        return absl::InvalidArgumentError(absl::StrCat(where, "boxes[", i, "] has a non-finite corner"));
      }
    }
    if (!std::isfinite(box.score()) || box.score() < 0 || box.score() > 1) {
      return absl::InvalidArgumentError(absl::StrCat(where, "boxes[", i, "].score must be in [0, 1]"));
    }
  }
  if (frame.jpeg().size() > limits.max_jpeg_bytes) {
    return absl::ResourceExhaustedError(
        absl::StrCat(where, "jpeg is ", frame.jpeg().size(), " bytes (at most ", limits.max_jpeg_bytes, ")"));
  }
  if (!frame.jpeg().empty()) {
    absl::StatusOr<JpegInfo> info = ParseJpegHeader(frame.jpeg());
    if (!info.ok()) return absl::InvalidArgumentError(absl::StrCat(where, "jpeg: ", info.status().message()));
    if (info->width != static_cast<int>(intrinsics.width()) || info->height != static_cast<int>(intrinsics.height())) {
      return absl::InvalidArgumentError(absl::StrCat(where, "jpeg is ", info->width, "x", info->height,
                                                     " but the camera's intrinsics say ", intrinsics.width(), "x",
                                                     intrinsics.height()));
    }
  }
  return absl::OkStatus();
}

absl::Status ValidateLidarSweep(const v1::LidarSweepFrame& sweep, uint64_t last_sequence, const FrameLimits& limits) {
  const std::string where = absl::StrCat("sweep ", sweep.sequence(), ": ");
  const auto bad = [&](auto&&... what) { return absl::InvalidArgumentError(absl::StrCat(where, what...)); };
  if (sweep.sequence() <= last_sequence) return bad("sequence must increase (last accepted ", last_sequence, ")");
  if (sweep.capture_time_ns() <= 0 || sweep.capture_time_ns() > kMaxTimeNs) {
    return bad("capture_time_ns must be in (0, ", kMaxTimeNs, "]");
  }
  if (sweep.clock_offset_ns() < -kMaxClockOffsetNs || sweep.clock_offset_ns() > kMaxClockOffsetNs) {
    return bad("clock_offset_ns must be within +-", kMaxClockOffsetNs, " ns (one day)");
  }
  if (sweep.has_world_from_sensor()) {
    if (absl::Status s = ValidatePose(sweep.world_from_sensor(), where + "world_from_sensor"); !s.ok()) return s;
  }
  if (sweep.tracks_size() > limits.max_foot_tracks) {
    return bad(sweep.tracks_size(), " tracks (at most ", limits.max_foot_tracks, ")");
  }
  // Ids unique within the sweep: a sorted copy (at most max_foot_tracks of them).
  std::vector<uint32_t> ids;
  ids.reserve(sweep.tracks_size());
  constexpr double kMaxCoordinateM = 1e7;  // the local frame is site-sized; this only bounds the sums
  constexpr float kMaxSpeedMps = kMaxTrackSpeedMps;
  for (int i = 0; i < sweep.tracks_size(); ++i) {
    const v1::FootTrack& t = sweep.tracks(i);
    const std::string field = absl::StrCat("tracks[", i, "]");
    if (t.track_id() == 0) return bad(field, ".track_id must be > 0");
    ids.push_back(t.track_id());
    const v1::Vec3& p = t.position();
    for (double v : {p.x(), p.y(), p.z()}) {
      if (!std::isfinite(v) || std::abs(v) > kMaxCoordinateM) {
        return bad(field, ".position must be finite and within ", kMaxCoordinateM, " m of the local origin");
      }
    }
    if (!std::isfinite(t.velocity_x_mps()) || !std::isfinite(t.velocity_y_mps()) ||
        std::hypot(t.velocity_x_mps(), t.velocity_y_mps()) > kMaxSpeedMps) {
      return bad(field, ".velocity must be finite and under ", kMaxSpeedMps, " m/s");
    }
    if (t.covariance_size() != 3) {
      return bad(field, ".covariance must have 3 values (xx, xy, yy), not ", t.covariance_size());
    }
    const double xx = t.covariance(0), xy = t.covariance(1), yy = t.covariance(2);
    if (!std::isfinite(xx) || !std::isfinite(xy) || !std::isfinite(yy)) return bad(field, ".covariance must be finite");
    // Positive semi-definite, with a little room for float rounding of a singular matrix.
    if (xx < 0 || yy < 0 || xx * yy - xy * xy < -1e-6 * (xx * yy + 1e-12)) {
      return bad(field, ".covariance (", xx, ", ", xy, ", ", yy, ") is not positive semi-definite");
    }
  }
  std::sort(ids.begin(), ids.end());
  if (auto dup = std::adjacent_find(ids.begin(), ids.end()); dup != ids.end()) {
    return bad("track_id ", *dup, " appears twice");
  }
  const v1::LidarPoints& points = sweep.foreground();
  if (points.count() > limits.max_lidar_points) {
    return absl::ResourceExhaustedError(
        absl::StrCat(where, "foreground.count ", points.count(), " points (at most ", limits.max_lidar_points, ")"));
  }
  if (points.packed().size() != size_t{points.count()} * 8) {
    return bad("foreground.packed is ", points.packed().size(), " bytes; count ", points.count(), " needs ",
               size_t{points.count()} * 8);
  }
  return absl::OkStatus();
}

}  // namespace ave
