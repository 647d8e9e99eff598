#include "sensor_agent/lidar_track/lidar_track_truth.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <random>

#include "sensor_agent/lidar_track/assignment.h"
#include "sensor_agent/sim/sim_camera.h"

namespace ave::lidar_track::testing {

sim::Scenario CrowdedCourtyard(sim::Scenario s) {
  s.name += "-crowd";
  auto add = [&](uint32_t id, std::vector<Eigen::Vector2d> path, double speed, double offset) {
    scene::Mover m;
    m.id = id;
    m.kind = scene::MoverKind::kPerson;
    m.loop_m = std::move(path);
    m.speed_mps = speed;
    m.start_offset_m = offset;
    m.color = Eigen::Vector3f(0.3f + 0.02f * (id % 30), 0.5f, 0.6f);
    s.world.movers.push_back(m);
  };
  // Ten more crossing the yard on diagonals and across, at staggered starts.
  add(101, {{-19, -12}, {19, 12}}, 1.25, 3.0);
  add(102, {{19, -12}, {-19, 12}}, 1.35, 9.0);
  add(103, {{-19, 3}, {19, 3}}, 1.15, 14.0);
  add(104, {{3, -14}, {3, 14}}, 1.45, 2.0);
  add(105, {{-12, -14}, {12, 14}}, 1.05, 20.0);
  add(106, {{12, -14}, {-12, 14}}, 1.5, 6.0);
  add(107, {{-19, -3}, {19, -3}}, 1.3, 25.0);
  add(108, {{-8, -14}, {-8, 14}}, 1.2, 11.0);
  add(109, {{8, 14}, {8, -14}}, 1.1, 17.0);
  add(110, {{-15, 13}, {15, -13}}, 1.4, 30.0);
  // Loitering: 0.1 m/s to and fro over 3 m (a person standing still since before the sensor
  // started is background to any background model; the walk-in-and-stand case is a gtest).
  add(120, {{6, 6}, {9, 6}}, 0.1, 0);
  // Two walking shoulder to shoulder.
  add(121, {{-18, -5.35}, {18, -5.35}}, 1.2, 4.0);
  add(122, {{-18, -6.05}, {18, -6.05}}, 1.2, 4.0);
  return s;
}

Eigen::Vector2d SyntheticPerson::At(double t_s) const {
  if (path.empty()) return Eigen::Vector2d::Zero();
  if (t_s <= path.front().first) return path.front().second;
  for (size_t k = 1; k < path.size(); ++k) {
    if (t_s <= path[k].first) {
      const double u = (t_s - path[k - 1].first) / std::max(1e-9, path[k].first - path[k - 1].first);
      return (1 - u) * path[k - 1].second + u * path[k].second;
    }
  }
  return path.back().second;
}

lidar::LidarSweep MakeSyntheticSweep(const SyntheticSite& site, double t_s, uint64_t seed) {
  lidar::LidarSweep sweep;
  sweep.t_ns = static_cast<int64_t>(std::llround(t_s * 1e9));
  sweep.rings = site.rings;
  const double pi = std::numbers::pi;
  const Eigen::Matrix3d site_R_sensor = Eigen::AngleAxisd(site.tilt_deg * pi / 180, Eigen::Vector3d::UnitX()).toRotationMatrix();
  const Eigen::Vector3d o(0, 0, site.sensor_height_m);
  sweep.world_from_sensor = Rigid3d(Eigen::Quaterniond(site_R_sensor), site.world_from_site_m + o);
  std::vector<Eigen::Vector2d> centre(site.people.size());
  for (size_t k = 0; k < site.people.size(); ++k) {
    centre[k] = site.people[k].At(t_s);
    sweep.truth_feet_in_world.emplace_back(sim::kMoverIdBase + site.people[k].id,
                                           site.world_from_site_m + Eigen::Vector3d(centre[k].x(), centre[k].y(), 0));
  }
  std::mt19937_64 rng(seed * 1000003 + static_cast<uint64_t>(sweep.t_ns));
  std::normal_distribution<double> noise(0, site.noise_sigma_m);
  for (int r = 0; r < site.rings; ++r) {
    const double deg = site.rings == 1 ? site.fov_up_deg : site.fov_up_deg - r * (site.fov_up_deg - site.fov_down_deg) / (site.rings - 1);
    sweep.ring_elevation_rad.push_back(static_cast<float>(deg * pi / 180));
  }
  for (int c = 0; c < site.cols; ++c) {
    const double az = 2 * pi * c / site.cols;
    for (int r = 0; r < site.rings; ++r) {
      const double el = sweep.ring_elevation_rad[r];
      const Eigen::Vector3d d_sensor(std::cos(el) * std::sin(az), std::cos(el) * std::cos(az), std::sin(el));
      const Eigen::Vector3d d = site_R_sensor * d_sensor;
      double best = std::numeric_limits<double>::infinity();
      uint32_t label = 0;
      if (d.z() < -1e-9) {
        best = -o.z() / d.z();
        label = sim::kGroundId;
      }
      // Inside of the wall cylinder: the positive root of |o_xy + t d_xy| = R.
      const double a = d.head<2>().squaredNorm();
      if (a > 1e-12) {
        const double t_wall = std::sqrt(site.wall_radius_m * site.wall_radius_m / a);
        const double z = o.z() + t_wall * d.z();
        if (t_wall < best && z >= 0 && z <= site.wall_height_m) best = t_wall, label = sim::kBuildingIdBase;
        for (size_t k = 0; k < site.people.size(); ++k) {
          const Eigen::Vector2d m = o.head<2>() - centre[k];
          const double b = m.dot(d.head<2>()), cc = m.squaredNorm() - site.people[k].radius_m * site.people[k].radius_m;
          const double disc = b * b - a * cc;
          if (disc < 0) continue;
          const double t_hit = (-b - std::sqrt(disc)) / a;
          const double zh = o.z() + t_hit * d.z();
          if (t_hit > 0 && t_hit < best && zh >= 0 && zh <= site.people[k].height_m) best = t_hit, label = sim::kMoverIdBase + site.people[k].id;
        }
      }
      if (!(best <= site.max_range_m)) continue;
      const double range = best + noise(rng);
      lidar::SweepPoint p;
      p.p_in_sensor = (d_sensor * range).cast<float>();
      p.range_m = static_cast<float>(range);
      p.intensity = 100;
      p.azimuth_rad = static_cast<float>(az);
      p.ring = static_cast<uint16_t>(r);
      p.truth_label = label;
      sweep.points.push_back(p);
    }
  }
  return sweep;
}

void MotEvaluator::Add(const lidar::LidarSweep& sweep, const std::vector<lidar::FootTrack>& tracks, const Rigid3d& world_from_ground) {
  ++s_.sweeps;
  if (last_t_ns_ >= 0 && sweep.t_ns > last_t_ns_) sweep_s_ = (sweep.t_ns - last_t_ns_) * 1e-9;
  last_t_ns_ = sweep.t_ns;
  std::map<uint32_t, int> points_of;
  for (const lidar::SweepPoint& p : sweep.points) {
    if (sim::IsMoverId(p.truth_label)) ++points_of[p.truth_label];
  }
  const auto& truth = sweep.truth_feet_in_world;
  std::vector<Eigen::Vector2d> hyp(tracks.size());
  for (size_t h = 0; h < tracks.size(); ++h) {
    hyp[h] = (world_from_ground * Eigen::Vector3d(tracks[h].xy_m.x(), tracks[h].xy_m.y(), 0)).head<2>();
  }
  const int ng = static_cast<int>(truth.size()), nh = static_cast<int>(tracks.size());
  std::vector<int> hyp_of(ng, -1), gt_of(nh, -1);
  auto dist = [&](int g, int h) { return (truth[g].second.head<2>() - hyp[h]).norm(); };
  // Keep last sweep's correspondences that still hold (CLEAR MOT), then the optimal assignment.
  for (int g = 0; g < ng; ++g) {
    auto it = last_match_.find(truth[g].first);
    if (it == last_match_.end()) continue;
    for (int h = 0; h < nh; ++h) {
      if (tracks[h].id == it->second && gt_of[h] < 0 && dist(g, h) < options_.match_m) hyp_of[g] = h, gt_of[h] = g;
    }
  }
  Eigen::MatrixXd cost = Eigen::MatrixXd::Constant(ng, nh, std::numeric_limits<double>::infinity());
  for (int g = 0; g < ng; ++g) {
    for (int h = 0; h < nh; ++h) {
      if (hyp_of[g] < 0 && gt_of[h] < 0 && dist(g, h) < options_.match_m) cost(g, h) = dist(g, h);
    }
  }
  const Assignment a = SolveAssignment(cost);
  for (int g = 0; g < ng; ++g) {
    if (a.col_of_row[g] >= 0) hyp_of[g] = a.col_of_row[g], gt_of[a.col_of_row[g]] = g;
  }
  for (int g = 0; g < ng; ++g) {
    const uint32_t label = truth[g].first;
    const bool visible = points_of[label] >= options_.min_visible_points;
    const int h = hyp_of[g];
    if (!visible) {
      if (h >= 0) last_match_[label] = tracks[h].id;
      continue;
    }
    Person& p = people_[label];
    ++p.visible;
    ++s_.truth;
    if (h < 0) {
      ++s_.misses;
      p.was_tracked = false;
      continue;
    }
    ++s_.hits;
    ++p.tracked;
    dist_sum_ += dist(g, h);
    auto it = last_match_.find(label);
    if (it != last_match_.end() && it->second != tracks[h].id) ++s_.id_switches;
    last_match_[label] = tracks[h].id;
    if (!p.was_tracked && p.ever_tracked) ++p.fragments;
    p.was_tracked = p.ever_tracked = true;
  }
  for (int h = 0; h < nh; ++h) {
    if (gt_of[h] < 0) ++s_.false_positives;
  }
}

MotScores MotEvaluator::Scores() const {
  MotScores s = s_;
  s.mota = s.truth ? 1.0 - static_cast<double>(s.misses + s.false_positives + s.id_switches) / s.truth : 1.0;
  s.motp_m = s.hits ? dist_sum_ / s.hits : 0;
  for (const auto& [label, p] : people_) {
    if (p.visible == 0) continue;
    ++s.people;
    s.fragmentations += p.fragments;
    const double share = static_cast<double>(p.tracked) / p.visible;
    s.mostly_tracked += share >= 0.8;
    s.mostly_lost += share < 0.2;
  }
  s.mostly_tracked_share = s.people ? static_cast<double>(s.mostly_tracked) / s.people : 0;
  s.person_minutes = s.truth * sweep_s_ / 60;
  s.id_switches_per_person_minute = s.person_minutes > 0 ? s.id_switches / s.person_minutes : 0;
  return s;
}

void PointScores::Add(const lidar::LidarSweep& sweep, const std::vector<uint8_t>& foreground) {
  for (size_t i = 0; i < sweep.points.size(); ++i) {
    const bool truth = sim::IsMoverId(sweep.points[i].truth_label);
    const bool fg = i < foreground.size() && foreground[i];
    tp += truth && fg;
    fp += !truth && fg;
    fn += truth && !fg;
  }
}

}  // namespace ave::lidar_track::testing
