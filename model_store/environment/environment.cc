#include "model_store/environment/environment.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <numbers>
#include <random>
#include <unordered_map>

#include <Eigen/Dense>
#include <opencv2/imgproc.hpp>

#include "absl/status/status.h"
#include "absl/strings/str_format.h"

namespace ave::model {
namespace {

using Eigen::Vector2d;
using Eigen::Vector3d;
using Eigen::Vector3f;

// 21 bits per axis: +-1e6 cells, i.e. +-200 km at 0.2 m voxels.
uint64_t VoxelKey(const Vector3d& p, double size) {
  const auto axis = [&](double v) { return static_cast<uint64_t>(static_cast<int64_t>(std::floor(v / size)) + (1 << 20)) & 0x1FFFFF; };
  return axis(p.x()) | (axis(p.y()) << 21) | (axis(p.z()) << 42);
}

// Points bucketed in cubes of `size`: neighbours within `size` are in the 27 surrounding cubes.
class NeighbourGrid {
 public:
  NeighbourGrid(const std::vector<Vector3f>& pts, double size) : pts_(pts), size_(size) {
    for (uint32_t i = 0; i < pts.size(); ++i) cells_[VoxelKey(pts[i].cast<double>(), size)].push_back(i);
  }
  template <typename Fn>
  void ForEachWithin(const Vector3f& p, double radius, Fn fn) const {
    const float r2 = static_cast<float>(radius * radius);
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const Vector3d q = p.cast<double>() + size_ * Vector3d(dx, dy, dz);
          const auto it = cells_.find(VoxelKey(q, size_));
          if (it == cells_.end()) continue;
          for (uint32_t j : it->second)
            if ((pts_[j] - p).squaredNorm() <= r2) fn(j);
        }
  }

