#pragma once
// Client side of a rotating LiDAR's foreground points (issue 16): the wire's packed points
// (ave.v1.LidarPoints: per point int16 x, y, z centimetres in the sensor frame and a uint16 label,
// little-endian; label k > 0 = the sweep's tracks[k - 1]) decoded into the model's local frame,
// each point tied to its person's track and fused object, so a point pass can colour the cloud by
// track or object id. No GL here: the point pass lives in viewer_client/render/.
#include <cstdint>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "absl/status/statusor.h"
#include "model_store/geometry/rigid3.h"

namespace ave::viewer {

// One person a LiDAR tracks in its newest sweep (wire FootTrack + the object it fused into).
struct LidarTrackView {
  uint32_t track_id = 0;
  Eigen::Vector3d position = Eigen::Vector3d::Zero();  // ground contact, local frame
  Eigen::Vector2d velocity_mps = Eigen::Vector2d::Zero();
  uint64_t object_id = 0;  // the server's fused object (DynamicObject.object_id); 0 = none
};

struct LidarPointCloud {
  uint64_t sweep_sequence = 0;
  std::vector<Eigen::Vector3f> p_local;  // local frame, metres (floats are fine: relative to the model's origin)
  std::vector<uint32_t> track_id;        // per point: its person's track id, 0 when the label names none
  std::vector<uint64_t> object_id;       // per point: that track's fused object id, 0 when none
  size_t bad_labels = 0;                 // labels past the sweep's track count (treated as none)
};

// Decodes `count` packed points. InvalidArgument (naming the sizes) when packed is not count * 8
// bytes; a label past `tracks` counts in bad_labels and leaves the point unassigned.
absl::StatusOr<LidarPointCloud> DecodeLidarPoints(std::string_view packed, uint32_t count,
                                                  const Rigid3d& world_from_sensor,
                                                  const std::vector<LidarTrackView>& tracks);

// A stable, saturated colour (RGB in [0, 1]) for an id (golden-ratio hues); grey for 0.
Eigen::Vector3f IdColor(uint64_t id);

}  // namespace ave::viewer
