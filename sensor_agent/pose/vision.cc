#include "sensor_agent/pose/vision.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <optional>

#include <Eigen/Eigenvalues>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

#include "model_store/geometry/bvh.h"

namespace ave::pose {
namespace {

using Clock = std::chrono::steady_clock;
double MsSince(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

constexpr double kBorder_px = 8;       // predictions closer than this to the image edge are skipped
constexpr double kChamferCap_px = 8;   // coarse pass: edge distances are truncated here
constexpr double kEdgeSample_px = 4;   // coarse pass: spacing of samples along a predicted model edge
constexpr double kCoarseMatch_px = 6;  // coarse pass: match radius once the offset is applied
constexpr double kMinSegment_px = 20;  // line segments shorter than this are ignored
constexpr double kMaxAngle_rad = 0.035;  // ~2°: a segment's direction against the predicted line's

// An a priori unknown point: its pixel track and its 3D estimate (local frame) with covariance.
struct Track {
  cv::Point2f px;                                  // in the (distorted) frame, for KLT
  Eigen::Vector2d uv = Eigen::Vector2d::Zero();    // the same, undistorted (ideal pinhole)
  Eigen::Vector3d point = Eigen::Vector3d::Zero();
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Identity();
  int observations = 0;
  double LargestSigma() const {
    return std::sqrt(std::max(0.0, Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(covariance, Eigen::EigenvaluesOnly).eigenvalues().maxCoeff()));
  }
};

struct Segment {
  Eigen::Vector2d a, b;
};

bool InImage(const PinholeIntrinsics& k, const Eigen::Vector2d& uv, double border) {
  return uv.x() >= border && uv.y() >= border && uv.x() <= k.width - 1 - border && uv.y() <= k.height - 1 - border;
}

// Nearest detected corner to `uv` within `radius`; -1 when none.
int Nearest(const std::vector<cv::Point2f>& corners, const Eigen::Vector2d& uv, double radius) {
  int best = -1;
  double best_d2 = radius * radius;
  for (size_t j = 0; j < corners.size(); ++j) {
    const double dx = corners[j].x - uv.x(), dy = corners[j].y - uv.y();
    const double d2 = dx * dx + dy * dy;
    if (d2 <= best_d2) {
      best_d2 = d2;
      best = static_cast<int>(j);
    }
  }
  return best;
}

// The image offset that best lays the predicted model edges onto the frame's edges (coarse
// pass, chamfer matching): mean truncated distance from each sampled model-edge pixel, shifted by
// the offset, to the nearest Canny edge; a 2 px grid over the search window, then 1 px around the best.
// Façades repeat horizontal edges (window rows) every few pixels, so a second term aligns the
// model edges that have sky above them with the frame's skyline (the first edge below the top of
// each column), which has no such repetition.
double MeanDistance(const cv::Mat& distance, const std::vector<Eigen::Vector2d>& samples, int dx, int dy) {
  double sum = 0;
  int n = 0;
  for (const Eigen::Vector2d& p : samples) {
    const int x = static_cast<int>(std::lround(p.x())) + dx, y = static_cast<int>(std::lround(p.y())) + dy;
    if (x < 0 || y < 0 || x >= distance.cols || y >= distance.rows) continue;
    sum += std::min(distance.at<float>(y, x), static_cast<float>(kChamferCap_px));
    ++n;
  }
  return n * 2 >= static_cast<int>(samples.size()) && n > 0 ? sum / n : kChamferCap_px;
}

Eigen::Vector2d ChamferOffset(const cv::Mat& edge_distance, const std::vector<Eigen::Vector2d>& samples, const cv::Mat& skyline_distance,
                              const std::vector<Eigen::Vector2d>& sky_samples, double radius) {
  if (samples.size() < 10) return Eigen::Vector2d::Zero();
  const bool use_sky = sky_samples.size() >= 5;
  auto score = [&](int dx, int dy) {
    return MeanDistance(edge_distance, samples, dx, dy) + (use_sky ? MeanDistance(skyline_distance, sky_samples, dx, dy) : 0.0);
  };
  const int r = static_cast<int>(radius);
  int best_x = 0, best_y = 0;
  double best = score(0, 0);
  for (int step : {2, 1}) {
    const int cx = best_x, cy = best_y, reach = step == 2 ? r : 2;
    for (int dy = cy - reach; dy <= cy + reach; dy += step) {
      for (int dx = cx - reach; dx <= cx + reach; dx += step) {
        const double v = score(dx, dy);
        if (v < best - 1e-9 || (std::abs(v - best) <= 1e-9 && dx * dx + dy * dy < best_x * best_x + best_y * best_y)) {
          best = v;
          best_x = dx;
          best_y = dy;
        }
      }
    }
  }
  return Eigen::Vector2d(best_x, best_y);
}

}  // namespace

std::string VisionOptions::Check() const {
  if (max_features < 0) return "max_features must be >= 0";
  if (!(search_radius_px > 0) || !(match_radius_px > 0)) return "search_radius_px and match_radius_px must be > 0";
  if (max_new_points < 0) return "max_new_points must be >= 0";
  if (!(new_point_sigma_m > 0) || !(new_point_prior_depth_m > 0)) return "new_point_sigma_m and new_point_prior_depth_m must be > 0";
  return {};
}

FeatureMap CampusFeatureMap(const scene::SyntheticCampus& campus) {
  FeatureMap map;
  for (const scene::BoxBuilding& b : campus.buildings) {
    const double ground = campus.BuildingGround(b);
    for (const scene::BuildingPart& part : b.Parts()) {
      if (part.kind == scene::PrimitiveKind::kCylinder || part.kind == scene::PrimitiveKind::kDome) continue;
      const std::vector<Eigen::Vector2d> corners = scene::FootprintCorners(part);
      const double eaves = ground + part.height_m;
      for (size_t i = 0; i < corners.size(); ++i) {
        const Eigen::Vector2d& c = corners[i];
        const Eigen::Vector2d& next = corners[(i + 1) % corners.size()];
        const Eigen::Vector3d foot(c.x(), c.y(), campus.TerrainHeight(c.x(), c.y()));
        const Eigen::Vector3d top(c.x(), c.y(), eaves), next_top(next.x(), next.y(), eaves);
        map.points.push_back(foot);
        map.points.push_back(top);
        map.lines.push_back({{top, Eigen::Vector3d::UnitZ()}, foot, top});
        map.lines.push_back({{top, (next_top - top).normalized()}, top, next_top});
      }
    }
  }
  return map;
}

struct VisionTracker::Impl {
  FeatureMap map;
  MeshBvh bvh;
  PinholeIntrinsics k;
  VisionOptions options;
  cv::Mat previous_gray;
  std::vector<Track> tracks;
  bool distorted = false;  // the frames show the lens distortion of the intrinsics
  cv::Matx33d K;
  cv::Mat distortion;

