#include "sensor_agent/lidar_track/range_image.h"

#include <cmath>
#include <numbers>

#include "absl/strings/str_cat.h"

namespace ave::lidar_track {

int AzimuthColumn(float azimuth_rad, int cols) {
  if (!std::isfinite(azimuth_rad)) return 0;
  const double steps = static_cast<double>(azimuth_rad) * cols / (2 * std::numbers::pi);
  long c = std::lround(std::floor(steps + 0.5)) % cols;
  if (c < 0) c += cols;
  return static_cast<int>(c);
}

absl::StatusOr<RangeImage> BuildRangeImage(const lidar::LidarSweep& sweep, int cols, float max_range_m) {
  if (sweep.rings < 1 || sweep.rings > 4096) {
    return absl::InvalidArgumentError(absl::StrCat("LidarSweep.rings: ", sweep.rings, " is not in [1, 4096]"));
  }
  if (cols < 8 || cols > 36000) return absl::InvalidArgumentError(absl::StrCat("range image cols: ", cols, " is not in [8, 36000]"));
  RangeImage img;
  img.rings = sweep.rings;
  img.cols = cols;
  const size_t pixels = static_cast<size_t>(sweep.rings) * cols;
  img.range_m.assign(pixels, 0.f);
  img.nearest_point.assign(pixels, -1);
  img.pixel_of_point.assign(sweep.points.size(), -1);
  for (size_t i = 0; i < sweep.points.size(); ++i) {
    const lidar::SweepPoint& p = sweep.points[i];
    if (p.ring >= sweep.rings) {
      return absl::InvalidArgumentError(absl::StrCat("LidarSweep.points[", i, "].ring: ", p.ring, " >= rings ", sweep.rings));
    }
    if (!(std::isfinite(p.range_m) && p.range_m > 0 && p.range_m <= max_range_m) || !p.p_in_sensor.allFinite()) continue;
    const int idx = img.Index(p.ring, AzimuthColumn(p.azimuth_rad, cols));
    img.pixel_of_point[i] = idx;
    if (img.nearest_point[idx] < 0 || p.range_m < img.range_m[idx]) {
      img.nearest_point[idx] = static_cast<int32_t>(i);
      img.range_m[idx] = p.range_m;
    }
  }
  return img;
}

}  // namespace ave::lidar_track
