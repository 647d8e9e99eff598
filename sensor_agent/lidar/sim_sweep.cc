#include "sensor_agent/lidar/sim_sweep.h"

#include <numbers>

namespace ave::lidar {

std::vector<float> RingElevationsRad(const sim::RotatingLidarSpec& spec) {
  std::vector<float> out;
  out.reserve(spec.rings);
  for (int r = 0; r < spec.rings; ++r) {
    const double deg =
        spec.rings == 1 ? spec.fov_up_deg : spec.fov_up_deg - r * (spec.fov_up_deg - spec.fov_down_deg) / (spec.rings - 1);
    out.push_back(static_cast<float>(deg * std::numbers::pi / 180));
  }
  return out;
}

LidarSweep SweepFromSimFrame(const sim::LidarFrame& frame, const sim::RotatingLidarSpec& spec,
                             const std::optional<Rigid3d>& world_from_sensor) {
  LidarSweep sweep;
  sweep.t_ns = frame.t_ns;
  sweep.rings = spec.rings;
  sweep.ring_elevation_rad = RingElevationsRad(spec);
  sweep.points.reserve(frame.points.size());
  for (const sim::LidarPoint& p : frame.points) {
    SweepPoint q;
    q.p_in_sensor = p.p_local;
    q.range_m = p.range_m;
    q.intensity = p.intensity;
    q.azimuth_rad = p.azimuth_rad;
    q.ring = p.ring;
    q.truth_label = p.label;
    sweep.points.push_back(q);
  }
  sweep.world_from_sensor = world_from_sensor ? *world_from_sensor : Rigid3d(Eigen::Quaterniond::Identity(), spec.position_m);
  sweep.truth_feet_in_world = frame.pedestrian_feet;
  return sweep;
}

}  // namespace ave::lidar