  // Frame pixels -> ideal pinhole pixels (cv::undistortPoints), where the filter measures.
  std::vector<cv::Point2f> ToIdeal(const std::vector<cv::Point2f>& raw) const {
    if (!distorted || raw.empty()) return raw;
    std::vector<cv::Point2f> ideal;
    cv::undistortPoints(raw, ideal, K, distortion, cv::noArray(), K);
    return ideal;
  }
  // Ideal pinhole pixel -> frame pixel (Brown-Conrady, OpenCV order k1 k2 p1 p2 k3).
  Eigen::Vector2d ToFrame(const Eigen::Vector2d& uv) const {
    if (!distorted) return uv;
    const auto& d = k.distortion;
    const double x = (uv.x() - k.cx) / k.fx, y = (uv.y() - k.cy) / k.fy, r2 = x * x + y * y;
    const double radial = 1 + r2 * (d[0] + r2 * (d[1] + r2 * d[4]));
    const double xd = x * radial + 2 * d[2] * x * y + d[3] * (r2 + 2 * x * x);
    const double yd = y * radial + d[2] * (r2 + 2 * y * y) + 2 * d[3] * x * y;
    return {k.fx * xd + k.cx, k.fy * yd + k.cy};
  }

  bool Visible(const Eigen::Vector3d& camera_centre, const Eigen::Vector3d& p) const {
    const Eigen::Vector3d d = p - camera_centre;
    const double distance = d.norm();
    return distance > 0.5 && !bvh.Raycast(camera_centre, d, 1e-3, distance - 0.3);
  }

