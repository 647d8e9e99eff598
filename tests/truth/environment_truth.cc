#include "tests/truth/environment_truth.h"

#include <cmath>
#include <numbers>
#include <set>
#include <tuple>

#include "absl/strings/str_format.h"
#include "sensor_agent/sim/rotating_lidar.h"
#include "sensor_agent/sim/scenario.h"
#include "sensor_agent/sim/sim_camera.h"

namespace ave::model::testing {

using Eigen::Vector2d;

absl::StatusOr<LidarFrames> SimulateLidarFrames(const std::string& scenario_name, int frames, double step_s) {
  absl::StatusOr<sim::Scenario> scenario = sim::LoadScenario(scenario_name);
  if (!scenario.ok()) return scenario.status();
  if (scenario->rotating_lidars.empty()) return absl::NotFoundError(scenario->label + ": no rotating_lidar sensor");
  const sim::RotatingLidarSpec& spec = scenario->rotating_lidars.front();
  LidarFrames out;
  out.site = scenario->world;
  out.sensor_m = spec.position_m;
  for (int f = 0; f < frames; ++f) {
    const sim::LidarFrame frame = sim::SimulateRotatingLidarFrame(scenario->world, spec, scenario->effects, scenario->seed, f * step_s);
    PointCloud cloud;
    cloud.origin = scenario->world.origin;
    for (const sim::LidarPoint& p : frame.points) {
      cloud.xyz.push_back(p.p_local + spec.position_m.cast<float>());
      cloud.intensity.push_back(static_cast<uint16_t>(std::lround(p.intensity)));
      uint8_t code = kEnvTruthObject;
      if (p.label == sim::kGroundId) code = kEnvTruthGround;
      else if (p.label == sim::kLidarVegetationId) code = kEnvTruthVegetation;
      else if (sim::IsBuildingId(p.label)) code = kEnvTruthBuilding;
      else if (sim::IsMoverId(p.label)) code = kEnvTruthMover;
      cloud.classification.push_back(code);
    }
    out.frames.push_back(std::move(cloud));
  }
  return out;
}

namespace {

struct Face {
  Vector2d a, b;
  double top_z;
};

std::vector<Face> TrueFaces(const scene::SyntheticCampus& site) {
  std::vector<Face> faces;
  for (const auto& b : site.buildings) {
    const double top = site.BuildingGround(b) + b.height_m;
    for (const auto& part : b.Parts()) {
      const std::vector<Vector2d> c = scene::FootprintCorners(part);
      for (size_t i = 0; i < c.size(); ++i) faces.push_back({c[i], c[(i + 1) % c.size()], top});
    }
  }
  return faces;
}

double LineDistance(const Face& f, const Vector2d& p) {
  const Vector2d d = (f.b - f.a).normalized();
  return std::abs(d.x() * (p - f.a).y() - d.y() * (p - f.a).x());
}

}  // namespace

EnvironmentScore ScoreEnvironment(const LidarFrames& truth, const EnvironmentModel& model, double voxel_m) {
  EnvironmentScore s;
  const PointCloud& bg = model.background;
  s.background_points = static_cast<int>(bg.size());
  for (size_t i = 0; i < bg.size() && i < bg.classification.size() && i < model.classes.size(); ++i) {
    const bool removed = model.classes[i] == EnvClass::kVegetation;
    if (bg.classification[i] == kEnvTruthVegetation) {
      ++s.vegetation_points;
      s.vegetation_removed += removed;
    } else {
      ++s.other_points;
      s.other_removed += removed;
      s.mover_points += bg.classification[i] == kEnvTruthMover;
    }
  }
  s.vegetation_removal_rate = s.vegetation_points ? static_cast<double>(s.vegetation_removed) / s.vegetation_points : 0;
  s.false_removal_rate = s.other_points ? static_cast<double>(s.other_removed) / s.other_points : 0;
  std::set<std::tuple<long, long, long>> seen;
  for (const PointCloud& f : truth.frames)
    for (size_t i = 0; i < f.size(); ++i)
      if (f.classification[i] == kEnvTruthVegetation)
        seen.emplace(std::lround(std::floor(f.xyz[i].x() / voxel_m)), std::lround(std::floor(f.xyz[i].y() / voxel_m)),
                     std::lround(std::floor(f.xyz[i].z() / voxel_m)));
  s.vegetation_observed_voxels = static_cast<int>(seen.size());
  s.overall_vegetation_removal_rate =
      seen.empty() ? 1.0 : 1.0 - static_cast<double>(s.vegetation_points - s.vegetation_removed) / static_cast<double>(seen.size());
  std::vector<Eigen::Vector3f> true_ground;
  for (size_t i = 0; i < bg.size() && i < bg.classification.size(); ++i)
    if (bg.classification[i] == kEnvTruthGround) true_ground.push_back(bg.xyz[i]);
  if (true_ground.size() >= 3) s.reference_ground_normal = FitPlaneLeastSquares(true_ground).normal;
  s.ground_angle_deg =
      std::acos(std::clamp(s.reference_ground_normal.dot(model.ground.normal), -1.0, 1.0)) * 180 / std::numbers::pi;

  const std::vector<Face> faces = TrueFaces(truth.site);
  std::set<size_t> found;
  s.walls = static_cast<int>(model.walls.size());
  for (const WallSegment& w : model.walls) {
    const Vector2d dir = (w.b_m - w.a_m).normalized(), mid = 0.5 * (w.a_m + w.b_m);
    int best = -1;
    double best_d = 1.0;
    for (size_t f = 0; f < faces.size(); ++f) {
      const Vector2d fd = (faces[f].b - faces[f].a).normalized();
      if (std::abs(fd.dot(dir)) < std::cos(10 * std::numbers::pi / 180)) continue;
      const double t = fd.dot(mid - faces[f].a), len = (faces[f].b - faces[f].a).norm();
      if (t < -1 || t > len + 1) continue;
      const double d = LineDistance(faces[f], mid);
      if (d < best_d) best_d = d, best = static_cast<int>(f);
    }
    if (best < 0) continue;
    ++s.walls_matched;
    found.insert(best);
    const Face& f = faces[best];
    const double pos = 0.5 * (LineDistance(f, w.a_m) + LineDistance(f, w.b_m));
    const double ang = std::acos(std::min(1.0, std::abs((f.b - f.a).normalized().dot(dir)))) * 180 / std::numbers::pi;
    s.position_err_m_mean += pos, s.position_err_m_max = std::max(s.position_err_m_max, pos);
    s.angle_err_deg_mean += ang, s.angle_err_deg_max = std::max(s.angle_err_deg_max, ang);
    s.top_err_m_mean += std::abs(w.top_z_m - f.top_z);
  }
  s.faces_found = static_cast<int>(found.size());
  if (s.walls_matched) {
    s.position_err_m_mean /= s.walls_matched, s.angle_err_deg_mean /= s.walls_matched, s.top_err_m_mean /= s.walls_matched;
  }
  return s;
}

}  // namespace ave::model::testing
