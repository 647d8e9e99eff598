#include "sensor_agent/pose/vision.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <optional>

#include <Eigen/Eigenvalues>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>
#include <opencv2/ximgproc/fast_line_detector.hpp>

#include "model_store/common/cpu_clock.h"
#include "model_store/geometry/bvh.h"
#include "sensor_agent/pose/feature_depth.h"
#include "sensor_agent/pose/vision_match.h"

namespace ave::pose {
namespace {

using namespace internal;  // NOLINT: the front end's own helpers
constexpr double kDegToRad = 3.14159265358979323846 / 180;

// An a priori unknown point: its pixel track and its 3D estimate (local frame) with covariance:
// anchored inverse depth (feature_depth.h) until it joins the pose filter's state, then the state's.
struct Track {
  cv::Point2f px;                                  // in the (distorted) frame, for KLT
  Eigen::Vector2d uv = Eigen::Vector2d::Zero();    // the same, undistorted (ideal pinhole)
  AnchoredPoint structure;
  Eigen::Vector3d point = Eigen::Vector3d::Zero();  // current estimate (structure's or the state's)
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Identity();
  int observations = 0;
  int64_t id = 0;  // landmark id in the pose filter's state (joint mode)
  cv::Point2f key_px;    // where it was on the last keyframe (unknown_from_keyframe: KLT re-matches against it)
  bool has_key = false;  // seen on the last keyframe
  Eigen::Vector2d first_bearing = Eigen::Vector2d::Zero();  // the anchored filter's (alpha, beta) at the first sighting (join_bearing_drift_px)
  double LargestSigma() const {
    return std::sqrt(std::max(0.0, Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(covariance, Eigen::EigenvaluesOnly).eigenvalues().maxCoeff()));
  }
  void Sync() {
    point = structure.Point();
    covariance = structure.PointCovariance();
    observations = structure.observations;
  }
};

// A known model point matched on a keyframe and followed by KLT since.
struct KnownTrack {
  int index = 0;      // into FeatureMap::points
  cv::Point2f px;     // in the (distorted) frame
  cv::Point2f key_px;  // where it was on the keyframe, which KLT matches against (no drift)
};

// Charges the CPU time since the last lap to a stage.
class StageTimer {
 public:
  explicit StageTimer(VisionFrameStats& stats) : stats_(stats), last_(ThreadCpuClock::now()) {}
  void Lap(int stage) {
    const ThreadCpuClock::time_point now = ThreadCpuClock::now();
    stats_.stage_ms[stage] += std::chrono::duration<double, std::milli>(now - last_).count();
    last_ = now;
  }

