#pragma once
// The sweep on the sensor's cylinder (i4D §3.1): a rings x cols range image, row = ring, column =
// azimuth bin (bins centred on multiples of 2π / cols, so column c covers [c - 0.5, c + 0.5) steps;
// the last bin wraps to column 0). Several points in one pixel: the nearest is the pixel's range,
// the others are kept by index for the 3D classification step.
#include <cstdint>
#include <vector>

#include "absl/status/statusor.h"
#include "sensor_agent/lidar/lidar_types.h"

namespace ave::lidar_track {

struct RangeImage {
  int rings = 0, cols = 0;
  std::vector<float> range_m;              // rings * cols, row-major; 0 = no return
  std::vector<int32_t> nearest_point;      // per pixel: index into sweep.points, -1 = no return
  std::vector<int32_t> pixel_of_point;     // per sweep point: pixel index, -1 = unusable point
  int Index(int ring, int col) const { return ring * cols + col; }
};

// A point is unusable (pixel -1, never foreground) when its range is not finite, <= 0 or above
// max_range_m, or its position is not finite. InvalidArgument, naming the point and field, when
// the sweep's ring count is not in [1, 4096], cols is not in [8, 36000] or a point's ring is out
// of range.
absl::StatusOr<RangeImage> BuildRangeImage(const lidar::LidarSweep& sweep, int cols, float max_range_m);

// Azimuth (radians, any value) to its column in [0, cols).
int AzimuthColumn(float azimuth_rad, int cols);

}  // namespace ave::lidar_track
