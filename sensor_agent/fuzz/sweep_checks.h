#pragma once
// What every decoded sweep must satisfy, whatever bytes it came from (the Velodyne fuzz targets'
// checks beyond "no crash"). A violation aborts, so libFuzzer keeps the input as a finding.
#include <cmath>
#include <cstdio>
#include <cstdlib>

#include "sensor_agent/lidar/lidar_types.h"

namespace ave::lidar::fuzz {

[[noreturn]] inline void Fail(const char* what, double value) {
  std::fprintf(stderr, "velodyne fuzz check failed: %s (%g)\n", what, value);
  std::abort();
}

// max_range_m: the decoder's limit; rings: its calibration's laser count.
inline void CheckSweep(const LidarSweep& sweep, double max_range_m, int rings) {
  constexpr float kTwoPi = static_cast<float>(2 * 3.14159265358979323846);
  if (sweep.rings != rings) Fail("sweep.rings is not the calibration's laser count", sweep.rings);
  if (static_cast<int>(sweep.ring_elevation_rad.size()) != rings) Fail("ring_elevation_rad size", sweep.ring_elevation_rad.size());
  for (const SweepPoint& p : sweep.points) {
    if (!p.p_in_sensor.allFinite()) Fail("p_in_sensor not finite", p.p_in_sensor.norm());
    if (!(p.range_m > 0 && p.range_m <= max_range_m)) Fail("range_m outside (0, max]", p.range_m);
    if (!(p.azimuth_rad >= 0 && p.azimuth_rad < kTwoPi)) Fail("azimuth_rad outside [0, 2pi)", p.azimuth_rad);
    if (!(p.intensity >= 0 && p.intensity <= 255)) Fail("intensity outside [0, 255]", p.intensity);
    if (p.ring >= rings) Fail("ring >= rings", p.ring);
    if (p.return_index > 1) Fail("return_index > 1", p.return_index);
  }
}

}  // namespace ave::lidar::fuzz
