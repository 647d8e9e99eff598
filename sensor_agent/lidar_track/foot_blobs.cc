#include "sensor_agent/lidar_track/foot_blobs.h"

#include <algorithm>
#include <cmath>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "absl/strings/str_cat.h"
#include "model_store/environment/environment.h"

namespace ave::lidar_track {

absl::StatusOr<GroundFrame> GroundFrameFromPlane(const Eigen::Vector3d& normal_in_sensor, double d) {
  const double norm = normal_in_sensor.norm();
  if (!normal_in_sensor.allFinite() || !std::isfinite(d) || !(norm > 1e-9)) {
    return absl::InvalidArgumentError("ground plane: the normal must be finite and non-zero");
  }
  Eigen::Vector3d n = normal_in_sensor / norm;
  d /= norm;
  if (std::abs(d) < 0.01) return absl::InvalidArgumentError(absl::StrCat("ground plane: runs through the sensor (d = ", d, " m)"));
  if (d < 0) {  // the sensor (origin) lies on the normal's side: n . 0 + d > 0
    n = -n;
    d = -d;
  }
  GroundFrame g;
  g.normal_in_sensor = n;
  g.d = d;
  Eigen::Vector3d x = Eigen::Vector3d::UnitX() - n * n.x();
  if (x.norm() < 1e-6) x = Eigen::Vector3d::UnitY() - n * n.y();
  x.normalize();
  const Eigen::Vector3d y = n.cross(x);
  Eigen::Matrix3d ground_R_sensor;
  ground_R_sensor.row(0) = x.transpose();
  ground_R_sensor.row(1) = y.transpose();
  ground_R_sensor.row(2) = n.transpose();
  const Eigen::Vector3d origin_in_sensor = -d * n;  // the sensor's foot on the plane
  g.ground_from_sensor = Rigid3d(Eigen::Quaterniond(ground_R_sensor), -(ground_R_sensor * origin_in_sensor));
  return g;
}

absl::StatusOr<GroundFrame> FitGroundFrame(const lidar::LidarSweep& sweep, const std::vector<uint8_t>& exclude, double tolerance_m,
                                           double max_tilt_deg) {
  std::vector<Eigen::Vector3f> below, all;
  for (size_t i = 0; i < sweep.points.size(); ++i) {
    const lidar::SweepPoint& p = sweep.points[i];
    if (!(p.range_m > 0) || !p.p_in_sensor.allFinite() || (i < exclude.size() && exclude[i])) continue;
    all.push_back(p.p_in_sensor);
    if (p.p_in_sensor.z() < 0) below.push_back(p.p_in_sensor);
  }
  model::EnvironmentOptions o;
  o.ground_tolerance_m = tolerance_m;
  o.max_ground_tilt_deg = max_tilt_deg;
  absl::StatusOr<model::GroundPlane> plane = model::FitGroundPlaneRansac(below.size() >= 100 ? below : all, o);
  if (!plane.ok()) return absl::FailedPreconditionError(absl::StrCat("LiDAR ground plane: ", plane.status().message()));
  return GroundFrameFromPlane(plane->normal, plane->d);
}

std::string BlobOptions::Check() const {
  if (!(cell_m > 0.01 && cell_m <= 1)) return "cell_m: must be in (0.01, 1]";
  if (!(half_extent_m > cell_m && half_extent_m / cell_m <= 8000)) return "half_extent_m: must be > cell_m and at most 8000 cells";
  if (!(max_height_m > min_height_m)) return "max_height_m: must be > min_height_m";
  if (closing_radius_cells < 0 || closing_radius_cells > 10) return "closing_radius_cells: must be in [0, 10]";
  if (!(min_area_m2 >= 0 && max_area_m2 > min_area_m2)) return "min_area_m2, max_area_m2: need 0 <= min < max";
  if (min_points < 1) return "min_points: must be >= 1";
  if (!(split_hint_radius_m >= 0)) return "split_hint_radius_m: must be >= 0";
  return "";
}

namespace {

struct Sums {
  double w = 0, wx = 0, wy = 0, top = -1e9;
  int n = 0;
  void Add(const Eigen::Vector3f& q) {
    const double h = std::clamp(static_cast<double>(q.z()), 0.1, 2.0);
    w += h;
    wx += h * q.x();
    wy += h * q.y();
    top = std::max(top, static_cast<double>(q.z()));
    ++n;
  }
};

}  // namespace

BlobDetection DetectFootBlobs(const lidar::LidarSweep& sweep, const std::vector<uint8_t>& foreground, const GroundFrame& ground,
                              const std::vector<Eigen::Vector2d>& split_hints, const BlobOptions& o) {
  BlobDetection out;
  const size_t n_points = sweep.points.size();
  out.blob_of_point.assign(n_points, -1);
  const Eigen::Matrix3f R = ground.ground_from_sensor.rotation.toRotationMatrix().cast<float>();
  const Eigen::Vector3f t = ground.ground_from_sensor.translation.cast<float>();
  const int grid = static_cast<int>(std::ceil(2 * o.half_extent_m / o.cell_m));
  const float inv_cell = static_cast<float>(1 / o.cell_m), ext = static_cast<float>(o.half_extent_m);
  auto cell_of = [&](float x, float y, int& cx, int& cy) {
    cx = static_cast<int>(std::floor((x + ext) * inv_cell));
    cy = static_cast<int>(std::floor((y + ext) * inv_cell));
    return cx >= 0 && cy >= 0 && cx < grid && cy < grid;
  };
  // Foreground points in the height band, in the ground frame, and the lattice box they span.
  std::vector<int32_t> fg_index;
  std::vector<Eigen::Vector3f> fg_q;
  int x0 = grid, y0 = grid, x1 = -1, y1 = -1;
  for (size_t i = 0; i < n_points && i < foreground.size(); ++i) {
    if (!foreground[i]) continue;
    const Eigen::Vector3f q = R * sweep.points[i].p_in_sensor + t;
    int cx, cy;
    if (!(q.z() >= o.min_height_m && q.z() <= o.max_height_m) || !cell_of(q.x(), q.y(), cx, cy)) continue;
    fg_index.push_back(static_cast<int32_t>(i));
    fg_q.push_back(q);
    x0 = std::min(x0, cx), y0 = std::min(y0, cy), x1 = std::max(x1, cx), y1 = std::max(y1, cy);
  }
  if (fg_index.empty()) return out;
  const int margin = o.closing_radius_cells + 1;
  x0 = std::max(0, x0 - margin), y0 = std::max(0, y0 - margin);
  x1 = std::min(grid - 1, x1 + margin), y1 = std::min(grid - 1, y1 + margin);
  cv::Mat mask = cv::Mat::zeros(y1 - y0 + 1, x1 - x0 + 1, CV_8U);
  for (const Eigen::Vector3f& q : fg_q) {
    int cx, cy;
    cell_of(q.x(), q.y(), cx, cy);
    mask.at<uint8_t>(cy - y0, cx - x0) = 255;
  }
  if (o.closing_radius_cells > 0) {
    const int k = 2 * o.closing_radius_cells + 1;
    cv::morphologyEx(mask, mask, cv::MORPH_CLOSE, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(k, k)));
  }
  cv::Mat labels, stats, centroids;
  const int n_labels = cv::connectedComponentsWithStats(mask, labels, stats, centroids, 8, CV_32S);
  std::vector<Sums> sums(n_labels);
  for (const Eigen::Vector3f& q : fg_q) {
    int cx, cy;
    cell_of(q.x(), q.y(), cx, cy);
    sums[labels.at<int32_t>(cy - y0, cx - x0)].Add(q);
  }
  const double cell_area = o.cell_m * o.cell_m;
  // Which split hints fall in which component.
  std::vector<std::vector<int>> hints_of(n_labels);
  const int hint_r = static_cast<int>(std::ceil(o.split_hint_radius_m / o.cell_m));
  for (size_t h = 0; h < split_hints.size(); ++h) {
    int cx, cy;
    if (!split_hints[h].allFinite() || !cell_of(static_cast<float>(split_hints[h].x()), static_cast<float>(split_hints[h].y()), cx, cy)) continue;
    int found = 0;
    for (int dy = -hint_r; dy <= hint_r && !found; ++dy) {
      for (int dx = -hint_r; dx <= hint_r && !found; ++dx) {
        const int x = cx + dx - x0, y = cy + dy - y0;
        if (x < 0 || y < 0 || x >= mask.cols || y >= mask.rows) continue;
        found = labels.at<int32_t>(y, x);
      }
    }
    if (found > 0) hints_of[found].push_back(static_cast<int>(h));
  }
  // Accepted components: blob index per component (or the first of its split parts).
  std::vector<int> first_blob(n_labels, -1);
  for (int l = 1; l < n_labels; ++l) {
    const double area = stats.at<int32_t>(l, cv::CC_STAT_AREA) * cell_area;
    const Sums& s = sums[l];
    const bool split = hints_of[l].size() >= 2;
    if (s.n < o.min_points || area < o.min_area_m2 || (!split && area > o.max_area_m2) || s.top < o.min_top_m) continue;
    first_blob[l] = static_cast<int>(out.blobs.size());
    if (!split) {
      out.blobs.push_back({Eigen::Vector2d(s.wx / s.w, s.wy / s.w), area, s.top, s.n, -1});
      continue;
    }
    for (const int h : hints_of[l]) out.blobs.push_back({split_hints[h], 0, 0, 0, h});
  }
  auto nearest_part = [&](int l, const Eigen::Vector3f& q) {
    const std::vector<int>& hs = hints_of[l];
    int best = 0;
    double best_d = 1e300;
    for (size_t k = 0; k < hs.size(); ++k) {
      const double dd = (split_hints[hs[k]] - Eigen::Vector2d(q.x(), q.y())).squaredNorm();
      if (dd < best_d) best_d = dd, best = static_cast<int>(k);
    }
    return first_blob[l] + best;
  };
  // Split parts: centres and sizes from their own points.
  std::vector<Sums> part(out.blobs.size());
  for (const Eigen::Vector3f& q : fg_q) {
    int cx, cy;
    cell_of(q.x(), q.y(), cx, cy);
    const int l = labels.at<int32_t>(cy - y0, cx - x0);
    if (first_blob[l] < 0 || hints_of[l].size() < 2) continue;
    part[nearest_part(l, q)].Add(q);
  }
  for (int l = 1; l < n_labels; ++l) {
    if (first_blob[l] < 0 || hints_of[l].size() < 2) continue;
    const double area = stats.at<int32_t>(l, cv::CC_STAT_AREA) * cell_area;
    for (size_t k = 0; k < hints_of[l].size(); ++k) {
      FootBlob& b = out.blobs[first_blob[l] + k];
      const Sums& s = part[first_blob[l] + k];
      if (s.n > 0) b.xy_m = Eigen::Vector2d(s.wx / s.w, s.wy / s.w);
      b.points = s.n;
      b.top_m = s.top;
      b.area_m2 = area * s.n / std::max(1, sums[l].n);
    }
  }
  // The LiDAR sees a person's near side only: move the centre away from the sensor's foot (the
  // ground frame's origin) by about half a body depth.
  for (FootBlob& b : out.blobs) {
    const double r = b.xy_m.norm();
    if (r > 1e-3) b.xy_m *= (r + o.surface_offset_m) / r;
  }
  // Vertical back-projection: every point above a blob's cells, within the label band.
  for (size_t i = 0; i < n_points; ++i) {
    const lidar::SweepPoint& p = sweep.points[i];
    if (!(p.range_m > 0) || !p.p_in_sensor.allFinite()) continue;
    const Eigen::Vector3f q = R * p.p_in_sensor + t;
    int cx, cy;
    if (!(q.z() >= o.label_min_height_m && q.z() <= o.label_max_height_m) || !cell_of(q.x(), q.y(), cx, cy)) continue;
    if (cx < x0 || cy < y0 || cx > x1 || cy > y1) continue;
    const int l = labels.at<int32_t>(cy - y0, cx - x0);
    if (l <= 0 || first_blob[l] < 0) continue;
    out.blob_of_point[i] = hints_of[l].size() >= 2 ? nearest_part(l, q) : first_blob[l];
  }
  return out;
}

}  // namespace ave::lidar_track