  // Known points the filter's pose predicts visible: (map index, predicted pixel).
  // Corners against the sky come first: nothing else nearby looks like them, while wall feet sit
  // among objects, people and ground texture.
  std::vector<std::pair<int, Eigen::Vector2d>> PredictPoints(const PoseEkf& ekf) const {
    std::vector<std::pair<int, Eigen::Vector2d>> skyline, other;
    const Eigen::Vector3d centre = ekf.world_from_camera().translation;
    for (size_t i = 0; i < map.points.size(); ++i) {
      const std::optional<Eigen::Vector2d> uv = ekf.ProjectPoint(k, map.points[i]);
      if (!uv || !InImage(k, *uv, kBorder_px) || !Visible(centre, map.points[i])) continue;
      (SkyAbove(centre, map.points[i]) ? skyline : other).emplace_back(static_cast<int>(i), *uv);
    }
    skyline.insert(skyline.end(), other.begin(), other.end());
    return skyline;
  }
  // Nothing of the model is seen just above the point (0.3 m).
  bool SkyAbove(const Eigen::Vector3d& camera_centre, const Eigen::Vector3d& p) const {
    return !bvh.Raycast(camera_centre, p + Eigen::Vector3d(0, 0, 0.3) - camera_centre, 1e-3).has_value();
  }

  // Unique matches (map index, corner index) of predicted points within `radius` of prediction + offset.
  static std::vector<std::pair<int, int>> MatchPoints(const std::vector<std::pair<int, Eigen::Vector2d>>& predicted,
                                                      const std::vector<cv::Point2f>& corners, const Eigen::Vector2d& offset,
                                                      double radius) {
    std::vector<std::pair<int, int>> out;
    std::vector<int> owner(corners.size(), -1);
    for (const auto& [index, uv] : predicted) {
      const int j = Nearest(corners, uv + offset, radius);
      if (j < 0) continue;
      if (owner[j] >= 0) {  // two predictions claim one corner: keep neither
        out[owner[j]].second = -1;
        continue;
      }
      owner[j] = static_cast<int>(out.size());
      out.emplace_back(index, j);
    }
    std::erase_if(out, [](const auto& m) { return m.second < 0; });
    return out;
  }

  // The longest detected segment along the predicted image of line feature `f`; nullopt if none.
  std::optional<Segment> MatchLine(const PoseEkf& ekf, const LineFeature& f, const std::vector<Segment>& segments) const {
    const std::optional<Eigen::Vector2d> pa = ekf.ProjectPoint(k, f.a), pb = ekf.ProjectPoint(k, f.b);
    if (!pa || !pb || (*pb - *pa).norm() < kMinSegment_px) return std::nullopt;
    const Eigen::Vector2d dir = (*pb - *pa).normalized();
    const double length = (*pb - *pa).norm();
    const Eigen::Vector2d normal(-dir.y(), dir.x());
    std::optional<Segment> best;
    double best_length = 0;
    for (const Segment& s : segments) {
      const Eigen::Vector2d sd = s.b - s.a;
      const double sl = sd.norm();
      if (sl < kMinSegment_px || sl <= best_length) continue;
      if (std::abs(normal.dot(sd)) / sl > std::sin(kMaxAngle_rad)) continue;
      if (std::abs(normal.dot(s.a - *pa)) > options.match_radius_px || std::abs(normal.dot(s.b - *pa)) > options.match_radius_px) continue;
      const double ta = dir.dot(s.a - *pa), tb = dir.dot(s.b - *pa);
      if (std::max(ta, tb) < 0 || std::min(ta, tb) > length) continue;  // beside the model segment
      best = s;
      best_length = sl;
    }
    return best;
  }

