#include "viewer_client/client/lidar_points.h"

#include <cmath>

#include "absl/strings/str_cat.h"

namespace ave::viewer {

absl::StatusOr<LidarPointCloud> DecodeLidarPoints(std::string_view packed, uint32_t count,
                                                  const Rigid3d& world_from_sensor,
                                                  const std::vector<LidarTrackView>& tracks) {
  if (packed.size() != size_t{count} * 8) {
    return absl::InvalidArgumentError(
        absl::StrCat("lidar points: ", packed.size(), " bytes for ", count, " points (8 bytes each)"));
  }
  const Eigen::Matrix3f r = world_from_sensor.rotation.toRotationMatrix().cast<float>();
  const Eigen::Vector3f t = world_from_sensor.translation.cast<float>();
  LidarPointCloud cloud;
  cloud.p_local.reserve(count);
  cloud.track_id.reserve(count);
  cloud.object_id.reserve(count);
  const auto u16 = [&](size_t at) {
    return static_cast<uint16_t>(static_cast<uint8_t>(packed[at]) | (static_cast<uint8_t>(packed[at + 1]) << 8));
  };
  for (size_t k = 0; k < count; ++k) {
    const size_t at = 8 * k;
    const Eigen::Vector3f p_in_sensor(static_cast<int16_t>(u16(at)) * 0.01f, static_cast<int16_t>(u16(at + 2)) * 0.01f,
                                      static_cast<int16_t>(u16(at + 4)) * 0.01f);
    cloud.p_local.push_back(r * p_in_sensor + t);
    const uint16_t label = u16(at + 6);
    if (label > tracks.size()) ++cloud.bad_labels;
    const bool named = label > 0 && label <= tracks.size();
    cloud.track_id.push_back(named ? tracks[label - 1].track_id : 0);
    cloud.object_id.push_back(named ? tracks[label - 1].object_id : 0);
  }
  return cloud;
}

Eigen::Vector3f IdColor(uint64_t id) {
  if (id == 0) return Eigen::Vector3f(0.6f, 0.6f, 0.6f);
  const double hue = std::fmod(id * 0.6180339887498949, 1.0) * 6;  // golden ratio: neighbours differ
  const int sector = static_cast<int>(hue);
  const float f = static_cast<float>(hue - sector), v = 0.95f, s = 0.8f;
  const float p = v * (1 - s), q = v * (1 - s * f), u = v * (1 - s * (1 - f));
  switch (sector % 6) {
    case 0: return {v, u, p};
    case 1: return {q, v, p};
    case 2: return {p, v, u};
    case 3: return {p, q, v};
    case 4: return {u, p, v};
    default: return {v, p, q};
  }
}

}  // namespace ave::viewer
