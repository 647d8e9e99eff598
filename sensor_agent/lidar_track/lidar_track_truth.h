#pragma once
// Test and benchmark support for the LiDAR people tracker (not linked into the agent): sweeps from
// the simulator (sim::LidarFrame -> LidarSweep) and from a tiny analytic scene, the crowded
// courtyard variant, and CLEAR-MOT and per-point scores against the truth the sweeps carry.
#include <cstdint>
#include <map>
#include <set>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "model_store/geometry/rigid3.h"
#include "sensor_agent/lidar/lidar_types.h"
#include "sensor_agent/lidar/sim_sweep.h"
#include "sensor_agent/sim/rotating_lidar.h"
#include "sensor_agent/sim/scenario.h"

namespace ave::lidar_track::testing {

// The simulator's frame as a sweep (sensor_agent/lidar/sim_sweep.h).
using lidar::SweepFromSimFrame;

// The courtyard plus 10 more people crossing, one loitering at 0.1 m/s (id 120, near (6, 6)) and two
// walking shoulder to shoulder (ids 121, 122, 0.7 m apart): 25 people. Keeps the courtyard's effects
// (waving_vegetation among them).
sim::Scenario CrowdedCourtyard(sim::Scenario courtyard);

// A small analytic scene for fast tests: flat ground (z = 0 in the site frame), a cylindrical wall
// around the sensor, and people as vertical cylinders moving between keyframes.
struct SyntheticPerson {
  uint32_t id = 1;                                         // truth label kMoverIdBase + id
  std::vector<std::pair<double, Eigen::Vector2d>> path;    // (t_s, xy in the site), linear, clamped
  double radius_m = 0.25, height_m = 1.8;
  Eigen::Vector2d At(double t_s) const;
};
struct SyntheticSite {
  int rings = 16, cols = 360;
  double fov_up_deg = 2, fov_down_deg = -24.8;
  double sensor_height_m = 2;
  double tilt_deg = 0;                         // sensor rolled about its x axis
  Eigen::Vector3d world_from_site_m = Eigen::Vector3d::Zero();  // site origin in the world
  double wall_radius_m = 25, wall_height_m = 4;
  double max_range_m = 100;
  double noise_sigma_m = 0.01;
  std::vector<SyntheticPerson> people;
};
lidar::LidarSweep MakeSyntheticSweep(const SyntheticSite& site, double t_s, uint64_t seed);

// CLEAR-MOT against the sweep's truth feet. A person is visible in a sweep when it has at least
// `min_visible_points` points there; only visible people count as misses, and a track matched to a
// hidden person (coasting behind an occluder) counts as neither hit nor false positive.
struct MotOptions {
  double match_m = 1.0;
  int min_visible_points = 10;
};
struct MotScores {
  int sweeps = 0, truth = 0, hits = 0, false_positives = 0, misses = 0, id_switches = 0, fragmentations = 0;
  int people = 0, mostly_tracked = 0, mostly_lost = 0;  // >= 80 % / < 20 % of their visible sweeps tracked
  double mota = 0, motp_m = 0, mostly_tracked_share = 0, person_minutes = 0, id_switches_per_person_minute = 0;
};
class MotEvaluator {
 public:
  explicit MotEvaluator(MotOptions options = {}) : options_(options) {}
  // `tracks` in the ground frame placed by world_from_ground; compared in the world's x-y.
  void Add(const lidar::LidarSweep& sweep, const std::vector<lidar::FootTrack>& tracks, const Rigid3d& world_from_ground);
  MotScores Scores() const;

 private:
  struct Person {
    int visible = 0, tracked = 0, fragments = 0;
    bool was_tracked = false, ever_tracked = false;
  };
  MotOptions options_;
  MotScores s_;
  double dist_sum_ = 0, sweep_s_ = 0.1;
  int64_t last_t_ns_ = -1;
  std::map<uint32_t, uint32_t> last_match_;  // truth label -> track id
  std::map<uint32_t, Person> people_;
};

// Per-point foreground precision and recall: a point is truly foreground when its truth label is a
// mover's (sim::kMoverIdBase + id).
struct PointScores {
  int64_t tp = 0, fp = 0, fn = 0;
  void Add(const lidar::LidarSweep& sweep, const std::vector<uint8_t>& foreground);
  double Precision() const { return tp + fp ? static_cast<double>(tp) / (tp + fp) : 1; }
  double Recall() const { return tp + fn ? static_cast<double>(tp) / (tp + fn) : 1; }
};

}  // namespace ave::lidar_track::testing