  // The 3D estimate of an unknown point after one more observation `uv` from the filter's pose.
  // Returns false when the observation disagrees (the track is then dropped).
  bool RefineTrack(Track& t, const PoseEkf& ekf, const Eigen::Vector2d& uv) const {
    Eigen::Matrix<double, 2, 12> J;
    const std::optional<Eigen::Vector2d> h = ekf.ProjectPoint(k, t.point, &J);
    if (!h) return false;
    // d pixel / d point = - d pixel / d camera position.
    const Eigen::Matrix<double, 2, 3> H = -J.block<2, 3>(0, kPos);
    const double sigma = ekf.options().pixel_sigma_px;
    const Eigen::Matrix2d R = Eigen::Matrix2d::Identity() * sigma * sigma + J * ekf.covariance() * J.transpose();
    const Eigen::Matrix2d S = H * t.covariance * H.transpose() + R;
    const Eigen::Vector2d innovation = uv - *h;
    const Eigen::LDLT<Eigen::Matrix2d> ldlt(S);
    if (ldlt.info() != Eigen::Success || innovation.dot(ldlt.solve(innovation)) > ekf.options().gate_chi2_2dof) return false;
    const Eigen::Matrix<double, 3, 2> K = ldlt.solve(H * t.covariance).transpose();
    const Eigen::Matrix3d I_KH = Eigen::Matrix3d::Identity() - K * H;
    t.point += K * innovation;
    t.covariance = I_KH * t.covariance * I_KH.transpose() + K * R * K.transpose();
    t.covariance = (0.5 * (t.covariance + t.covariance.transpose())).eval();
    ++t.observations;
    return t.point.allFinite();
  }

  Track NewTrack(const PoseEkf& ekf, const cv::Point2f& px, const Eigen::Vector2d& uv) const {
    const Rigid3d pose = ekf.world_from_camera();
    const Eigen::Vector3d ray = pose.rotation * PixelRay(k, uv);
    const double d0 = options.new_point_prior_depth_m;
    const double across = d0 * 2.0 / k.fx;  // two pixels at the prior depth
    Track t;
    t.px = px;
    t.uv = uv;
    t.point = pose.translation + d0 * ray;
    const Eigen::Matrix3d along = ray * ray.transpose();
    t.covariance = d0 * d0 * along + across * across * (Eigen::Matrix3d::Identity() - along);
    return t;
  }
};

VisionTracker::VisionTracker(FeatureMap map, const TriangleMesh& mesh, PinholeIntrinsics intrinsics, VisionOptions options)
    : impl_(std::make_unique<Impl>()) {
  impl_->map = std::move(map);
  impl_->bvh = MeshBvh(mesh);
  impl_->k = intrinsics;
  impl_->options = options;
  for (double d : intrinsics.distortion) impl_->distorted |= d != 0;
  impl_->K = cv::Matx33d(intrinsics.fx, 0, intrinsics.cx, 0, intrinsics.fy, intrinsics.cy, 0, 0, 1);
  impl_->distortion = cv::Mat(std::vector<double>(intrinsics.distortion.begin(), intrinsics.distortion.end()), true);
}
VisionTracker::VisionTracker(VisionTracker&&) noexcept = default;
VisionTracker& VisionTracker::operator=(VisionTracker&&) noexcept = default;
VisionTracker::~VisionTracker() = default;

std::vector<Eigen::Vector3d> VisionTracker::VisiblePoints(const Rigid3d& world_from_camera) const {
  std::vector<Eigen::Vector3d> out;
  for (const Eigen::Vector3d& p : impl_->map.points) {
    const std::optional<Eigen::Vector2d> uv = ProjectToPixel(impl_->k, world_from_camera.Inverse() * p, 0.1);
    if (uv && InImage(impl_->k, *uv, kBorder_px) && impl_->Visible(world_from_camera.translation, p)) out.push_back(p);
  }
  return out;
}

VisionFrameStats VisionTracker::Update(const uint8_t* bgr, int width, int height, PoseEkf& ekf) {
  Impl& m = *impl_;
  VisionFrameStats stats;
  if (m.options.max_features == 0 || width != m.k.width || height != m.k.height || !ekf.initialized()) return stats;
  const Clock::time_point t0 = Clock::now();
  const cv::Mat image(height, width, CV_8UC3, const_cast<uint8_t*>(bgr));
  cv::Mat gray;
  cv::cvtColor(image, gray, cv::COLOR_BGR2GRAY);
  std::vector<cv::Point2f> frame_corners;
  cv::goodFeaturesToTrack(gray, frame_corners, 1500, 0.005, 3);
  if (!frame_corners.empty()) {
    cv::cornerSubPix(gray, frame_corners, cv::Size(4, 4), cv::Size(-1, -1),
                     cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 20, 0.03));
  }
  const std::vector<cv::Point2f> corners = m.ToIdeal(frame_corners);  // where the filter measures
  std::vector<Segment> segments;
  if (m.options.use_lines) {
    std::vector<cv::Vec4f> lines;
    cv::createLineSegmentDetector(cv::LSD_REFINE_STD)->detect(gray, lines);
    std::vector<cv::Point2f> ends;
    for (const cv::Vec4f& l : lines) ends.insert(ends.end(), {cv::Point2f(l[0], l[1]), cv::Point2f(l[2], l[3])});
    ends = m.ToIdeal(ends);
    for (size_t i = 0; i + 1 < ends.size(); i += 2) {
      segments.push_back({Eigen::Vector2d(ends[i].x, ends[i].y), Eigen::Vector2d(ends[i + 1].x, ends[i + 1].y)});
    }
  }
  // Unknown features: follow last frame's tracks (pyramidal Lucas-Kanade).
  if (m.options.use_new_points && !m.tracks.empty() && !m.previous_gray.empty()) {
    std::vector<cv::Point2f> before, after;
    for (const Track& t : m.tracks) before.push_back(t.px);
    std::vector<uchar> status;
    std::vector<float> error;
    cv::calcOpticalFlowPyrLK(m.previous_gray, gray, before, after, status, error, cv::Size(15, 15), 2);
    const std::vector<cv::Point2f> after_ideal = m.ToIdeal(after);
    std::vector<Track> kept;
    for (size_t i = 0; i < m.tracks.size(); ++i) {
      if (!status[i] || !InImage(m.k, Eigen::Vector2d(after[i].x, after[i].y), kBorder_px)) continue;
      m.tracks[i].px = after[i];
      m.tracks[i].uv = Eigen::Vector2d(after_ideal[i].x, after_ideal[i].y);
      kept.push_back(m.tracks[i]);
    }
    m.tracks = std::move(kept);
  }

