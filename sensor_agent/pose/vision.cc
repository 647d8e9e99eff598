#include "sensor_agent/pose/vision.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <optional>
#include <utility>
#include <vector>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

#include "sensor_agent/pose/feature_depth.h"
#include "sensor_agent/pose/vision_impl.h"
#include "sensor_agent/pose/vision_match.h"

// The tracker's state and the steps of Update are declared in vision_impl.h; the keyframe steps
// (full model matching, acquisition, relocalisation) are in vision_keyframe.cc.

namespace ave::pose {
namespace {

using namespace internal;  // NOLINT: the front end's own helpers

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
  if (!(acquisition_heading_search_deg >= 0 && acquisition_heading_search_deg <= 180) || !(acquisition_heading_step_deg > 0))
    return "acquisition_heading_search_deg must be in [0, 180] and acquisition_heading_step_deg > 0";
  if (!(reorient_sigma_deg > 0 && reorient_sigma_deg <= 90)) return "reorient_sigma_deg must be in (0, 90]";
  if (!(relocalize_extent_m >= 0) || !(relocalize_step_m > 0) || !(relocalize_margin_px >= 0) || relocalize_extent_m > 20 * relocalize_step_m)
    return "relocalize_extent_m must be in [0, 20 relocalize_step_m], relocalize_step_m > 0 and relocalize_margin_px >= 0";
  if (!(relocalize_extent_sigmas >= 0 && std::isfinite(relocalize_extent_sigmas)) || !(relocalize_max_extent_m >= 0 && relocalize_max_extent_m <= 100))
    return "relocalize_extent_sigmas must be finite and >= 0, relocalize_max_extent_m in [0, 100]";
  if (!(relocalize_distinct_px >= 0)) return "relocalize_distinct_px must be >= 0";
  if (!(relocalize_max_score_px >= 0)) return "relocalize_max_score_px must be >= 0";
  if (relocalize_retry_frames < 1) return "relocalize_retry_frames must be >= 1";
  if (lost_frames < 0 || !(lost_orientation_sigma_deg >= 0)) return "lost_frames and lost_orientation_sigma_deg must be >= 0";
  if (!(carrier_height_m >= 0) || !(carrier_height_sigma_m > 0) || !(carrier_height_correlation_s >= 0))
    return "carrier_height_m and carrier_height_correlation_s must be >= 0 and carrier_height_sigma_m > 0";
  if (!(feature_point_bias_near_px >= 0) || !(feature_point_near_m >= 0)) return "feature_point_bias_near_px and feature_point_near_m must be >= 0";
  if (!(tracked_sigma_px >= 0)) return "tracked_sigma_px must be >= 0";
  if (!(robust_residual_px >= 0 && std::isfinite(robust_residual_px))) return "robust_residual_px must be finite and >= 0";
  if (!(feature_class_bias_px >= 0 && std::isfinite(feature_class_bias_px))) return "feature_class_bias_px must be finite and >= 0";
  if (corners_on_edges < 0 || corners_on_edges > 2) return "corners_on_edges must be 0, 1 or 2";
  if (corner_window_px < 1 || corner_window_px > 8) return "corner_window_px must be 1 to 8";
  if (!(corner_bias_px >= 0 && corner_bias_px <= 3)) return "corner_bias_px must be 0 to 3";
  if (!(point_bias_gain >= 0 && point_bias_gain <= 1)) return "point_bias_gain must be 0 to 1";
  if (!(point_bias_weight_px >= 0) || !std::isfinite(point_bias_weight_px)) return "point_bias_weight_px must be finite and >= 0";
  if (!(foot_variance_scale >= 1 && std::isfinite(foot_variance_scale))) return "foot_variance_scale must be finite and >= 1";
  if (!(local_fit_px >= 0 && std::isfinite(local_fit_px)) || !(local_fit_after_lock_s >= 0 && std::isfinite(local_fit_after_lock_s)))
    return "local_fit_px and local_fit_after_lock_s must be finite and >= 0";
  if (!(tracked_max_innovation_px >= 0)) return "tracked_max_innovation_px must be >= 0";
  if (!(landmark_sigma_px >= 0)) return "landmark_sigma_px must be >= 0";
  if (!(landmark_bias_px >= 0 && std::isfinite(landmark_bias_px))) return "landmark_bias_px must be finite and >= 0";
  if (!(join_depth_sigma_scale > 0 && std::isfinite(join_depth_sigma_scale))) return "join_depth_sigma_scale must be finite and > 0";
  if (!(new_point_depth_sigma_ratio >= 0 && std::isfinite(new_point_depth_sigma_ratio))) return "new_point_depth_sigma_ratio must be finite and >= 0";
  if (!(join_bearing_drift_px >= 0 && std::isfinite(join_bearing_drift_px))) return "join_bearing_drift_px must be finite and >= 0";
  if (!(join_model_depth_tolerance >= 0 && std::isfinite(join_model_depth_tolerance))) return "join_model_depth_tolerance must be finite and >= 0";
  if (!(weak_lock_gated_share >= 0 && weak_lock_gated_share <= 1)) return "weak_lock_gated_share must be in [0, 1]";
  if (!(lock_sigma_px > 0)) return "lock_sigma_px must be > 0";
  if (!(locked_search_sigmas >= 0 && std::isfinite(locked_search_sigmas)) || !(locked_search_floor_px >= 0 && std::isfinite(locked_search_floor_px)))
    return "locked_search_sigmas and locked_search_floor_px must be finite and >= 0";
  if (!(line_ambiguity_ratio >= 0 && line_ambiguity_ratio <= 1)) return "line_ambiguity_ratio must be in [0, 1]";
  if (!(line_max_overhang_px >= 0) || !(line_max_overhang_share >= 0)) return "line_max_overhang_px and line_max_overhang_share must be >= 0";
  if (min_view_points < 0) return "min_view_points must be >= 0";
  if (!(relocalize_min_outline_share >= 0 && relocalize_min_outline_share <= 1)) return "relocalize_min_outline_share must be in [0, 1]";
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

namespace {

// One rectangular building part's wireframe, as the campus meshes it (scene::PartMesher): its
// corners at the ground and at the top of each wall, the roof's own vertices, and the edges where
// faces meet at an angle. A shed's high walls end at the roof's high edge and its side walls'
// tops slope; a gable end has no eaves (its wall rises to the ridge), and its apex is a corner.
void AddPart(const scene::SyntheticCampus& campus, const scene::BuildingPart& part, double eave_z, FeatureMap& map) {
  const double c = std::cos(part.yaw_rad), s = std::sin(part.yaw_rad);
  const Eigen::Vector2d ax(c, s), ay(-s, c);
  const double hx = 0.5 * part.size_m.x(), hy = 0.5 * part.size_m.y(), ze = eave_z, zt = eave_z + part.roof_height_m;
  auto at = [&](double x, double y, double z) {
    const Eigen::Vector2d p = part.center_m + x * ax + y * ay;
    return Eigen::Vector3d(p.x(), p.y(), z);
  };
  auto line = [&](const Eigen::Vector3d& a, const Eigen::Vector3d& b, bool roof_edge = false) {
    map.lines.push_back({{b, (b - a).normalized()}, a, b, roof_edge});
  };
  using scene::PrimitiveKind;
  const std::array<Eigen::Vector2d, 4> corners = {Eigen::Vector2d(-hx, -hy), Eigen::Vector2d(hx, -hy), Eigen::Vector2d(hx, hy), Eigen::Vector2d(-hx, hy)};
  std::array<Eigen::Vector3d, 4> tops;
  for (size_t i = 0; i < corners.size(); ++i) {
    const Eigen::Vector2d& q = corners[i];
    const double top_z = part.kind == PrimitiveKind::kShed && q.y() > 0 ? zt : ze;
    tops[i] = at(q.x(), q.y(), top_z);
    const Eigen::Vector3d foot(tops[i].x(), tops[i].y(), campus.TerrainHeight(tops[i].x(), tops[i].y()));
    map.points.push_back(foot);
    map.points.push_back(tops[i]);
    map.lines.push_back({{tops[i], Eigen::Vector3d::UnitZ()}, foot, tops[i]});
  }
  switch (part.kind) {
    case PrimitiveKind::kGable:  // eaves along x; rakes up to the apexes over the gable ends; the ridge
      line(tops[0], tops[1]);
      line(tops[2], tops[3]);
      for (double sx : {-hx, hx}) {
        const Eigen::Vector3d apex = at(sx, 0, zt);
        map.points.push_back(apex);
        line(at(sx, -hy, ze), apex, true);
        line(apex, at(sx, hy, ze), true);
      }
      line(at(-hx, 0, zt), at(hx, 0, zt), true);
      break;
    case PrimitiveKind::kHip: {  // eaves all round; hips up to the ridge's ends; the ridge
      for (size_t i = 0; i < 4; ++i) line(tops[i], tops[(i + 1) % 4]);
      const bool along_x = hx >= hy;
      const double r = along_x ? hx - hy : hy - hx;
      const Eigen::Vector3d lo = along_x ? at(-r, 0, zt) : at(0, -r, zt), hi = along_x ? at(r, 0, zt) : at(0, r, zt);
      map.points.push_back(lo);
      if (r > 1e-6) {
        map.points.push_back(hi);
        line(lo, hi, true);
      }
      // Corners 0 (-x, -y), 1 (+x, -y), 2 (+x, +y), 3 (-x, +y): each hip runs to the nearer end.
      line(tops[0], lo, true);
      line(tops[1], along_x ? hi : lo, true);
      line(tops[2], hi, true);
      line(tops[3], along_x ? lo : hi, true);
      break;
    }
    default:  // box at the eaves all round; a shed's walls' tops, sloping on its sides
      for (size_t i = 0; i < 4; ++i) line(tops[i], tops[(i + 1) % 4]);
      break;
  }
}

}  // namespace

FeatureMap CampusFeatureMap(const scene::SyntheticCampus& campus) {
  FeatureMap map;
  for (const scene::BoxBuilding& b : campus.buildings) {
    const double ground = campus.BuildingGround(b);
    for (const scene::BuildingPart& part : b.Parts()) {
      if (part.kind == scene::PrimitiveKind::kCylinder || part.kind == scene::PrimitiveKind::kDome) continue;
      AddPart(campus, part, ground + part.height_m, map);
    }
  }
  return map;
}

// The 3D estimate of an unknown point after one more observation `uv` from the filter's pose.
// Returns false when the observation disagrees (the track is then dropped).
bool VisionTracker::Impl::RefineTrack(Track& t, const PoseEkf& ekf, const Eigen::Vector2d& uv) const {
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
const char* VisionTracker::Impl::JoinRefusal(const Track& t, const PoseEkf& ekf, double depth) const {
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

// A new unknown-feature track at a corner (frame and ideal pixel), its structure anchored at the
// filter's pose with the prior depth (new_point_prior_depth_m, new_point_inverse_depth_sigma).
Track VisionTracker::Impl::NewTrack(const PoseEkf& ekf, const cv::Point2f& px, const Eigen::Vector2d& uv) {
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

VisionTracker::VisionTracker(FeatureMap map, const TriangleMesh& mesh, PinholeIntrinsics intrinsics, VisionOptions options)
    : impl_(std::make_unique<Impl>()) {
  impl_->map = std::move(map);
  // Each known point's model edges: the lines with an end on it (the wireframe's corners are
  // shared to the millimetre).
  impl_->point_edges.assign(impl_->map.points.size(), {});
  for (size_t i = 0; i < impl_->map.points.size(); ++i) {
    const Eigen::Vector3d& p = impl_->map.points[i];
    for (const LineFeature& l : impl_->map.lines) {
      if ((l.a - p).norm() < 1e-3) impl_->point_edges[i].push_back(l.b - p);
      else if ((l.b - p).norm() < 1e-3) impl_->point_edges[i].push_back(l.a - p);
    }
  }
  impl_->bvh = MeshBvh(mesh);
  impl_->ground_triangle.assign(mesh.TriangleCount(), false);
  for (size_t i = 0; i < mesh.TriangleCount() && i < mesh.triangle_material.size(); ++i)
    impl_->ground_triangle[i] = mesh.triangle_material[i] == SurfaceMaterial::kTerrain || mesh.triangle_material[i] == SurfaceMaterial::kRoad;
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
// One frame: KLT tracking, then either the tracked-frame update (between keyframes, while the lock
// holds) or full model matching (keyframes), then the unknown features, then the frame's reports.
VisionFrameStats VisionTracker::Update(const uint8_t* bgr, int width, int height, PoseEkf& ekf) {
  Impl& m = *impl_;
  if (m.options.max_features == 0 || width != m.k.width || height != m.k.height || !ekf.initialized()) return VisionFrameStats();
  if (!m.acquired) {  // the first vision frame widens the GPS + AHRS prior (acquisition_*)
    ekf.InflatePose(m.options.acquisition_position_sigma_m, m.options.acquisition_orientation_sigma_deg * 3.14159265358979323846 / 180);
    m.acquired = true;
  }
  if (ekf.position_moves() != m.position_moves) {
    // Something else moved the position since the last frame (a GPS re-anchor,
    // PoseFilterOptions::gps_reanchor_s): the lock and the tracks belong to the old one.
    m.relocalize = true;
    m.locked_once = false;
    m.ever_locked = false;  // the wrong lock's heading is in doubt too: searched again
    m.good_full_matches = m.bad_full_matches = 0;
  }
  Impl::Frame f(width, height, m.options.max_features);
  const cv::Mat image(height, width, CV_8UC3, const_cast<uint8_t*>(bgr));
  cv::cvtColor(image, f.gray, cv::COLOR_BGR2GRAY);
  f.timer.Lap(kStageGray);

  m.ConstrainHeight(ekf, f);  // 0. a carried camera's height above the ground
  m.TrackByKlt(ekf, f);      // 1. known and unknown features followed into this frame
  m.DecideKeyframe(ekf, f);  // 2. does the lock hold?
  if (!f.keyframe) {
    m.UpdateTrackedPoints(ekf, f);  // 3a. tracked known points ...
    m.UpdateTrackedLines(ekf, f);   // 3a'. ... and lines
  } else {
    m.UpdateKeyframe(ekf, f);  // 3b. full model matching (vision_keyframe.cc)
  }
  if (m.UnknownWanted()) m.UpdateUnknown(ekf, f);  // 4. unknown features
  m.KeepPyramids(f);
  m.ReportNisScale(ekf, f);
  m.ConsiderFeatureBias(ekf, f);
  for (int s = 0; s < kVisionStageCount; ++s) (s == kStageEkf || s == kStageUnknown ? f.stats.update_ms : f.stats.detect_ms) += f.stats.stage_ms[s];
  m.position_moves = ekf.position_moves();
  return std::move(f.stats);
}

// 0. A carried camera's height (VisionOptions::carrier_height_m): the static model's ground
// straight below the filter's position, plus the carrier's height. Only terrain and road count as
// ground (a bench, a kiosk roof or a tree below is not where the carrier stands).
void VisionTracker::Impl::ConstrainHeight(PoseEkf& ekf, Frame& f) {
  if (!(options.carrier_height_m > 0)) return;
  f.stats.height_applied = ApplyCarrierHeight(ekf);
  f.timer.Lap(kStageVisibility);  // a ray cast (and one scalar update)
}

bool VisionTracker::Impl::ApplyCarrierHeight(PoseEkf& ekf) {
  if (!(options.carrier_height_m > 0) || (last_height_ns != INT64_MIN && ekf.time_ns() <= last_height_ns)) return false;
  const Eigen::Vector3d p = ekf.world_from_camera().translation;
  const double reach_m = 4 * options.carrier_height_m + 10;
  auto ground = [&](const std::optional<RayHit>& h) { return h && h->triangle < ground_triangle.size() && ground_triangle[h->triangle]; };
  std::optional<RayHit> hit = bvh.Raycast(p, Eigen::Vector3d(0, 0, -1), 1e-3, reach_m);
  double ground_z = 0;
  if (ground(hit)) {
    ground_z = p.z() - hit->distance_m;
  } else if (!hit) {
    // Nothing below: the filter has sunk under the terrain (a GPS outage leaves only the inertial
    // height, which drifts metres). The ground straight above is where the carrier stands.
    hit = bvh.Raycast(p, Eigen::Vector3d(0, 0, 1), 1e-3, reach_m);
    if (!ground(hit)) return false;
    ground_z = p.z() + hit->distance_m;
  } else {
    return false;  // a bench, a kiosk roof or a tree below
  }
  const double dt_s = last_height_ns == INT64_MIN ? options.carrier_height_correlation_s : static_cast<double>(ekf.time_ns() - last_height_ns) * 1e-9;
  const double inflation = options.carrier_height_correlation_s > dt_s ? options.carrier_height_correlation_s / dt_s : 1.0;
  last_height_ns = ekf.time_ns();
  return ekf.UpdateHeight(ground_z + options.carrier_height_m, options.carrier_height_sigma_m * std::sqrt(inflation)).accepted();
}

// 1. KLT: known features matched on the last keyframe and unknown features, from their
// projection with the filter's predicted pose (the unknown ones from their 3D estimate).
void VisionTracker::Impl::TrackByKlt(PoseEkf& ekf, Frame& f) {
  const cv::Size window(options.klt_window_px, options.klt_window_px);
  cv::buildOpticalFlowPyramid(f.gray, f.pyramid, window, options.klt_levels);
  TrackKnownByKlt(ekf, f);
  TrackUnknownByKlt(ekf, f);
  f.stats.known_tracked = static_cast<int>(known.size());
  f.timer.Lap(kStageKlt);
}

// Where KLT starts a feature: the projection of `p` with the filter's predicted pose, in the
// frame; `fallback` (its last pixel) when that is behind the camera or outside the image.
cv::Point2f VisionTracker::Impl::PredictedPx(const PoseEkf& ekf, const Eigen::Vector3d& p, const cv::Point2f& fallback) const {
  const std::optional<Eigen::Vector2d> uv = ekf.ProjectPoint(k, p);
  if (!uv) return fallback;
  const Eigen::Vector2d frame = ToFrame(*uv);
  return InImage(k, frame, 0) ? cv::Point2f(static_cast<float>(frame.x()), static_cast<float>(frame.y())) : fallback;
}

// Pyramidal KLT from `from` to this frame's pyramid, `after` holding the starting guesses; per
// feature, whether it was found inside the image (the lost ones counted in klt_lost).
std::vector<bool> VisionTracker::Impl::Klt(Frame& f, const std::vector<cv::Mat>& from, const std::vector<cv::Point2f>& before,
                                           std::vector<cv::Point2f>& after) const {
  const cv::Size window(options.klt_window_px, options.klt_window_px);
  std::vector<uchar> status;
  std::vector<float> error;
  cv::calcOpticalFlowPyrLK(from, f.pyramid, before, after, status, error, window, options.klt_levels,
                           cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 20, 0.03), cv::OPTFLOW_USE_INITIAL_FLOW);
  std::vector<bool> ok(before.size());
  for (size_t i = 0; i < before.size(); ++i) {
    ok[i] = status[i] && InImage(k, Eigen::Vector2d(after[i].x, after[i].y), kBorder_px);
    f.stats.klt_lost += !ok[i];
  }
  return ok;
}

// Known features: from the keyframe's image to this one (no drift accumulates), started at
// their projection with the filter's predicted pose.
void VisionTracker::Impl::TrackKnownByKlt(const PoseEkf& ekf, Frame& f) {
  if (keyframe_pyramid.empty() || known.empty()) return;
  std::vector<cv::Point2f> before, after;
  for (const KnownTrack& t : known) {
    before.push_back(t.key_px);
    after.push_back(PredictedPx(ekf, map.points[t.index], t.px));
  }
  const std::vector<bool> ok = Klt(f, keyframe_pyramid, before, after);
  std::vector<KnownTrack> kept;
  for (size_t i = 0; i < known.size(); ++i)
    if (ok[i]) {
      kept.push_back(known[i]);
      kept.back().px = after[i];
    }
  known = std::move(kept);
}

// Unknown features: frame to frame, started at the projection of their 3D estimate. A lost one
// leaves the filter's state; all are dropped while unknown features are off or there is no
// previous frame.
void VisionTracker::Impl::TrackUnknownByKlt(PoseEkf& ekf, Frame& f) {
  if (!UnknownWanted() || previous_pyramid.empty()) {
    for (const Track& t : tracks) ekf.RemoveLandmark(t.id);
    tracks.clear();
    return;
  }
  if (tracks.empty()) return;
  std::vector<cv::Point2f> before, after;
  for (const Track& t : tracks) {
    before.push_back(t.px);
    after.push_back(PredictedPx(ekf, t.point, t.px));
  }
  std::vector<bool> ok = Klt(f, previous_pyramid, before, after);
  if (options.unknown_from_keyframe && !keyframe_pyramid.empty()) RematchOnKeyframe(f, ok, after);
  const std::vector<cv::Point2f> after_ideal = ToIdeal(after);
  std::vector<Track> kept;
  for (size_t i = 0; i < tracks.size(); ++i) {
    if (!ok[i]) {
      ekf.RemoveLandmark(tracks[i].id);
      continue;
    }
    tracks[i].px = after[i];
    tracks[i].uv = Eigen::Vector2d(after_ideal[i].x, after_ideal[i].y);
    kept.push_back(tracks[i]);
  }
  tracks = std::move(kept);
}

// Then, for the tracks seen on the last keyframe, KLT again from the keyframe's patch, started
// where the frame-to-frame step put them: the track's error no longer accumulates frame after
// frame (each step's error adds to a chained track, and the joint filter takes the track's
// sightings as independent), only once per keyframe. A track that no longer matches its
// keyframe patch, or lands more than 2 px away from its frame-to-frame position, is dropped.
void VisionTracker::Impl::RematchOnKeyframe(Frame& f, std::vector<bool>& ok, std::vector<cv::Point2f>& after) const {
  std::vector<size_t> keyed;
  std::vector<cv::Point2f> key_before, key_after;
  for (size_t i = 0; i < tracks.size(); ++i) {
    if (!ok[i] || !tracks[i].has_key) continue;
    keyed.push_back(i);
    key_before.push_back(tracks[i].key_px);
    key_after.push_back(after[i]);
  }
  if (keyed.empty()) return;
  const std::vector<bool> key_ok = Klt(f, keyframe_pyramid, key_before, key_after);
  for (size_t j = 0; j < keyed.size(); ++j) {
    const size_t i = keyed[j];
    ok[i] = key_ok[j] && std::hypot(key_after[j].x - after[i].x, key_after[j].y - after[i].y) <= 2.0;
    if (ok[i]) after[i] = key_after[j];
  }
}

// 2. A keyframe every keyframe_interval frames, on the first frame, and until the lock has held
// for lock_frames; between keyframes, the innovation test of the tracked known features against
// the prediction decides whether the lock holds (a weak lock makes this frame a keyframe).
void VisionTracker::Impl::DecideKeyframe(const PoseEkf& ekf, Frame& f) {
  f.keyframe = ++frames_since_keyframe >= options.keyframe_interval || previous_pyramid.empty() || good_full_matches < options.lock_frames;
  if (!f.keyframe) {
    RefineTrackedKnown(f);
    f.stats.weak_lock = WeakLock(ekf, f);
    f.keyframe = f.stats.weak_lock;
    f.timer.Lap(kStageMatch);
  }
  f.stats.keyframe = f.keyframe;
}

// The tracked known features' pixels (refined to sub-pixel corners when refine_tracked_corners)
// and their ideal pixels (f.known_uv), where the filter measures.
void VisionTracker::Impl::RefineTrackedKnown(Frame& f) {
  std::vector<cv::Point2f> raw;
  for (const KnownTrack& t : known) raw.push_back(t.px);
  if (options.refine_tracked_corners && !raw.empty()) {
    cv::cornerSubPix(f.gray, raw, cv::Size(options.corner_window_px, options.corner_window_px), cv::Size(-1, -1), cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 10, 0.03));
    for (size_t i = 0; i < raw.size(); ++i) known[i].px = raw[i];
  }
  const std::vector<cv::Point2f> ideal = ToIdeal(raw);
  for (size_t i = 0; i < ideal.size(); ++i) f.known_uv.push_back(Eigen::Vector2d(ideal[i].x, ideal[i].y) + known[i].correction);
}

// The lock is weak when too few known features are tracked (min_tracked_known), too many fall
// outside the filter's gate (weak_lock_gated_share), or the pose's own projected uncertainty at
// them is too large (lock_sigma_px).
bool VisionTracker::Impl::WeakLock(const PoseEkf& ekf, const Frame& f) const {
  int gated = 0;
  double pose_sigma_px = 0;  // the pose's own projected uncertainty, summed over the tracks
  const double var = ekf.options().pixel_sigma_px * ekf.options().pixel_sigma_px;
  for (size_t i = 0; i < known.size(); ++i) {
    Eigen::Matrix2d JPJ;
    std::optional<Eigen::Vector2d> h;
    pose_sigma_px += ProjectedSigmaPx(ekf, known[i].index, &JPJ, &h);
    const Eigen::Matrix2d S = JPJ + var * Eigen::Matrix2d::Identity();
    const Eigen::Vector2d r = h ? Eigen::Vector2d(f.known_uv[i] - *h) : Eigen::Vector2d::Constant(1e9);
    gated += !(r.dot(S.ldlt().solve(r)) <= ekf.options().gate_chi2_2dof);
  }
  const int n = static_cast<int>(known.size());
  return n < options.min_tracked_known || gated > options.weak_lock_gated_share * n || pose_sigma_px > options.lock_sigma_px * n;
}

double VisionTracker::Impl::ProjectedSigmaPx(const PoseEkf& ekf, int index, Eigen::Matrix2d* jpj, std::optional<Eigen::Vector2d>* uv) const {
  Eigen::Matrix<double, 2, kErrorDim> J;
  const std::optional<Eigen::Vector2d> h = ekf.ProjectPoint(k, map.points[index], &J);
  const Eigen::Matrix2d JPJ = h ? Eigen::Matrix2d(J * ekf.covariance() * J.transpose()) : Eigen::Matrix2d::Zero();
  if (jpj) *jpj = JPJ;
  if (uv) *uv = h;
  return std::sqrt(std::max(0.0, 0.5 * JPJ.trace()));
}

// While the lock holds, a shift the pose's uncertainty cannot explain is the outline laid on
// something else: the search reaches locked_search_sigmas times the mean projected sigma at the
// predicted points, plus locked_search_floor_px (the prediction's ordinary error between keyframes).
double VisionTracker::Impl::AlignmentSearchRadius(const PoseEkf& ekf, const Frame& f) const {
  // Since the lock first held and until the pose is declared lost: keyframes with too few matches
  // to count as good ones (82.5 s of the walk: 2-5 points) are when the bound matters most.
  if (!locked_once || !(options.locked_search_sigmas > 0) || f.predicted.empty()) return options.search_radius_px;
  double sum = 0;
  for (const auto& [index, uv] : f.predicted) sum += ProjectedSigmaPx(ekf, index);
  const double bound = options.locked_search_sigmas * sum / static_cast<double>(f.predicted.size()) + options.locked_search_floor_px;
  return std::min(options.search_radius_px, bound);
}

// 3a. Tracked known features update the filter; a rejected one is dropped.
void VisionTracker::Impl::UpdateTrackedPoints(PoseEkf& ekf, Frame& f) {
  std::vector<KnownTrack> kept;
  for (size_t i = 0; i < known.size(); ++i) {
    const Eigen::Vector3d& p = map.points[known[i].index];
    f.stats.point_matches.emplace_back(p, f.known_uv[i]);
    if (f.budget <= 0) continue;
    --f.budget;
    if (options.tracked_max_innovation_px > 0) {
      const std::optional<Eigen::Vector2d> predicted = ekf.ProjectPoint(k, p);
      if (!predicted || (*predicted - f.known_uv[i]).norm() > options.tracked_max_innovation_px) {
        ++f.stats.rejected_tracked_jump;
        continue;
      }
    }
    const UpdateResult r = ekf.UpdatePoint(k, p, f.known_uv[i], options.tracked_sigma_px * options.tracked_sigma_px,
                                           {{{BiasId(known[i].index), PointBiasPx(known[i].index, ekf.world_from_camera().translation)},
                                             SharedBias(known[i].index, ekf.world_from_camera().translation)}},
                                           known[i].variance_scale, known[i].gain_scale);
    Count(r, f.stats.points_used, f.stats);
    if (r.accepted()) kept.push_back(known[i]);
  }
  known = std::move(kept);
  f.timer.Lap(kStageEkf);
}

// 3a'. Lines matched on the keyframe: the edge near each predicted line (1D searches along
// its normal), a line fitted through what was found, then the line update; a rejected line is dropped.
void VisionTracker::Impl::UpdateTrackedLines(PoseEkf& ekf, Frame& f) {
  std::vector<int> lines_kept;
  for (const int li : known_lines) {
    if (f.budget <= 0 || !options.track_lines) break;
    const LineFeature& line = map.lines[li];
    const std::optional<Eigen::Vector2d> pa = ekf.ProjectPoint(k, line.a), pb = ekf.ProjectPoint(k, line.b);
    if (!pa || !pb || (*pb - *pa).norm() < kMinSegment_px) continue;
    const Eigen::Vector2d dir = (*pb - *pa).normalized(), normal(-dir.y(), dir.x());
    std::vector<Eigen::Vector2d> samples;
    constexpr int kSamples = 12;
    for (int i = 0; i < kSamples; ++i) {
      const Eigen::Vector2d ideal = *pa + (*pb - *pa) * ((i + 0.5) / kSamples);
      if (InImage(k, ideal, kBorder_px)) samples.push_back(ToFrame(ideal));
    }
    f.timer.Lap(kStageMatch);
    std::vector<cv::Point2f> found = ToIdeal(SearchEdge(f.gray, samples, normal, options.match_radius_px + 1, 12.0));
    f.timer.Lap(kStageSegments);
    if (found.size() < 4) continue;
    cv::Vec4f fit;
    cv::fitLine(found, fit, cv::DIST_HUBER, 0, 0.01, 0.01);
    const Eigen::Vector2d d(fit[0], fit[1]), o(fit[2], fit[3]);
    auto on_line = [&](const cv::Point2f& p) { return Eigen::Vector2d(o + d * d.dot(Eigen::Vector2d(p.x, p.y) - o)); };
    f.timer.Lap(kStageMatch);
    --f.budget;
    const UpdateResult r = ekf.UpdateLine(k, line.line, on_line(found.front()), on_line(found.back()), options.tracked_sigma_px * options.tracked_sigma_px);
    Count(r, f.stats.lines_used, f.stats);
    if (r.accepted()) lines_kept.push_back(li);
    f.timer.Lap(kStageEkf);
  }
  known_lines = std::move(lines_kept);
}

// 4. Unknown features: the filter updates from those in its state (joint mode) or converged ones
// (new_points_in_pose), every other one's structure refined with the corrected pose, converged
// ones joining the state (joint mode), new tracks where the tracked set is thin; then the counts.
void VisionTracker::Impl::UpdateUnknown(PoseEkf& ekf, Frame& f) {
  std::vector<bool> drop = UpdateJointLandmarks(ekf, f);
  UpdateConvergedInPose(ekf, f);
  RefineUnknownStructure(ekf, f, drop);
  if (options.joint_new_points) JoinConverged(ekf, f);
  StartNewTracks(ekf, f);
  f.stats.new_points_tracked = static_cast<int>(tracks.size());
  for (const Track& t : tracks) f.stats.unknown_tracks.emplace_back(t.id, t.uv);
  f.stats.landmarks_in_state = ekf.landmark_count();
  for (const Track& t : tracks) f.stats.new_points_converged += t.observations >= options.new_point_min_observations && t.LargestSigma() <= options.new_point_sigma_m;
  f.timer.Lap(kStageUnknown);
}

// Joint mode: the features in the filter's state update pose and structure together; one that
// disagrees leaves the state and is dropped. Returns which tracks to drop (none outside joint mode).
std::vector<bool> VisionTracker::Impl::UpdateJointLandmarks(PoseEkf& ekf, Frame& f) {
  std::vector<bool> drop(tracks.size(), false);
  if (!options.joint_new_points) return drop;
  for (size_t i = 0; i < tracks.size(); ++i) {
    Track& t = tracks[i];
    if (!ekf.HasLandmark(t.id)) continue;
    const PointBias bias{options.landmark_bias_px > 0 ? 4 * static_cast<int64_t>(map.points.size()) + t.id : -1, options.landmark_bias_px};
    const UpdateResult r = ekf.UpdateLandmark(k, t.id, t.uv, options.landmark_sigma_px * options.landmark_sigma_px, bias);
    Count(r, f.stats.new_points_used, f.stats);
    if (!r.accepted()) {
      ekf.RemoveLandmark(t.id);
      drop[i] = true;
    }
  }
  for (Track& t : tracks) {
    if (const auto l = ekf.Landmark(t.id)) {
      t.point = l->first;
      t.covariance = l->second;
      ++t.observations;
    }
  }
  return drop;
}

// new_points_in_pose (not joint mode): converged unknown points update the pose as if known, their
// own uncertainty projected into the image added to the pixel noise.
void VisionTracker::Impl::UpdateConvergedInPose(PoseEkf& ekf, Frame& f) {
  for (Track& t : tracks) {
    if (f.budget <= 0 || !options.new_points_in_pose || options.joint_new_points) break;
    if (t.observations < options.new_point_min_observations || t.LargestSigma() > options.new_point_sigma_m) continue;
    Eigen::Matrix<double, 2, kErrorDim> J;
    if (!ekf.ProjectPoint(k, t.point, &J)) continue;
    const Eigen::Matrix<double, 2, 3> H = -J.block<2, 3>(0, kPos);
    const double extra = 0.5 * (H * t.covariance * H.transpose()).trace();
    --f.budget;
    Count(ekf.UpdatePoint(k, t.point, t.uv, extra), f.stats.new_points_used, f.stats);
  }
}

// Prediction-correction of every other unknown point's structure with the corrected pose; the
// tracks marked in `drop` and those whose observation disagrees are dropped (unknown_dropped).
void VisionTracker::Impl::RefineUnknownStructure(const PoseEkf& ekf, Frame& f, std::vector<bool>& drop) {
  const size_t before = tracks.size();
  for (size_t i = 0; i < tracks.size(); ++i) {
    if (!drop[i] && !ekf.HasLandmark(tracks[i].id)) drop[i] = !RefineTrack(tracks[i], ekf, tracks[i].uv);
  }
  std::vector<Track> kept;
  for (size_t i = 0; i < tracks.size(); ++i)
    if (!drop[i]) kept.push_back(tracks[i]);
  tracks = std::move(kept);
  f.stats.unknown_dropped = static_cast<int>(before - tracks.size());
}

// Joint mode: converged features join the state while there is room (max_state_points).
void VisionTracker::Impl::JoinConverged(PoseEkf& ekf, Frame& f) {
  for (const Track& t : tracks) {
    if (ekf.landmark_count() >= options.max_state_points) break;
    if (ekf.HasLandmark(t.id) || t.observations < options.new_point_min_observations) continue;
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
    if (t.LargestSigma() > options.new_point_sigma_m &&
        !(options.new_point_depth_sigma_ratio > 0 && depth_sigma <= options.new_point_depth_sigma_ratio * depth))
      continue;
    if (JoinRefusal(t, ekf, depth) != nullptr) {
      ++f.stats.landmarks_refused;
      continue;
    }
    if (ekf.AddLandmarkOnRay(t.id, k, t.uv, depth, depth_sigma * options.join_depth_sigma_scale, ekf.options().pixel_sigma_px)) {
      const auto l = ekf.Landmark(t.id);
      f.stats.landmarks_joined.push_back({l->first, l->second, t.uv, Eigen::Vector2d(t.px.x, t.px.y), t.id, t.observations});
    }
  }
}

// New tracks only where the tracked set (known and unknown) is thin: a grid mask. Keyframes start
// them at their detected corners, other frames detect corners in the thin cells; none before the
// lock when unknown_after_lock, and at most max_new_points in all.
void VisionTracker::Impl::StartNewTracks(const PoseEkf& ekf, Frame& f) {
  CellGrid grid(f.width, f.height, options.grid_cell_px);
  for (const KnownTrack& t : known) grid.Add(t.px.x, t.px.y);
  for (const Track& t : tracks) grid.Add(t.px.x, t.px.y);
  for (const auto& p : f.predicted) grid.Add(p.second.x(), p.second.y());
  const bool room = static_cast<int>(tracks.size()) < options.max_new_points;
  if (!room || (options.unknown_after_lock && good_full_matches < options.lock_frames)) return;
  if (!f.keyframe) DetectThinCorners(f, grid);
  for (size_t j = 0; j < f.corners.size() && static_cast<int>(tracks.size()) < options.max_new_points; ++j) {
    if (grid.Count(f.frame_corners[j].x, f.frame_corners[j].y) >= options.grid_min_tracks) continue;
    bool near = false;
    for (const Track& t : tracks) near |= (t.uv - Eigen::Vector2d(f.corners[j].x, f.corners[j].y)).squaredNorm() < 100;
    for (const KnownTrack& t : known) near |= std::hypot(t.px.x - f.frame_corners[j].x, t.px.y - f.frame_corners[j].y) < 10;
    if (near) continue;
    tracks.push_back(NewTrack(ekf, f.frame_corners[j], Eigen::Vector2d(f.corners[j].x, f.corners[j].y)));
    grid.Add(f.frame_corners[j].x, f.frame_corners[j].y);
  }
}

// Between keyframes: corners on a coarser pyramid level inside the thin cells only, then
// refined to sub-pixel on the full image (f.frame_corners, f.corners).
void VisionTracker::Impl::DetectThinCorners(Frame& f, const CellGrid& grid) const {
  const int level_index = std::min(options.detect_level, options.klt_levels);  // buildOpticalFlowPyramid: image, derivatives, ...
  const int scale = 1 << level_index;
  const cv::Mat level = level_index == 0 ? f.gray : f.pyramid[2 * level_index];
  const cv::Mat mask = grid.ThinMask(options.grid_min_tracks, scale);
  if (level.size() == mask.size() && cv::countNonZero(mask) > 0) {
    cv::goodFeaturesToTrack(level, f.frame_corners, options.max_new_points - static_cast<int>(tracks.size()), 0.01, 10.0 / scale, mask);
    for (cv::Point2f& p : f.frame_corners) p *= static_cast<float>(scale);
    if (!f.frame_corners.empty()) {
      cv::cornerSubPix(f.gray, f.frame_corners, cv::Size(options.corner_window_px, options.corner_window_px), cv::Size(-1, -1),
                       cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 10, 0.05));
    }
    f.corners = ToIdeal(f.frame_corners);
  }
}

// The frame's pyramid is kept for KLT from it on the next frame and, on a keyframe, for KLT from
// the keyframe (known features; unknown_from_keyframe) until the next one.
void VisionTracker::Impl::KeepPyramids(Frame& f) {
  if (f.keyframe) {
    keyframe_pyramid = f.pyramid;  // shares the pixels
    for (Track& t : tracks) t.key_px = t.px, t.has_key = true;
  }
  previous_pyramid = std::move(f.pyramid);
}

// The frame's mean NIS, and the reported covariance's scale from its short and long running means
// (nis_short_gain): recent innovations larger than usual mean the filter's covariance is too small.
void VisionTracker::Impl::ReportNisScale(PoseEkf& ekf, Frame& f) {
  if (f.stats.nis >= 0) f.stats.nis /= std::max(1, f.stats.features_used());
  if (options.nis_short_gain > 0 && f.stats.nis >= 0) {
    nis_short = nis_short < 0 ? f.stats.nis : nis_short + options.nis_short_gain * (f.stats.nis - nis_short);
    nis_long = nis_long < 0 ? f.stats.nis : nis_long + options.nis_long_gain * (f.stats.nis - nis_long);
    ekf.SetReportedScale(nis_long > 0 ? std::clamp(nis_short / nis_long, 1.0, options.nis_scale_cap) : 1.0);
  }
  f.stats.reported_scale = ekf.reported_scale();
}

// The features' persisting bias (feature_bias_px) seen from the camera, as the reported pose
// covariance's consider term: bias / fx (pitch), bias / fy (yaw), bias / the RMS radius of the
// frame's point matches (roll). The estimate is unchanged.
void VisionTracker::Impl::ConsiderFeatureBias(PoseEkf& ekf, const Frame& f) const {
  if (!(options.feature_bias_px > 0 && f.stats.points_used + f.stats.lines_used > 0)) return;
  double r2 = 0;
  for (const auto& pm : f.stats.point_matches) r2 += (pm.second - Eigen::Vector2d(k.cx, k.cy)).squaredNorm();
  const double radius = f.stats.point_matches.empty() ? 0.25 * k.width : std::max(20.0, std::sqrt(r2 / f.stats.point_matches.size()));
  const double b = options.feature_bias_px;
  const Eigen::Vector3d sigma(b / k.fx, b / k.fy, b / radius);
  const Eigen::Matrix3d R = ekf.world_from_camera().rotation.toRotationMatrix();
  ekf.SetConsideredOrientation(R * sigma.cwiseAbs2().asDiagonal() * R.transpose());
}

}  // namespace ave::pose