 private:
  const std::vector<Vector3f>& pts_;
  double size_;
  std::unordered_map<uint64_t, std::vector<uint32_t>> cells_;
};

// Least-squares plane through points (smallest principal axis), normal turned up.
GroundPlane PlaneThrough(const std::vector<Vector3f>& pts, const std::vector<uint32_t>& idx) {
  Vector3d mean = Vector3d::Zero();
  for (uint32_t i : idx) mean += pts[i].cast<double>();
  mean /= static_cast<double>(idx.size());
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (uint32_t i : idx) {
    const Vector3d d = pts[i].cast<double>() - mean;
    cov += d * d.transpose();
  }
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
  GroundPlane g;
  g.normal = eig.eigenvectors().col(0);
  if (g.normal.z() < 0) g.normal = -g.normal;
  g.d = -g.normal.dot(mean);
  g.inliers = static_cast<int>(idx.size());
  g.rms_m = std::sqrt(std::max(0.0, eig.eigenvalues()(0)) / static_cast<double>(idx.size()));
  return g;
}

double Seconds(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

GroundPlane FitPlaneLeastSquares(const std::vector<Vector3f>& points) {
  std::vector<uint32_t> all(points.size());
  for (uint32_t i = 0; i < all.size(); ++i) all[i] = i;
  return points.empty() ? GroundPlane{} : PlaneThrough(points, all);
}

std::string EnvironmentOptions::Check() const {
  if (!(voxel_m > 0)) return "voxel_m must be > 0";
  if (!(background_fraction > 0 && background_fraction <= 1)) return "background_fraction must be in (0, 1]";
  if (!(ground_tolerance_m > 0)) return "ground_tolerance_m must be > 0";
  if (ransac_iterations < 1) return "ransac_iterations must be >= 1";
  if (!(max_ground_tilt_deg > 0 && max_ground_tilt_deg < 90)) return "max_ground_tilt_deg must be in (0, 90)";
  if (!(vegetation_radius_m > 0)) return "vegetation_radius_m must be > 0";
  if (!(hough_cell_m > 0)) return "hough_cell_m must be > 0";
  if (hough_votes < 1) return "hough_votes must be >= 1";
  if (!(min_wall_length_m > 0)) return "min_wall_length_m must be > 0";
  return "";
}

absl::StatusOr<GroundPlane> FitGroundPlaneRansac(const std::vector<Vector3f>& points, const EnvironmentOptions& o) {
  if (const std::string bad = o.Check(); !bad.empty()) return absl::InvalidArgumentError("environment options: " + bad);
  if (points.size() < 3) return absl::FailedPreconditionError(absl::StrFormat("%d points; a plane needs at least 3", points.size()));
  std::mt19937_64 rng(o.seed);
  std::uniform_int_distribution<size_t> pick(0, points.size() - 1);
  const double min_nz = std::cos(o.max_ground_tilt_deg * std::numbers::pi / 180);
  int best_count = 0, degenerate = 0;
  Vector3d best_n = Vector3d::UnitZ();
  double best_d = 0;
  for (int it = 0; it < o.ransac_iterations; ++it) {
    const Vector3d a = points[pick(rng)].cast<double>(), b = points[pick(rng)].cast<double>(), c = points[pick(rng)].cast<double>();
    Vector3d n = (b - a).cross(c - a);
    // Collinear or coincident samples span no plane: skip them (relative to the sample's size).
    const double scale = std::max((b - a).squaredNorm(), (c - a).squaredNorm());
    if (!(n.norm() > 1e-6 * scale) || scale < 1e-12) {
      ++degenerate;
      continue;
    }
    n.normalize();
    if (n.z() < 0) n = -n;
    if (n.z() < min_nz) continue;
    const double d = -n.dot(a);
    int count = 0;
    for (const auto& p : points) count += std::abs(n.dot(p.cast<double>()) + d) <= o.ground_tolerance_m;
    if (count > best_count) best_count = count, best_n = n, best_d = d;
  }
  if (degenerate == o.ransac_iterations)
    return absl::FailedPreconditionError(
        absl::StrFormat("RANSAC: all %d samples degenerate (points collinear or coincident)", o.ransac_iterations));
  if (best_count < 3)
    return absl::FailedPreconditionError(
        absl::StrFormat("RANSAC: no plane within %.0f deg of horizontal has 3 inliers", o.max_ground_tilt_deg));
  std::vector<uint32_t> inliers;
  for (uint32_t i = 0; i < points.size(); ++i)
    if (std::abs(best_n.dot(points[i].cast<double>()) + best_d) <= o.ground_tolerance_m) inliers.push_back(i);
  GroundPlane g = PlaneThrough(points, inliers);
  if (!g.normal.allFinite() || g.normal.z() < min_nz) {
    g.normal = best_n, g.d = best_d;  // inliers on a line: keep the sampled plane
  }
  return g;
}

PointCloud AccumulateBackground(const std::vector<PointCloud>& frames, const EnvironmentOptions& o) {
  PointCloud out;
  if (frames.empty()) return out;
  out.origin = frames.front().origin;
  struct Acc {
    Vector3d sum = Vector3d::Zero();
    double intensity = 0;
    int points = 0, frames = 0, last_frame = -1;
    std::map<uint8_t, int> classes;
  };
  std::unordered_map<uint64_t, Acc> voxels;
  for (int f = 0; f < static_cast<int>(frames.size()); ++f) {
    const PointCloud& frame = frames[f];
    const Vector3d shift = frame.origin - out.origin;
    const bool has_i = frame.intensity.size() == frame.size(), has_c = frame.classification.size() == frame.size();
    for (size_t i = 0; i < frame.size(); ++i) {
      const Vector3d p = frame.xyz[i].cast<double>() + shift;
      if (!p.allFinite()) continue;
      Acc& a = voxels[VoxelKey(p, o.voxel_m)];
      a.sum += p;
      a.intensity += has_i ? frame.intensity[i] : 0;
      ++a.points;
      if (has_c) ++a.classes[frame.classification[i]];
      if (a.last_frame != f) a.last_frame = f, ++a.frames;
    }
  }
  const int need = std::max(1, static_cast<int>(std::ceil(o.background_fraction * frames.size())));
  const bool has_c = frames.front().classification.size() == frames.front().size();
  for (const auto& [key, a] : voxels) {
    if (a.frames < need) continue;
    out.xyz.push_back((a.sum / a.points).cast<float>());
    out.intensity.push_back(static_cast<uint16_t>(std::lround(a.intensity / a.points)));
    if (has_c)
      out.classification.push_back(
          std::max_element(a.classes.begin(), a.classes.end(), [](auto x, auto y) { return x.second < y.second; })->first);
  }
  return out;
}

std::vector<NeighbourStats> PointNeighbourhoods(const PointCloud& cloud, const EnvironmentOptions& o) {
  std::vector<NeighbourStats> out(cloud.size());
  const NeighbourGrid grid(cloud.xyz, o.vegetation_radius_m);
  for (size_t i = 0; i < cloud.size(); ++i) {
    const Vector3f& p = cloud.xyz[i];
    Vector3d mean = Vector3d::Zero();
    Eigen::Matrix3d second = Eigen::Matrix3d::Zero();
    int n = 0;
    grid.ForEachWithin(p, o.vegetation_radius_m, [&](uint32_t j) {
      const Vector3d q = (cloud.xyz[j] - p).cast<double>();
      mean += q;
      second += q * q.transpose();
      ++n;
    });
    out[i].neighbours = n - 1;
    if (n < 4) continue;
    mean /= n;
    const Eigen::Matrix3d cov = second / n - mean * mean.transpose();
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
    const Eigen::Vector3d ev = eig.eigenvalues().cwiseMax(0.0);
    if (ev.sum() <= 1e-12) continue;
    out[i].irregularity = static_cast<float>(ev(0) / ev.sum());
    // Thin and upright (a trunk, a pole): one long vertical axis, the others short.
    out[i].upright_linear = ev(2) > 0 && (ev(2) - ev(1)) / ev(2) > 0.7 && std::abs(eig.eigenvectors().col(2).z()) > 0.8;
  }
  return out;
}

std::vector<EnvClass> ClassifyEnvironment(const PointCloud& cloud, const GroundPlane& ground, const EnvironmentOptions& o) {
  std::vector<EnvClass> out(cloud.size(), EnvClass::kOther);
  const std::vector<NeighbourStats> hood = PointNeighbourhoods(cloud, o);
  const bool has_i = cloud.intensity.size() == cloud.size();
  for (size_t i = 0; i < cloud.size(); ++i) {
    if (std::abs(ground.HeightAbove(cloud.xyz[i].cast<double>())) <= o.ground_tolerance_m) {
      out[i] = EnvClass::kGround;
      continue;
    }
    const bool weak = !has_i || cloud.intensity[i] < o.vegetation_intensity;
    const bool sparse = hood[i].neighbours < o.min_neighbours;
    const bool irregular = hood[i].irregularity > o.vegetation_irregularity;
    if ((weak && (sparse || irregular || hood[i].upright_linear)) || hood[i].irregularity > 3 * o.vegetation_irregularity) out[i] = EnvClass::kVegetation;
  }
  return out;
}

OccupancyImage RasteriseWallPoints(const PointCloud& cloud, const std::vector<EnvClass>& classes, const GroundPlane& ground,
                                   const EnvironmentOptions& o) {
  OccupancyImage img;
  img.cell_m = o.hough_cell_m;
  for (size_t i = 0; i < cloud.size() && i < classes.size(); ++i) {
    if (classes[i] != EnvClass::kOther) continue;
    const Vector3d p = cloud.xyz[i].cast<double>();
    const double h = ground.HeightAbove(p);
    if (h >= o.wall_min_height_m) img.points.emplace_back(p.x(), p.y(), h);
  }
  if (img.points.size() < 10) return img;
  Vector2d lo = img.points.front().head<2>(), hi = lo;
  for (const auto& p : img.points) lo = lo.cwiseMin(p.head<2>()), hi = hi.cwiseMax(p.head<2>());
  const double cell = img.cell_m;
  const double w = (hi.x() - lo.x()) / cell + 3, h = (hi.y() - lo.y()) / cell + 3;
  if (w * h > 64e6) return img;  // > 64 Mpx: the cell is far too small for the extent
  img.min_xy = lo;
  img.width = static_cast<int>(w), img.height = static_cast<int>(h);
  std::vector<uint8_t> count(static_cast<size_t>(img.width) * img.height, 0);
  for (const auto& p : img.points) {
    uint8_t& px = count[img.PixelIndex(p.head<2>())];
    px = static_cast<uint8_t>(std::min(255, px + 1));
  }
  // Two or more points stacked in a pixel: a wall column, not a stray return; dilated by one pixel
  // so the sparse columns of a far wall join into a line.
  cv::Mat counts(img.height, img.width, CV_8U, count.data()), mask;
  cv::threshold(counts, mask, 1, 255, cv::THRESH_BINARY);
  cv::dilate(mask, mask, cv::Mat::ones(3, 3, CV_8U));
  img.pixels.assign(mask.data, mask.data + mask.total());
  return img;
}

std::vector<WallSegment> DetectWalls(const PointCloud& cloud, const std::vector<EnvClass>& classes, const GroundPlane& ground,
                                     const EnvironmentOptions& o) {
  std::vector<WallSegment> walls;
  OccupancyImage img = RasteriseWallPoints(cloud, classes, ground, o);
  if (img.pixels.empty()) return walls;
  const std::vector<Vector3d>& pts = img.points;
  const Vector2d lo = img.min_xy;
  const double cell = img.cell_m;
  const cv::Mat image(img.height, img.width, CV_8U, img.pixels.data());
  std::vector<cv::Vec4i> raw;
  cv::HoughLinesP(image, raw, 1, std::numbers::pi / 360, o.hough_votes, o.min_wall_length_m / cell, o.max_wall_gap_m / cell);
  // Merge collinear pieces, longest first.
  struct Line {
    Vector2d dir, origin;
    double t0, t1;
  };
  std::vector<Line> lines;
  std::sort(raw.begin(), raw.end(), [](const cv::Vec4i& a, const cv::Vec4i& b) {
    return std::hypot(a[2] - a[0], a[3] - a[1]) > std::hypot(b[2] - b[0], b[3] - b[1]);
  });
  for (const auto& s : raw) {
    const Vector2d a = lo + cell * Vector2d(s[0] - 0.5, s[1] - 0.5), b = lo + cell * Vector2d(s[2] - 0.5, s[3] - 0.5);  // pixel 1 = lo
    const Vector2d dir = (b - a).normalized();
    bool merged = false;
    for (Line& l : lines) {
      const Vector2d n(-l.dir.y(), l.dir.x());
      if (std::abs(dir.dot(l.dir)) < std::cos(3 * std::numbers::pi / 180)) continue;
      if (std::abs(n.dot(a - l.origin)) > 0.3 || std::abs(n.dot(b - l.origin)) > 0.3) continue;
      const double ta = l.dir.dot(a - l.origin), tb = l.dir.dot(b - l.origin);
      if (std::min(ta, tb) > l.t1 + o.max_wall_gap_m || std::max(ta, tb) < l.t0 - o.max_wall_gap_m) continue;
      l.t0 = std::min({l.t0, ta, tb}), l.t1 = std::max({l.t1, ta, tb});
      merged = true;
      break;
    }
    if (!merged) lines.push_back({dir, a, 0.0, (b - a).norm()});
  }
  // Refit each line to its points by least squares; the top is the 98th percentile height.
  for (const Line& l : lines) {
    const Vector2d n(-l.dir.y(), l.dir.x());
    std::vector<Vector3d> band;
    for (const auto& p : pts) {
      const double t = l.dir.dot(p.head<2>() - l.origin);
      if (std::abs(n.dot(p.head<2>() - l.origin)) <= 0.25 && t >= l.t0 - 0.5 && t <= l.t1 + 0.5) band.push_back(p);
    }
    if (band.size() < 10) continue;
    Vector2d mean = Vector2d::Zero();
    for (const auto& p : band) mean += p.head<2>();
    mean /= static_cast<double>(band.size());
    Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
    for (const auto& p : band) cov += (p.head<2>() - mean) * (p.head<2>() - mean).transpose();
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(cov);
    const Vector2d dir = eig.eigenvectors().col(1);
    std::vector<double> ts, heights;
    double ss = 0;
    for (const auto& p : band) {
      ts.push_back(dir.dot(p.head<2>() - mean));
      heights.push_back(p.z());
      const double r = Vector2d(-dir.y(), dir.x()).dot(p.head<2>() - mean);
      ss += r * r;
    }
    std::sort(ts.begin(), ts.end());
    std::sort(heights.begin(), heights.end());
    WallSegment wall;
    wall.a_m = mean + ts[ts.size() / 100] * dir;
    wall.b_m = mean + ts[ts.size() - 1 - ts.size() / 100] * dir;
    if ((wall.b_m - wall.a_m).norm() < o.min_wall_length_m) continue;
    const Vector2d mid = 0.5 * (wall.a_m + wall.b_m);
    wall.bottom_z_m = -(ground.normal.x() * mid.x() + ground.normal.y() * mid.y() + ground.d) / ground.normal.z();
    wall.top_z_m = wall.bottom_z_m + heights[heights.size() * 98 / 100];
    wall.support = static_cast<int>(band.size());
    wall.rms_m = std::sqrt(ss / band.size());
    walls.push_back(wall);
  }
  return walls;
}

void AppendWallMeshes(const std::vector<WallSegment>& walls, TriangleMesh& mesh) {
  for (const WallSegment& w : walls) {
    const Vector3f a0(w.a_m.x(), w.a_m.y(), w.bottom_z_m), b0(w.b_m.x(), w.b_m.y(), w.bottom_z_m);
    const Vector3f a1(w.a_m.x(), w.a_m.y(), w.top_z_m), b1(w.b_m.x(), w.b_m.y(), w.top_z_m);
    const Vector3f n = (b0 - a0).cross(a1 - a0).normalized();
    for (const float side : {1.0f, -1.0f}) {
      const uint32_t first = static_cast<uint32_t>(mesh.positions.size());
      for (const Vector3f& p : {a0, b0, b1, a1}) {
        mesh.positions.push_back(p);
        mesh.normals.push_back(side * n);
        mesh.colors.push_back(Vector3f(0.76f, 0.73f, 0.68f));
      }
      if (side > 0) mesh.indices.insert(mesh.indices.end(), {first, first + 1, first + 2, first, first + 2, first + 3});
      else mesh.indices.insert(mesh.indices.end(), {first, first + 2, first + 1, first, first + 3, first + 2});
      for (int t = 0; t < 2; ++t) mesh.triangle_material.push_back(SurfaceMaterial::kWall), mesh.triangle_object.push_back(-1);
    }
  }
}

absl::StatusOr<EnvironmentModel> ReconstructEnvironment(const std::vector<PointCloud>& frames, const EnvironmentOptions& o) {
  if (const std::string bad = o.Check(); !bad.empty()) return absl::InvalidArgumentError("environment options: " + bad);
  if (frames.empty()) return absl::InvalidArgumentError("no LiDAR frames to accumulate");
  EnvironmentModel m;
  auto t0 = std::chrono::steady_clock::now();
  m.background = AccumulateBackground(frames, o);
  m.accumulate_s = Seconds(t0);
  t0 = std::chrono::steady_clock::now();
  absl::StatusOr<GroundPlane> ground = FitGroundPlaneRansac(m.background.xyz, o);
  if (!ground.ok()) return ground.status();
  m.ground = *ground;
  m.ransac_s = Seconds(t0);
  t0 = std::chrono::steady_clock::now();
  m.classes = ClassifyEnvironment(m.background, m.ground, o);
  m.vegetation_s = Seconds(t0);
  t0 = std::chrono::steady_clock::now();
  m.walls = DetectWalls(m.background, m.classes, m.ground, o);
  m.hough_s = Seconds(t0);
  t0 = std::chrono::steady_clock::now();
  m.mesh.origin = m.background.origin;
  AppendWallMeshes(m.walls, m.mesh);
  m.mesh_s = Seconds(t0);
  return m;
}

}  // namespace ave::model