  // Coarse pass on a copy of the filter: the image offset that lays the predicted model edges on
  // the frame's edges (chamfer), then points matched within a few pixels of prediction + offset;
  // the copy's updated pose re-predicts everything for the fine pass.
  std::vector<std::pair<int, Eigen::Vector2d>> predicted = m.PredictPoints(ekf);
  stats.points_predicted = static_cast<int>(predicted.size());
  cv::Mat edges, edge_distance;
  cv::Canny(gray, edges, 60, 180);
  cv::distanceTransform(255 - edges, edge_distance, cv::DIST_L2, 3);
  // The skyline: in each column, the first edge pixel from the top.
  cv::Mat skyline(edges.size(), CV_8U, cv::Scalar(255)), skyline_distance;
  for (int u = 0; u < edges.cols; ++u) {
    for (int v = 0; v < edges.rows; ++v) {
      if (edges.at<uint8_t>(v, u)) {
        skyline.at<uint8_t>(v, u) = 0;
        break;
      }
    }
  }
  cv::distanceTransform(skyline, skyline_distance, cv::DIST_L2, 3);
  std::vector<Eigen::Vector2d> samples, sky_samples;
  {
    const Eigen::Vector3d centre = ekf.world_from_camera().translation;
    for (const LineFeature& f : m.map.lines) {
      const auto a = ekf.ProjectPoint(m.k, f.a), b = ekf.ProjectPoint(m.k, f.b);
      if (!a || !b || !m.Visible(centre, 0.5 * (f.a + f.b))) continue;
      const int steps = static_cast<int>(std::min(2000.0, (*b - *a).norm() / kEdgeSample_px));
      const bool horizontal = std::abs(f.line.direction.z()) < 0.5;
      for (int i = 0; i <= steps; ++i) {
        const double s = steps == 0 ? 0.0 : static_cast<double>(i) / steps;
        const Eigen::Vector2d p = m.ToFrame(*a + (*b - *a) * s);
        if (!InImage(m.k, p, 1)) continue;
        samples.push_back(p);
        // On the skyline: the model point itself is seen and nothing is seen just above it.
        const Eigen::Vector3d x = f.a + (f.b - f.a) * s;
        if (horizontal && m.Visible(centre, x) && m.SkyAbove(centre, x)) sky_samples.push_back(p);
      }
    }
  }
  const Eigen::Vector2d offset = ChamferOffset(edge_distance, samples, skyline_distance, sky_samples, m.options.search_radius_px);
  stats.coarse_offset_px = offset;
  stats.detect_ms = MsSince(t0);
  const Clock::time_point t1 = Clock::now();
  PoseEkf coarse = ekf;
  for (const auto& [index, j] : Impl::MatchPoints(predicted, corners, offset, kCoarseMatch_px)) {
    (void)coarse.UpdatePoint(m.k, m.map.points[index], Eigen::Vector2d(corners[j].x, corners[j].y));
  }
  double update_ms = MsSince(t1);