 private:
  VisionFrameStats& stats_;
  ThreadCpuClock::time_point last_;
};

}  // namespace

std::string VisionOptions::Check() const {
  if (max_features < 0) return "max_features must be >= 0";
  if (!(search_radius_px > 0) || !(match_radius_px > 0)) return "search_radius_px and match_radius_px must be > 0";
  if (max_new_points < 0) return "max_new_points must be >= 0";
  if (max_state_points < 0) return "max_state_points must be >= 0";
  if (!(new_point_sigma_m > 0) || !(new_point_prior_depth_m > 0)) return "new_point_sigma_m and new_point_prior_depth_m must be > 0";
  if (!(new_point_inverse_depth_sigma > 0)) return "new_point_inverse_depth_sigma must be > 0";
  if (new_point_min_observations < 1) return "new_point_min_observations must be >= 1";
  if (keyframe_interval < 1) return "keyframe_interval must be >= 1";
  if (min_tracked_known < 0) return "min_tracked_known must be >= 0";
  if (lock_frames < 0) return "lock_frames must be >= 0";
  if (!(acquisition_roll_search_deg >= 0 && acquisition_roll_search_deg <= 30) || !(acquisition_roll_step_deg > 0))
    return "acquisition_roll_search_deg must be in [0, 30] and acquisition_roll_step_deg > 0";
  if (!(lock_alignment_px >= 0)) return "lock_alignment_px must be >= 0";
  if (!(max_alignment_score_px >= 0)) return "max_alignment_score_px must be >= 0";
  if (acquisition_coarse_passes < 1) return "acquisition_coarse_passes must be >= 1";
  if (!(relocalize_extent_m >= 0) || !(relocalize_step_m > 0) || !(relocalize_margin_px >= 0) || relocalize_extent_m > 20 * relocalize_step_m)
    return "relocalize_extent_m must be in [0, 20 relocalize_step_m], relocalize_step_m > 0 and relocalize_margin_px >= 0";
  if (lost_frames < 0 || !(lost_orientation_sigma_deg >= 0)) return "lost_frames and lost_orientation_sigma_deg must be >= 0";
  if (!(tracked_sigma_px >= 0)) return "tracked_sigma_px must be >= 0";
  if (!(landmark_sigma_px >= 0)) return "landmark_sigma_px must be >= 0";
  if (!(landmark_bias_px >= 0 && std::isfinite(landmark_bias_px))) return "landmark_bias_px must be finite and >= 0";
  if (!(join_depth_sigma_scale > 0 && std::isfinite(join_depth_sigma_scale))) return "join_depth_sigma_scale must be finite and > 0";
  if (!(new_point_depth_sigma_ratio >= 0 && std::isfinite(new_point_depth_sigma_ratio))) return "new_point_depth_sigma_ratio must be finite and >= 0";
  if (!(join_bearing_drift_px >= 0 && std::isfinite(join_bearing_drift_px))) return "join_bearing_drift_px must be finite and >= 0";
  if (!(join_model_depth_tolerance >= 0 && std::isfinite(join_model_depth_tolerance))) return "join_model_depth_tolerance must be finite and >= 0";
  if (!(weak_lock_gated_share >= 0 && weak_lock_gated_share <= 1)) return "weak_lock_gated_share must be in [0, 1]";
  if (!(lock_sigma_px > 0)) return "lock_sigma_px must be > 0";
  if (!(visibility_cache_m >= 0)) return "visibility_cache_m must be >= 0";
  if (!(nis_short_gain >= 0 && nis_short_gain <= 1 && nis_long_gain > 0 && nis_long_gain <= 1)) {
    return "nis_short_gain must be in [0, 1] and nis_long_gain in (0, 1]";
  }
  if (!(nis_scale_cap >= 1 && std::isfinite(nis_scale_cap))) return "nis_scale_cap must be finite and >= 1";
  if (klt_window_px < 5 || klt_levels < 0 || klt_levels > 6) return "klt_window_px must be >= 5 and klt_levels in [0, 6]";
  if (grid_cell_px < 8 || grid_min_tracks < 1) return "grid_cell_px must be >= 8 and grid_min_tracks >= 1";
  if (detect_level < 0 || detect_level > 3) return "detect_level must be in [0, 3]";
  return {};
}

const char* VisionStageName(int stage) {
  static constexpr std::array<const char*, kVisionStageCount> kNames = {
      "grey conversion", "corners + sub-pixel", "segments (FLD or LSD)", "Canny + distance transforms", "chamfer/sky-line search",
      "KLT (pyramid + tracks)", "visibility ray casts", "association", "EKF updates", "unknown features"};
  return stage >= 0 && stage < kVisionStageCount ? kNames[stage] : "?";
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
  std::vector<cv::Mat> previous_pyramid, keyframe_pyramid;
  std::vector<Track> tracks;        // unknown features
  std::vector<KnownTrack> known;    // known points followed since the last keyframe
  std::vector<int> known_lines;     // line features matched on the last keyframe, followed by edge search
  int frames_since_keyframe = 0;
  bool acquired = false;       // the first vision frame has widened the GPS + AHRS prior (acquisition_*)
  bool relocalize = true;      // the next keyframe searches positions around the filter's (first frame, lost)
  bool locked_once = false;    // the lock has held since the start or since the pose was last declared lost
  int good_full_matches = 0;  // consecutive full matchings that fitted well (lock_frames)
  int bad_full_matches = 0;   // ... and badly (lost_frames)
  int64_t next_track_id = 1;
  double nis_short = -1, nis_long = -1;  // running means of the frames' NIS (VisionOptions::nis_short_gain; -1: none yet)
  cv::Ptr<cv::ximgproc::FastLineDetector> fast_lines;  // SegmentDetector::kFastLine, made on first use
  bool distorted = false;  // the frames show the lens distortion of the intrinsics
  // The persisting-bias id of known point `index` (VisionOptions::feature_point_bias_px; -1: none).
  int64_t BiasId(int index) const { return options.feature_point_bias_px > 0 ? index : -1; }
  // The id of the bias every known point shares (VisionOptions::feature_shared_bias_px; -1: none).
  int64_t SharedBiasId() const { return options.feature_shared_bias_px > 0 ? static_cast<int64_t>(map.points.size()) + 1 : -1; }
  cv::Matx33d K;
  cv::Mat distortion;
  // Visibility per static-model feature, computed lazily and reused while the camera stays within
  // options.visibility_cache_m of cache_centre: -1 unknown, 0 hidden, 1 seen.
  Eigen::Vector3d cache_centre = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  std::vector<int8_t> point_seen, point_sky, line_seen, line_mid_seen;
  std::vector<std::vector<uint8_t>> line_sky_samples;  // per line, per chamfer sample: seen with sky above

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
  // Nothing of the model is seen just above the point (0.3 m).
  bool SkyAbove(const Eigen::Vector3d& camera_centre, const Eigen::Vector3d& p) const {
    return !bvh.Raycast(camera_centre, p + Eigen::Vector3d(0, 0, 0.3) - camera_centre, 1e-3).has_value();
  }

  // Relocalisation (VisionOptions::relocalize_extent_m): the chamfer alignment (shift and turn) of
  // the model's edges from positions on a horizontal grid around the filter's; the filter moves to
  // the best one when it fits clearly better than where it is. True when it moved.
  bool Relocalize(PoseEkf& ekf, const cv::Mat& edge_distance, const cv::Mat& skyline_distance, double roll_search, double roll_step) {
    const Eigen::Vector2d centre(k.cx, k.cy);
    const Eigen::Vector3d here = ekf.world_from_camera().translation;
    auto fit = [&](const Eigen::Vector3d& position) {
      PoseEkf moved = ekf;
      moved.MovePosition(position, options.relocalize_step_m);
      std::vector<Eigen::Vector2d> samples, sky_samples;
      EdgeSamples(moved, samples, sky_samples);
      // (A 4 px first grid: the distance transform is smooth, truncated at 8 px.)
      return ChamferAlign(edge_distance, samples, skyline_distance, sky_samples, options.search_radius_px, centre, roll_search, roll_step, 4).score_px;
    };
    const double at_here = fit(here);
    double best = at_here;
    Eigen::Vector3d best_position = here;
    const int n = static_cast<int>(std::floor(options.relocalize_extent_m / options.relocalize_step_m + 1e-9));
    for (int i = -n; i <= n; ++i) {
      for (int j = -n; j <= n; ++j) {
        if (i == 0 && j == 0) continue;
        const Eigen::Vector3d position = here + options.relocalize_step_m * Eigen::Vector3d(i, j, 0);
        const double score = fit(position);
        if (score < best) best = score, best_position = position;
      }
    }
    // Then halved steps around the best, down to kFinest_m. (Heights were tried too, 0.5 m steps
    // within +-1.5 m: 8 of 13 draws held instead of 12; on far façades a pitch mimics a height,
    // and the chamfer score cannot tell them apart.)
    constexpr double kFinest_m = 0.5;
    double step = options.relocalize_step_m;
    while (step > kFinest_m + 1e-9) {
      step = std::max(kFinest_m, 0.5 * step);
      const Eigen::Vector3d around = best_position;
      for (int i = -1; i <= 1; ++i) {
        for (int j = -1; j <= 1; ++j) {
          if (i == 0 && j == 0) continue;
          const Eigen::Vector3d position = around + step * Eigen::Vector3d(i, j, 0);
          const double score = fit(position);
          if (score < best) best = score, best_position = position;
        }
      }
    }
    if (!(best < at_here - options.relocalize_margin_px) || (options.max_alignment_score_px > 0 && best > options.max_alignment_score_px)) return false;
    ekf.MovePosition(best_position, step);
    return true;
  }

  // Starts a fresh cache when the camera moved beyond options.visibility_cache_m (or caching is off).
  void RefreshCache(const Eigen::Vector3d& centre) {
    if (options.visibility_cache_m > 0 && (centre - cache_centre).norm() < options.visibility_cache_m) return;
    cache_centre = centre;
    point_seen.assign(map.points.size(), -1);
    point_sky.assign(map.points.size(), -1);
    line_seen.assign(map.lines.size(), -1);
    line_mid_seen.assign(map.lines.size(), -1);
    line_sky_samples.assign(map.lines.size(), {});
  }
  static bool Cached(int8_t& slot, const auto& compute) {
    if (slot < 0) slot = compute() ? 1 : 0;
    return slot == 1;
  }
  bool PointSeen(int i, const Eigen::Vector3d& c) { return Cached(point_seen[i], [&] { return Visible(c, map.points[i]); }); }
  bool PointSky(int i, const Eigen::Vector3d& c) { return Cached(point_sky[i], [&] { return SkyAbove(c, map.points[i]); }); }
  bool LineMidSeen(int i, const Eigen::Vector3d& c) {
    return Cached(line_mid_seen[i], [&] { return Visible(c, 0.5 * (map.lines[i].a + map.lines[i].b)); });
  }
  bool LineSeen(int i, const Eigen::Vector3d& c) {
    return Cached(line_seen[i], [&] { return LineMidSeen(i, c) || Visible(c, map.lines[i].a) || Visible(c, map.lines[i].b); });
  }

  // Known points the filter's pose predicts visible: (map index, predicted pixel).
  // Corners against the sky come first: nothing else nearby looks like them, while wall feet sit
  // among objects, people and ground texture.
  std::vector<std::pair<int, Eigen::Vector2d>> PredictPoints(const PoseEkf& ekf) {
    std::vector<std::pair<int, Eigen::Vector2d>> skyline, other;
    const Eigen::Vector3d centre = ekf.world_from_camera().translation;
    RefreshCache(centre);
    for (size_t i = 0; i < map.points.size(); ++i) {
      const std::optional<Eigen::Vector2d> uv = ekf.ProjectPoint(k, map.points[i]);
      if (!uv || !InImage(k, *uv, kBorder_px) || !PointSeen(static_cast<int>(i), centre)) continue;
      (PointSky(static_cast<int>(i), centre) ? skyline : other).emplace_back(static_cast<int>(i), *uv);
    }
    skyline.insert(skyline.end(), other.begin(), other.end());
    return skyline;
  }

  // Sampled frame pixels of the predicted model edges, and those on the skyline (the model point
  // itself is seen and nothing is seen just above it), for the chamfer search.
  void EdgeSamples(const PoseEkf& ekf, std::vector<Eigen::Vector2d>& samples, std::vector<Eigen::Vector2d>& sky_samples) {
    const Eigen::Vector3d centre = ekf.world_from_camera().translation;
    RefreshCache(centre);
    for (size_t li = 0; li < map.lines.size(); ++li) {
      const LineFeature& f = map.lines[li];
      const auto a = ekf.ProjectPoint(k, f.a), b = ekf.ProjectPoint(k, f.b);
      if (!a || !b || !LineMidSeen(static_cast<int>(li), centre)) continue;
      const int steps = static_cast<int>(std::min(2000.0, (*b - *a).norm() / kEdgeSample_px));
      const bool horizontal = std::abs(f.line.direction.z()) < 0.5;
      std::vector<uint8_t>& sky = line_sky_samples[li];
      if (horizontal && static_cast<int>(sky.size()) != steps + 1) sky.assign(steps + 1, 2);  // 2: not cast yet
      for (int i = 0; i <= steps; ++i) {
        const double s = steps == 0 ? 0.0 : static_cast<double>(i) / steps;
        const Eigen::Vector2d p = ToFrame(*a + (*b - *a) * s);
        if (!InImage(k, p, 1)) continue;
        samples.push_back(p);
        if (!horizontal) continue;
        if (sky[i] == 2) {
          const Eigen::Vector3d x = f.a + (f.b - f.a) * s;
          sky[i] = Visible(centre, x) && SkyAbove(centre, x);
        }
        if (sky[i]) sky_samples.push_back(p);
      }
    }
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

  // The Fast Line Detector fits its segments to Canny's whole-pixel edges; a matched one is moved
  // onto the sub-pixel intensity step along it (SearchEdge at 16 places, a Huber line fit), as LSD's
  // refinement does for its own. Unchanged when too little of it is found.
  Segment RefineSegment(const cv::Mat& gray, const Segment& s) const {
    constexpr int kSamples = 16;
    const Eigen::Vector2d dir = (s.b - s.a).normalized(), normal(-dir.y(), dir.x());
    std::vector<Eigen::Vector2d> samples;
    for (int i = 0; i < kSamples; ++i) samples.push_back(ToFrame(s.a + (s.b - s.a) * ((i + 0.5) / kSamples)));
    const std::vector<cv::Point2f> found = ToIdeal(SearchEdge(gray, samples, normal, 1.5, 12.0));
    if (found.size() < kSamples / 2) return s;
    cv::Vec4f fit;
    cv::fitLine(found, fit, cv::DIST_HUBER, 0, 0.01, 0.01);
    const Eigen::Vector2d d(fit[0], fit[1]), o(fit[2], fit[3]);
    if (std::abs(d.dot(dir)) < std::cos(kMaxAngle_rad)) return s;
    return {o + d * d.dot(s.a - o), o + d * d.dot(s.b - o)};
  }

  // The 3D estimate of an unknown point after one more observation `uv` from the filter's pose.
  // Returns false when the observation disagrees (the track is then dropped).
  bool RefineTrack(Track& t, const PoseEkf& ekf, const Eigen::Vector2d& uv) const {
    if (!RefineAnchoredPoint(t.structure, ekf, k, uv)) return false;
    t.Sync();
    return t.point.allFinite();
  }

  // Why a converged unknown feature may not join the pose filter's state (issue 19, session pose19j),
  // nullptr when it may. `depth` is its depth from the filter's pose (camera z).
  // 1. Static-point test on its sightings so far: seen from its anchor camera, a static point's
  //    bearing is fixed (only its depth is unknown), so the anchored filter's (alpha, beta) stays
  //    where the first sighting put it; a track that slides (a corner formed by a tree or an
  //    occluding edge in front of something farther, KLT creeping along an edge) or an object
  //    moving across the epipolar lines drags it away. More than join_bearing_drift_px: refused.
  // 2. Consistency with the static model: a point whose depth disagrees with the static mesh's
  //    surface on the same ray by more than join_model_depth_tolerance (and 1 m) is in front of
  //    every modelled surface (a person, a vehicle, the lens's occluder: a mover whose motion
  //    along the epipolar lines the depth absorbed) or behind a surface that would hide it (a wrong
  //    depth); a ray into the sky gives no depth to check, so it is refused too.
  const char* JoinRefusal(const Track& t, const PoseEkf& ekf, double depth) const {
    if (options.join_bearing_drift_px > 0) {
      const Eigen::Vector2d b = t.structure.state.head<2>() - t.first_bearing;
      if (std::hypot(b.x() * k.fx, b.y() * k.fy) > options.join_bearing_drift_px) return "bearing drifted";
    }
    if (options.join_model_depth_tolerance > 0) {
      const Rigid3d pose = ekf.world_from_camera();
      const Eigen::Vector3d ray = PixelRay(k, t.uv);
      const std::optional<RayHit> hit = bvh.Raycast(pose.translation, (pose.rotation * ray).normalized(), 1e-3);
      if (!hit) return "no model surface";
      const double model_depth = hit->distance_m / ray.norm();
      if (std::abs(depth - model_depth) > std::max(1.0, options.join_model_depth_tolerance * model_depth)) return "off the model";
    }
    return nullptr;
  }

  Track NewTrack(const PoseEkf& ekf, const cv::Point2f& px, const Eigen::Vector2d& uv) {
    Track t;
    t.id = next_track_id++;
    t.px = px;
    t.uv = uv;
    t.structure = StartAnchoredPoint(ekf.world_from_camera(), k, uv, ekf.options().pixel_sigma_px, options.new_point_prior_depth_m,
                                     options.new_point_inverse_depth_sigma);
    t.first_bearing = t.structure.state.head<2>();
    t.Sync();
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

namespace {

// Counts one feature update: used, or rejected with its reason.
void Count(const UpdateResult& r, int& used, VisionFrameStats& stats) {
  if (r.accepted()) {
    ++used;
    stats.nis = (stats.nis < 0 ? 0.0 : stats.nis) + r.mahalanobis_sq;  // a sum until the frame ends
    return;
  }
  ++stats.rejected;
  switch (r.rejection) {
    case Rejection::kGate: ++stats.rejected_gate; break;
    case Rejection::kBehindCamera: ++stats.rejected_behind; break;
    default: ++stats.rejected_not_finite; break;
  }
}

}  // namespace

VisionFrameStats VisionTracker::Update(const uint8_t* bgr, int width, int height, PoseEkf& ekf) {
  Impl& m = *impl_;
  VisionFrameStats stats;
  if (m.options.max_features == 0 || width != m.k.width || height != m.k.height || !ekf.initialized()) return stats;
  if (!m.acquired) {
    ekf.InflatePose(m.options.acquisition_position_sigma_m, m.options.acquisition_orientation_sigma_deg * 3.14159265358979323846 / 180);
    m.acquired = true;
  }
  StageTimer timer(stats);
  const cv::Mat image(height, width, CV_8UC3, const_cast<uint8_t*>(bgr));
  cv::Mat gray;
  cv::cvtColor(image, gray, cv::COLOR_BGR2GRAY);
  timer.Lap(kStageGray);

  // 1. KLT: known features matched on the last keyframe and unknown features, from their
  // projection with the filter's predicted pose (the unknown ones from their 3D estimate).
  const cv::Size window(m.options.klt_window_px, m.options.klt_window_px);
  std::vector<cv::Mat> pyramid;
  cv::buildOpticalFlowPyramid(gray, pyramid, window, m.options.klt_levels);
  const bool unknown_wanted = m.options.use_new_points || m.options.new_points_in_pose || m.options.joint_new_points;
  const bool track_unknown = unknown_wanted && !m.previous_pyramid.empty();
  auto predicted_px = [&](const Eigen::Vector3d& p, const cv::Point2f& fallback) {
    const std::optional<Eigen::Vector2d> uv = ekf.ProjectPoint(m.k, p);
    if (!uv) return fallback;
    const Eigen::Vector2d f = m.ToFrame(*uv);
    return InImage(m.k, f, 0) ? cv::Point2f(static_cast<float>(f.x()), static_cast<float>(f.y())) : fallback;
  };
  auto klt = [&](const std::vector<cv::Mat>& from, const std::vector<cv::Point2f>& before, std::vector<cv::Point2f>& after) {
    std::vector<uchar> status;
    std::vector<float> error;
    cv::calcOpticalFlowPyrLK(from, pyramid, before, after, status, error, window, m.options.klt_levels,
                             cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 20, 0.03), cv::OPTFLOW_USE_INITIAL_FLOW);
    std::vector<bool> ok(before.size());
    for (size_t i = 0; i < before.size(); ++i) {
      ok[i] = status[i] && InImage(m.k, Eigen::Vector2d(after[i].x, after[i].y), kBorder_px);
      stats.klt_lost += !ok[i];
    }
    return ok;
  };
  // Known features: from the keyframe's image to this one (no drift accumulates), started at
  // their projection with the filter's predicted pose.
  if (!m.keyframe_pyramid.empty() && !m.known.empty()) {
    std::vector<cv::Point2f> before, after;
    for (const KnownTrack& t : m.known) {
      before.push_back(t.key_px);
      after.push_back(predicted_px(m.map.points[t.index], t.px));
    }
    const std::vector<bool> ok = klt(m.keyframe_pyramid, before, after);
    std::vector<KnownTrack> known;
    for (size_t i = 0; i < m.known.size(); ++i)
      if (ok[i]) known.push_back({m.known[i].index, after[i], m.known[i].key_px});
    m.known = std::move(known);
  }
  // Unknown features: frame to frame, started at the projection of their 3D estimate.
  if (track_unknown && !m.tracks.empty()) {
    std::vector<cv::Point2f> before, after;
    for (const Track& t : m.tracks) {
      before.push_back(t.px);
      after.push_back(predicted_px(t.point, t.px));
    }
    std::vector<bool> ok = klt(m.previous_pyramid, before, after);
    // Then, for the tracks seen on the last keyframe, KLT again from the keyframe's patch, started
    // where the frame-to-frame step put them: the track's error no longer accumulates frame after
    // frame (each step's error adds to a chained track, and the joint filter takes the track's
    // sightings as independent), only once per keyframe. A track that no longer matches its
    // keyframe patch, or lands more than 2 px away from its frame-to-frame position, is dropped.
    if (m.options.unknown_from_keyframe && !m.keyframe_pyramid.empty()) {
      std::vector<size_t> keyed;
      std::vector<cv::Point2f> key_before, key_after;
      for (size_t i = 0; i < m.tracks.size(); ++i) {
        if (!ok[i] || !m.tracks[i].has_key) continue;
        keyed.push_back(i);
        key_before.push_back(m.tracks[i].key_px);
        key_after.push_back(after[i]);
      }
      if (!keyed.empty()) {
        const std::vector<bool> key_ok = klt(m.keyframe_pyramid, key_before, key_after);
        for (size_t j = 0; j < keyed.size(); ++j) {
          const size_t i = keyed[j];
          ok[i] = key_ok[j] && std::hypot(key_after[j].x - after[i].x, key_after[j].y - after[i].y) <= 2.0;
          if (ok[i]) after[i] = key_after[j];
        }
      }
    }
    const std::vector<cv::Point2f> after_ideal = m.ToIdeal(after);
    std::vector<Track> kept;
    for (size_t i = 0; i < m.tracks.size(); ++i) {
      if (!ok[i]) {
        ekf.RemoveLandmark(m.tracks[i].id);
        continue;
      }
      m.tracks[i].px = after[i];
      m.tracks[i].uv = Eigen::Vector2d(after_ideal[i].x, after_ideal[i].y);
      kept.push_back(m.tracks[i]);
    }
    m.tracks = std::move(kept);
  } else if (!track_unknown) {
    for (const Track& t : m.tracks) ekf.RemoveLandmark(t.id);
    m.tracks.clear();
  }
  stats.known_tracked = static_cast<int>(m.known.size());
  timer.Lap(kStageKlt);

  // 2. Between keyframes: the innovation test of the tracked known features against the
  // prediction decides whether the lock holds.
  std::vector<Eigen::Vector2d> known_uv;
  bool keyframe = ++m.frames_since_keyframe >= m.options.keyframe_interval || m.previous_pyramid.empty() ||
                  m.good_full_matches < m.options.lock_frames;
  if (!keyframe) {
    std::vector<cv::Point2f> raw;
    for (const KnownTrack& t : m.known) raw.push_back(t.px);
    if (m.options.refine_tracked_corners && !raw.empty()) {
      cv::cornerSubPix(gray, raw, cv::Size(4, 4), cv::Size(-1, -1), cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 10, 0.03));
      for (size_t i = 0; i < raw.size(); ++i) m.known[i].px = raw[i];
    }
    for (const cv::Point2f& p : m.ToIdeal(raw)) known_uv.emplace_back(p.x, p.y);
    int gated = 0;
    double pose_sigma_px = 0;  // the pose's own projected uncertainty, summed over the tracks
    const double var = ekf.options().pixel_sigma_px * ekf.options().pixel_sigma_px;
    for (size_t i = 0; i < m.known.size(); ++i) {
      Eigen::Matrix<double, 2, kErrorDim> J;
      const std::optional<Eigen::Vector2d> h = ekf.ProjectPoint(m.k, m.map.points[m.known[i].index], &J);
      const Eigen::Matrix2d JPJ = J * ekf.covariance() * J.transpose();
      const Eigen::Matrix2d S = JPJ + var * Eigen::Matrix2d::Identity();
      const Eigen::Vector2d r = h ? Eigen::Vector2d(known_uv[i] - *h) : Eigen::Vector2d::Constant(1e9);
      gated += !(r.dot(S.ldlt().solve(r)) <= ekf.options().gate_chi2_2dof);
      pose_sigma_px += std::sqrt(std::max(0.0, 0.5 * JPJ.trace()));
    }
    const int n = static_cast<int>(m.known.size());
    stats.weak_lock = n < m.options.min_tracked_known || gated > m.options.weak_lock_gated_share * n ||
                      pose_sigma_px > m.options.lock_sigma_px * n;
    keyframe = stats.weak_lock;
    timer.Lap(kStageMatch);
  }
  stats.keyframe = keyframe;

  std::vector<cv::Point2f> frame_corners, corners;  // keyframes: detected corners (frame, ideal pixels)
  std::vector<std::pair<int, Eigen::Vector2d>> predicted;
  int budget = m.options.max_features;
  if (!keyframe) {
    // 3a. Tracked known features update the filter; a rejected one is dropped.
    std::vector<KnownTrack> kept;
    for (size_t i = 0; i < m.known.size(); ++i) {
      const Eigen::Vector3d& p = m.map.points[m.known[i].index];
      stats.point_matches.emplace_back(p, known_uv[i]);
      if (budget <= 0) continue;
      --budget;
      const UpdateResult r = ekf.UpdatePoint(m.k, p, known_uv[i], m.options.tracked_sigma_px * m.options.tracked_sigma_px,
                                             {{{m.BiasId(m.known[i].index), m.options.feature_point_bias_px}, {m.SharedBiasId(), m.options.feature_shared_bias_px}}});
      Count(r, stats.points_used, stats);
      if (r.accepted()) kept.push_back(m.known[i]);
    }
    m.known = std::move(kept);
    timer.Lap(kStageEkf);
    // 3a'. Lines matched on the keyframe: the edge near each predicted line (1D searches along
    // its normal), a line fitted through what was found, then the line update; a rejected line is dropped.
    std::vector<int> lines_kept;
    for (const int li : m.known_lines) {
      if (budget <= 0 || !m.options.track_lines) break;
      const LineFeature& f = m.map.lines[li];
      const std::optional<Eigen::Vector2d> pa = ekf.ProjectPoint(m.k, f.a), pb = ekf.ProjectPoint(m.k, f.b);
      if (!pa || !pb || (*pb - *pa).norm() < kMinSegment_px) continue;
      const Eigen::Vector2d dir = (*pb - *pa).normalized(), normal(-dir.y(), dir.x());
      std::vector<Eigen::Vector2d> samples;
      constexpr int kSamples = 12;
      for (int i = 0; i < kSamples; ++i) {
        const Eigen::Vector2d ideal = *pa + (*pb - *pa) * ((i + 0.5) / kSamples);
        if (InImage(m.k, ideal, kBorder_px)) samples.push_back(m.ToFrame(ideal));
      }
      timer.Lap(kStageMatch);
      std::vector<cv::Point2f> found = m.ToIdeal(SearchEdge(gray, samples, normal, m.options.match_radius_px + 1, 12.0));
      timer.Lap(kStageSegments);
      if (found.size() < 4) continue;
      cv::Vec4f fit;
      cv::fitLine(found, fit, cv::DIST_HUBER, 0, 0.01, 0.01);
      const Eigen::Vector2d d(fit[0], fit[1]), o(fit[2], fit[3]);
      auto on_line = [&](const cv::Point2f& p) { return Eigen::Vector2d(o + d * d.dot(Eigen::Vector2d(p.x, p.y) - o)); };
      timer.Lap(kStageMatch);
      --budget;
      const UpdateResult r = ekf.UpdateLine(m.k, f.line, on_line(found.front()), on_line(found.back()), m.options.tracked_sigma_px * m.options.tracked_sigma_px);
      Count(r, stats.lines_used, stats);
      if (r.accepted()) lines_kept.push_back(li);
      timer.Lap(kStageEkf);
    }
    m.known_lines = std::move(lines_kept);
  } else {
    // 3b. Keyframe: full model matching, coarse to fine.
    m.frames_since_keyframe = 0;
    cv::goodFeaturesToTrack(gray, frame_corners, 1500, 0.005, 3);
    if (!frame_corners.empty()) {
      cv::cornerSubPix(gray, frame_corners, cv::Size(4, 4), cv::Size(-1, -1),
                       cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 20, 0.03));
    }
    corners = m.ToIdeal(frame_corners);  // where the filter measures
    timer.Lap(kStageCorners);
    std::vector<Segment> segments;
    if (m.options.use_lines) {
      std::vector<cv::Vec4f> lines;
      if (m.options.segment_detector == SegmentDetector::kFastLine) {
        if (!m.fast_lines) m.fast_lines = cv::ximgproc::createFastLineDetector(static_cast<int>(kMinSegment_px));
        m.fast_lines->detect(gray, lines);
      } else {
        cv::createLineSegmentDetector(cv::LSD_REFINE_STD)->detect(gray, lines);
      }
      std::vector<cv::Point2f> ends;
      for (const cv::Vec4f& l : lines) ends.insert(ends.end(), {cv::Point2f(l[0], l[1]), cv::Point2f(l[2], l[3])});
      ends = m.ToIdeal(ends);
      for (size_t i = 0; i + 1 < ends.size(); i += 2) {
        segments.push_back({Eigen::Vector2d(ends[i].x, ends[i].y), Eigen::Vector2d(ends[i + 1].x, ends[i + 1].y)});
      }
    }
    timer.Lap(kStageSegments);
    // Coarse pass on a copy of the filter: the image offset that lays the predicted model edges on
    // the frame's edges (chamfer), then points matched within a few pixels of prediction + offset;
    // the copy's updated pose re-predicts everything for the fine pass.
    cv::Mat edge_distance, skyline_distance;
    EdgeDistances(gray, edge_distance, skyline_distance);
    timer.Lap(kStageEdges);
    const Eigen::Vector2d centre(m.k.cx, m.k.cy);
    const double roll_search = m.options.acquisition_roll_search_deg * kDegToRad, roll_step = m.options.acquisition_roll_step_deg * kDegToRad;
    if (m.relocalize && m.options.relocalize_extent_m > 0) {
      m.relocalize = false;
      stats.relocalized = m.Relocalize(ekf, edge_distance, skyline_distance, roll_search, roll_step);
      timer.Lap(kStageChamfer);
    }
    predicted = m.PredictPoints(ekf);
    stats.points_predicted = static_cast<int>(predicted.size());
    std::vector<Eigen::Vector2d> samples, sky_samples;
    m.EdgeSamples(ekf, samples, sky_samples);
    timer.Lap(kStageVisibility);
    // While acquiring (before the first lock, and after the pose was declared lost) the search turns
    // the image too: the AHRS's roll error is not a shift. Once locked, a frame that disagrees (a bus
    // covering half of it) must not pull the pose, and a turn fitted to the bus's edges would.
    const bool acquiring = !m.locked_once;
    const bool turn = acquiring;
    const ImageAlignment alignment =
        ChamferAlign(edge_distance, samples, skyline_distance, sky_samples, m.options.search_radius_px, centre, turn ? roll_search : 0.0, roll_step);
    // Nowhere does the model's outline lie on this frame's edges (a bus across half of it): the
    // frame's matches would be guesses, so none is applied, and the frame counts as a bad fit.
    stats.unfit = m.options.max_alignment_score_px > 0 && alignment.score_px > m.options.max_alignment_score_px;
    if (stats.unfit) budget = 0;
    stats.coarse_offset_px = alignment.offset;
    stats.coarse_rotation_rad = alignment.rotation_rad;
    timer.Lap(kStageChamfer);
    std::vector<std::pair<int, Eigen::Vector2d>> moved = predicted;
    for (auto& [index, uv] : moved) uv = alignment.Apply(uv, centre);
    const std::vector<std::pair<int, int>> coarse_matches = MatchPoints(moved, corners, Eigen::Vector2d::Zero(), kCoarseMatch_px);
    timer.Lap(kStageMatch);
    PoseEkf coarse = ekf;
    for (const auto& [index, j] : coarse_matches) {
      (void)coarse.UpdatePoint(m.k, m.map.points[index], Eigen::Vector2d(corners[j].x, corners[j].y));
    }
    // Until the lock holds: the coarse pass again from the coarse pose (matched within the coarse
    // radius, applied to a fresh copy of the filter), as the pose that the first matches pulled
    // brings more of the image's corners within reach (iterated re-linearisation).
    for (int pass = 1; turn && pass < m.options.acquisition_coarse_passes; ++pass) {
      const std::vector<std::pair<int, int>> again = MatchPoints(m.PredictPoints(coarse), corners, Eigen::Vector2d::Zero(), kCoarseMatch_px);
      coarse = ekf;
      for (const auto& [index, j] : again) (void)coarse.UpdatePoint(m.k, m.map.points[index], Eigen::Vector2d(corners[j].x, corners[j].y));
    }
    timer.Lap(kStageEkf);

    // Fine pass on the filter itself: known points, then lines, then converged unknown points.
    predicted = m.PredictPoints(coarse);
    std::vector<bool> line_seen(m.map.lines.size(), false);
    if (m.options.use_lines) {
      const Eigen::Vector3d centre = coarse.world_from_camera().translation;
      for (size_t i = 0; i < m.map.lines.size(); ++i) line_seen[i] = m.LineSeen(static_cast<int>(i), centre);
    }
    timer.Lap(kStageVisibility);
    const std::vector<std::pair<int, int>> matches = MatchPoints(predicted, corners, Eigen::Vector2d::Zero(), m.options.match_radius_px);
    std::vector<std::optional<Segment>> line_matches(m.map.lines.size());
    for (size_t i = 0; i < m.map.lines.size(); ++i) {
      if (line_seen[i]) line_matches[i] = m.MatchLine(coarse, m.map.lines[i], segments);
      if (line_matches[i] && m.options.segment_detector == SegmentDetector::kFastLine) line_matches[i] = m.RefineSegment(gray, *line_matches[i]);
    }
    timer.Lap(kStageMatch);
    m.known.clear();
    const double acquiring_var =
        m.good_full_matches < m.options.lock_frames ? m.options.acquiring_sigma_px * m.options.acquiring_sigma_px : 0.0;
    // Until the lock holds, a point's match may be the wrong corner, and the same wrong one on the
    // next acquiring frames (each is matched from the pose the last one pulled): a persisting
    // association error per point (acquisition_association_px), ids after the shared one.
    const bool acquiring_association = m.good_full_matches < m.options.lock_frames && m.options.acquisition_association_px > 0;
    for (const auto& [index, j] : matches) {
      const Eigen::Vector2d uv(corners[j].x, corners[j].y);
      stats.point_matches.emplace_back(m.map.points[index], uv);
      if (budget <= 0) continue;
      --budget;
      const PointBias second = acquiring_association
                                   ? PointBias{static_cast<int64_t>(m.map.points.size()) + 2 + index, m.options.acquisition_association_px}
                                   : PointBias{m.SharedBiasId(), m.options.feature_shared_bias_px};
      const UpdateResult r =
          ekf.UpdatePoint(m.k, m.map.points[index], uv, acquiring_var, {{{m.BiasId(index), m.options.feature_point_bias_px}, second}});
      Count(r, stats.points_used, stats);
      if (r.accepted()) m.known.push_back({index, frame_corners[j], frame_corners[j]});
    }
    m.known_lines.clear();
    for (size_t i = 0; i < line_matches.size() && budget > 0; ++i) {
      if (!line_matches[i]) continue;
      --budget;
      const UpdateResult r = ekf.UpdateLine(m.k, m.map.lines[i].line, line_matches[i]->a, line_matches[i]->b, acquiring_var);
      Count(r, stats.lines_used, stats);
      if (r.accepted()) m.known_lines.push_back(static_cast<int>(i));
    }
    // The lock: enough features applied and few rejected; tracking resumes after lock_frames of these.
    const int applied = stats.points_used + stats.lines_used, tried = applied + stats.rejected;
    // ... and the model's edges lay down on the frame's where the filter predicts them: a coarse
    // alignment that had to move the image means the matches were taken from a pose that was off,
    // and a lock formed there holds a wrong association (issue 19, sixth session).
    // (A turn of one search step, 0.5 deg, is the prediction's ordinary roll error without an AHRS.)
    const bool aligned = !acquiring || !(m.options.lock_alignment_px > 0) ||
                         (alignment.offset.norm() <= m.options.lock_alignment_px &&
                          std::abs(alignment.rotation_rad) <= m.options.acquisition_roll_step_deg * kDegToRad + 1e-9);
    const bool good = applied >= m.options.min_tracked_known && stats.rejected <= m.options.weak_lock_gated_share * tried && aligned;
    m.good_full_matches = good ? m.good_full_matches + 1 : 0;
    m.bad_full_matches = good ? 0 : m.bad_full_matches + 1;
    m.locked_once = m.locked_once || m.good_full_matches >= m.options.lock_frames;
    if (m.options.lost_frames > 0 && m.bad_full_matches >= m.options.lost_frames) {
      ekf.InflatePose(0.5, m.options.lost_orientation_sigma_deg * 3.14159265358979323846 / 180);
      m.bad_full_matches = 0;
      m.relocalize = true;
      m.locked_once = false;
      ++stats.relocks;
    }
    timer.Lap(kStageEkf);
  }

  // 4. Unknown features.
  if (unknown_wanted) {
    // Joint mode: the features in the filter's state update pose and structure together; one that
    // disagrees leaves the state and is dropped.
    std::vector<bool> drop(m.tracks.size(), false);
    if (m.options.joint_new_points) {
      for (size_t i = 0; i < m.tracks.size(); ++i) {
        Track& t = m.tracks[i];
        if (!ekf.HasLandmark(t.id)) continue;
        const PointBias bias{m.options.landmark_bias_px > 0 ? 4 * static_cast<int64_t>(m.map.points.size()) + t.id : -1, m.options.landmark_bias_px};
        const UpdateResult r = ekf.UpdateLandmark(m.k, t.id, t.uv, m.options.landmark_sigma_px * m.options.landmark_sigma_px, bias);
        Count(r, stats.new_points_used, stats);
        if (!r.accepted()) {
          ekf.RemoveLandmark(t.id);
          drop[i] = true;
        }
      }
      for (Track& t : m.tracks) {
        if (const auto l = ekf.Landmark(t.id)) {
          t.point = l->first;
          t.covariance = l->second;
          ++t.observations;
        }
      }
    }
    for (Track& t : m.tracks) {
      if (budget <= 0 || !m.options.new_points_in_pose || m.options.joint_new_points) break;
      if (t.observations < m.options.new_point_min_observations || t.LargestSigma() > m.options.new_point_sigma_m) continue;
      Eigen::Matrix<double, 2, kErrorDim> J;
      if (!ekf.ProjectPoint(m.k, t.point, &J)) continue;
      const Eigen::Matrix<double, 2, 3> H = -J.block<2, 3>(0, kPos);
      const double extra = 0.5 * (H * t.covariance * H.transpose()).trace();
      --budget;
      Count(ekf.UpdatePoint(m.k, t.point, t.uv, extra), stats.new_points_used, stats);
    }
    // Prediction-correction of every other unknown point's structure with the corrected pose.
    const size_t before = m.tracks.size();
    for (size_t i = 0; i < m.tracks.size(); ++i) {
      if (!drop[i] && !ekf.HasLandmark(m.tracks[i].id)) drop[i] = !m.RefineTrack(m.tracks[i], ekf, m.tracks[i].uv);
    }
    std::vector<Track> kept;
    for (size_t i = 0; i < m.tracks.size(); ++i)
      if (!drop[i]) kept.push_back(m.tracks[i]);
    m.tracks = std::move(kept);
    stats.unknown_dropped = static_cast<int>(before - m.tracks.size());
    if (m.options.joint_new_points) {  // converged features join the state while there is room
      for (const Track& t : m.tracks) {
        if (ekf.landmark_count() >= m.options.max_state_points) break;
        if (ekf.HasLandmark(t.id) || t.observations < m.options.new_point_min_observations) continue;
        // The point is placed on this frame's ray from this frame's pose, at the depth the anchored
        // filter found, with the cross-covariances that placement implies (the issue-19 bug was
        // joining with none: the pose then re-learnt its own error from the point).
        // Its depth sigma is inflated by join_depth_sigma_scale: the anchored filter takes its frozen
        // anchor pose as exact and its sightings as independent, and is overconfident by about 2x.
        double depth = 0, depth_sigma = 0;
        if (!DepthFromPose(t.structure, ekf, depth, depth_sigma)) continue;
        // Converged: every sigma below new_point_sigma_m, or (session pose19j) the depth known to a
        // share of itself: far points, good references for the orientation, reach 0.3 m only after
        // seconds, while an absolute test favours near points, and near is what a mover's image
        // motion absorbed as depth looks like.
        if (t.LargestSigma() > m.options.new_point_sigma_m &&
            !(m.options.new_point_depth_sigma_ratio > 0 && depth_sigma <= m.options.new_point_depth_sigma_ratio * depth))
          continue;
        if (m.JoinRefusal(t, ekf, depth) != nullptr) {
          ++stats.landmarks_refused;
          continue;
        }
        if (ekf.AddLandmarkOnRay(t.id, m.k, t.uv, depth, depth_sigma * m.options.join_depth_sigma_scale, ekf.options().pixel_sigma_px)) {
          const auto l = ekf.Landmark(t.id);
          stats.landmarks_joined.push_back({l->first, l->second, t.uv, Eigen::Vector2d(t.px.x, t.px.y), t.id, t.observations});
        }
      }
    }
    // New tracks only where the tracked set (known and unknown) is thin: a grid mask.
    CellGrid grid(width, height, m.options.grid_cell_px);
    for (const KnownTrack& t : m.known) grid.Add(t.px.x, t.px.y);
    for (const Track& t : m.tracks) grid.Add(t.px.x, t.px.y);
    for (const auto& p : predicted) grid.Add(p.second.x(), p.second.y());
    if (static_cast<int>(m.tracks.size()) < m.options.max_new_points && (!m.options.unknown_after_lock || m.good_full_matches >= m.options.lock_frames)) {
      if (!keyframe) {
        // Between keyframes: corners on a coarser pyramid level inside the thin cells only, then
        // refined to sub-pixel on the full image.
        const int level_index = std::min(m.options.detect_level, m.options.klt_levels);  // buildOpticalFlowPyramid: image, derivatives, ...
        const int scale = 1 << level_index;
        const cv::Mat level = level_index == 0 ? gray : pyramid[2 * level_index];
        const cv::Mat mask = grid.ThinMask(m.options.grid_min_tracks, scale);
        if (level.size() == mask.size() && cv::countNonZero(mask) > 0) {
          cv::goodFeaturesToTrack(level, frame_corners, m.options.max_new_points - static_cast<int>(m.tracks.size()), 0.01, 10.0 / scale, mask);
          for (cv::Point2f& p : frame_corners) p *= static_cast<float>(scale);
          if (!frame_corners.empty()) {
            cv::cornerSubPix(gray, frame_corners, cv::Size(4, 4), cv::Size(-1, -1),
                             cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 10, 0.05));
          }
          corners = m.ToIdeal(frame_corners);
        }
      }
      for (size_t j = 0; j < corners.size() && static_cast<int>(m.tracks.size()) < m.options.max_new_points; ++j) {
        if (grid.Count(frame_corners[j].x, frame_corners[j].y) >= m.options.grid_min_tracks) continue;
        bool near = false;
        for (const Track& t : m.tracks) near |= (t.uv - Eigen::Vector2d(corners[j].x, corners[j].y)).squaredNorm() < 100;
        for (const KnownTrack& t : m.known) near |= std::hypot(t.px.x - frame_corners[j].x, t.px.y - frame_corners[j].y) < 10;
        if (near) continue;
        m.tracks.push_back(m.NewTrack(ekf, frame_corners[j], Eigen::Vector2d(corners[j].x, corners[j].y)));
        grid.Add(frame_corners[j].x, frame_corners[j].y);
      }
    }
    stats.new_points_tracked = static_cast<int>(m.tracks.size());
    for (const Track& t : m.tracks) stats.unknown_tracks.emplace_back(t.id, t.uv);
    stats.landmarks_in_state = ekf.landmark_count();
    for (const Track& t : m.tracks) stats.new_points_converged += t.observations >= m.options.new_point_min_observations && t.LargestSigma() <= m.options.new_point_sigma_m;
    timer.Lap(kStageUnknown);
  }
  if (keyframe) {
    m.keyframe_pyramid = pyramid;  // shares the pixels
    for (Track& t : m.tracks) t.key_px = t.px, t.has_key = true;
  }
  m.previous_pyramid = std::move(pyramid);
  if (stats.nis >= 0) stats.nis /= std::max(1, stats.features_used());
  if (m.options.nis_short_gain > 0 && stats.nis >= 0) {
    m.nis_short = m.nis_short < 0 ? stats.nis : m.nis_short + m.options.nis_short_gain * (stats.nis - m.nis_short);
    m.nis_long = m.nis_long < 0 ? stats.nis : m.nis_long + m.options.nis_long_gain * (stats.nis - m.nis_long);
    ekf.SetReportedScale(m.nis_long > 0 ? std::clamp(m.nis_short / m.nis_long, 1.0, m.options.nis_scale_cap) : 1.0);
  }
  stats.reported_scale = ekf.reported_scale();
  if (m.options.feature_bias_px > 0 && stats.points_used + stats.lines_used > 0) {
    double r2 = 0;
    for (const auto& pm : stats.point_matches) r2 += (pm.second - Eigen::Vector2d(m.k.cx, m.k.cy)).squaredNorm();
    const double radius = stats.point_matches.empty() ? 0.25 * m.k.width : std::max(20.0, std::sqrt(r2 / stats.point_matches.size()));
    const double b = m.options.feature_bias_px;
    const Eigen::Vector3d sigma(b / m.k.fx, b / m.k.fy, b / radius);
    const Eigen::Matrix3d R = ekf.world_from_camera().rotation.toRotationMatrix();
    ekf.SetConsideredOrientation(R * sigma.cwiseAbs2().asDiagonal() * R.transpose());
  }
  for (int s = 0; s < kVisionStageCount; ++s) (s == kStageEkf || s == kStageUnknown ? stats.update_ms : stats.detect_ms) += stats.stage_ms[s];
  return stats;
}

}  // namespace ave::pose