  // Fine pass on the filter itself: known points, then lines, then converged unknown points.
  const Clock::time_point t2 = Clock::now();
  predicted.clear();
  for (auto& p : m.PredictPoints(coarse)) predicted.push_back(p);
  const std::vector<std::pair<int, int>> matches = Impl::MatchPoints(predicted, corners, Eigen::Vector2d::Zero(), m.options.match_radius_px);
  std::vector<std::optional<Segment>> line_matches;
  if (m.options.use_lines) {
    const Eigen::Vector3d centre = coarse.world_from_camera().translation;
    for (const LineFeature& f : m.map.lines) {
      const bool seen = m.Visible(centre, 0.5 * (f.a + f.b)) || m.Visible(centre, f.a) || m.Visible(centre, f.b);
      line_matches.push_back(seen ? m.MatchLine(coarse, f, segments) : std::nullopt);
    }
  }
  stats.detect_ms += MsSince(t2);
  const Clock::time_point t3 = Clock::now();
  int budget = m.options.max_features;
  auto count = [&](const UpdateResult& r, int& used) {
    --budget;
    if (r.accepted()) {
      ++used;
    } else {
      ++stats.rejected;
    }
  };
  for (const auto& [index, j] : matches) {
    stats.point_matches.emplace_back(m.map.points[index], Eigen::Vector2d(corners[j].x, corners[j].y));
    if (budget <= 0) continue;
    count(ekf.UpdatePoint(m.k, m.map.points[index], Eigen::Vector2d(corners[j].x, corners[j].y)), stats.points_used);
  }
  for (size_t i = 0; i < line_matches.size() && budget > 0; ++i) {
    if (line_matches[i]) count(ekf.UpdateLine(m.k, m.map.lines[i].line, line_matches[i]->a, line_matches[i]->b), stats.lines_used);
  }
  if (m.options.use_new_points) {
    for (Track& t : m.tracks) {
      if (budget <= 0 || !m.options.new_points_in_pose) break;
      if (t.observations < 5 || t.LargestSigma() > m.options.new_point_sigma_m) continue;
      Eigen::Matrix<double, 2, 12> J;
      if (!ekf.ProjectPoint(m.k, t.point, &J)) continue;
      const Eigen::Matrix<double, 2, 3> H = -J.block<2, 3>(0, kPos);
      const double extra = 0.5 * (H * t.covariance * H.transpose()).trace();
      count(ekf.UpdatePoint(m.k, t.point, t.uv, extra), stats.new_points_used);
    }
    // Prediction-correction of every unknown point's structure with the corrected pose.
    std::erase_if(m.tracks, [&](Track& t) { return !m.RefineTrack(t, ekf, t.uv); });
    // New tracks on corners far from known predictions and existing tracks.
    for (size_t j = 0; j < corners.size(); ++j) {
      if (static_cast<int>(m.tracks.size()) >= m.options.max_new_points) break;
      const Eigen::Vector2d uv(corners[j].x, corners[j].y);
      bool near = false;
      for (const auto& p : predicted) near |= (p.second - uv).squaredNorm() < 100;
      for (const Track& t : m.tracks) near |= (t.uv - uv).squaredNorm() < 100;
      if (!near) m.tracks.push_back(m.NewTrack(ekf, frame_corners[j], uv));
    }
    stats.new_points_tracked = static_cast<int>(m.tracks.size());
    for (const Track& t : m.tracks) stats.new_points_converged += t.observations >= 5 && t.LargestSigma() <= m.options.new_point_sigma_m;
  }
  stats.update_ms = update_ms + MsSince(t3);
  m.previous_gray = gray;
  return stats;
}

}  // namespace ave::pose
