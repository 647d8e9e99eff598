#pragma once
// Internal to the vision front end (vision.cc, vision_keyframe.cc): the tracker's state
// (VisionTracker::Impl) and the steps of VisionTracker::Update. Includes OpenCV; do not include
// from public headers (vision.h keeps OpenCV out).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Eigenvalues>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/ximgproc/fast_line_detector.hpp>

#include "model_store/common/cpu_clock.h"
#include "model_store/geometry/bvh.h"
#include "sensor_agent/pose/feature_depth.h"
#include "sensor_agent/pose/vision.h"
#include "sensor_agent/pose/vision_match.h"

namespace ave::pose {
namespace internal {

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
  double variance_scale = 1;  // its keyframe match's robust weight (VisionOptions::robust_residual_px), kept along the track
  double gain_scale = 1;      // its learned misfit's weight on the gain (VisionOptions::point_bias_weight_px), kept along the track
  Eigen::Vector2d correction = Eigen::Vector2d::Zero();  // ideal px from the keyframe's detected corner to where its edges meet
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

// Counts one feature update: used, or rejected with its reason.
inline void Count(const UpdateResult& r, int& used, VisionFrameStats& stats) {
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

}  // namespace internal

struct VisionTracker::Impl {
  using Track = internal::Track;
  using KnownTrack = internal::KnownTrack;
  using Segment = internal::Segment;
  using ImageAlignment = internal::ImageAlignment;
  // (model point index, predicted ideal pixel)
  using Prediction = std::pair<int, Eigen::Vector2d>;

  // One frame's working state, handed from step to step of Update. Not copyable: the timer holds
  // a reference to the stats.
  struct Frame {
    Frame(int frame_width, int frame_height, int max_features) : width(frame_width), height(frame_height), budget(max_features) {}
    Frame(const Frame&) = delete;
    Frame& operator=(const Frame&) = delete;

    VisionFrameStats stats;
    internal::StageTimer timer{stats};  // started with the frame
    int width, height;
    cv::Mat gray;
    std::vector<cv::Mat> pyramid;  // KLT pyramid of gray (image, derivatives, ... per level)
    bool keyframe = false;         // full model matching on this frame (else the tracked-frame update)
    int budget;                    // features the filter may still take this frame (max_features)
    std::vector<Eigen::Vector2d> known_uv;  // between keyframes: the tracked known features, ideal pixels
    std::vector<cv::Point2f> frame_corners, corners;  // keyframes: detected corners (frame, ideal pixels)
    std::vector<Prediction> predicted;                // keyframes: the fine pass's predicted known points
    // Keyframes the model fits nowhere as a whole: per known point and line, whether its own
    // stretch of the outline lies nowhere either (VisionOptions::local_fit_px); empty: all fit.
    std::vector<bool> point_unfit, line_unfit;
    std::vector<std::pair<int, Eigen::Vector2d>> applied_points;  // keyframes: known points the filter took, ideal pixels
  };

  FeatureMap map;
  std::vector<std::vector<Eigen::Vector3d>> point_edges;  // per known point, its model edges (to their other ends), local frame
  MeshBvh bvh;
  std::vector<bool> ground_triangle;  // per mesh triangle: terrain or road (ConstrainHeight)
  int64_t last_height_ns = INT64_MIN;  // the carried camera's height last applied (ConstrainHeight)
  PinholeIntrinsics k;
  VisionOptions options;
  std::vector<cv::Mat> previous_pyramid, keyframe_pyramid;
  std::vector<Track> tracks;        // unknown features
  std::vector<KnownTrack> known;    // known points followed since the last keyframe
  std::vector<int> known_lines;     // line features matched on the last keyframe, followed by edge search
  int frames_since_keyframe = 0;
  bool acquired = false;       // the first vision frame has widened the GPS + AHRS prior (acquisition_*)
  int64_t position_moves = 0;  // PoseEkf::position_moves() after the last frame: a change is a move from outside
  bool relocalize = true;      // the next keyframe searches positions around the filter's (first frame, lost)
  int relocalize_thin_outlines = 0;  // this frame's relocalisation positions refused for their thin outline (VisionFrameStats)
  int relocalize_wait = 0;     // frames before a waiting relocalisation searches again (relocalize_retry_frames)
  bool locked_once = false;    // the lock has held since the start or since the pose was last declared lost
  bool ever_locked = false;    // the lock has held at least once since the start (the heading search runs only before)
  int64_t lock_since_ns = 0;   // filter time the lock formed (locked_once)
  int good_full_matches = 0;  // consecutive full matchings that fitted well (lock_frames)
  int bad_full_matches = 0;   // ... and badly (lost_frames)
  int64_t next_track_id = 1;
  double nis_short = -1, nis_long = -1;  // running means of the frames' NIS (VisionOptions::nis_short_gain; -1: none yet)
  cv::Ptr<cv::ximgproc::FastLineDetector> fast_lines;  // SegmentDetector::kFastLine, made on first use
  bool distorted = false;  // the frames show the lens distortion of the intrinsics
  // Per known point, the running mean of its post-fit keyframe residual and how many went into it
  // (VisionOptions::point_bias_gain).
  std::vector<Eigen::Vector2d> misfit_mean;
  std::vector<int> misfit_count;
  // That misfit's per-axis RMS, px (0 until learned from 3 keyframes).
  double LearnedMisfitPx(int index) const {
    if (!(options.point_bias_gain > 0) || index >= static_cast<int>(misfit_count.size()) || misfit_count[index] < 3) return 0;
    return misfit_mean[index].norm() / std::sqrt(2.0);
  }
  void LearnMisfits(const PoseEkf& ekf, const Frame& f);
  // The persisting-bias id of known point `index` (VisionOptions::feature_point_bias_px; -1: none).
  int64_t BiasId(int index) const { return options.feature_point_bias_px > 0 ? index : -1; }
  // Its sigma seen from `camera_centre` (feature_point_bias_near_px near, feature_point_bias_px far).
  double PointBiasPx(int index, const Eigen::Vector3d& camera_centre) const {
    const double d = (map.points[index] - camera_centre).norm(), near = options.feature_point_near_m;
    const double t = near > 0 ? std::clamp((d - near) / near, 0.0, 1.0) : 1.0;
    const double base = options.feature_point_bias_near_px + t * (options.feature_point_bias_px - options.feature_point_bias_near_px);
    // A point weighed down by its misfit (point_bias_weight_px) keeps the base sigma: its misfit is
    // then mostly out of the estimate (13 draws: NEES in band 80.0 %, 79.7 % with the misfit as
    // its consider sigma too; docs/POSE.md, "The gyro's bias decides the pitch").
    return options.point_bias_weight_px > 0 ? base : std::max(base, LearnedMisfitPx(index));
  }
  // The gain's variance factor of known point `index` from its learned misfit
  // (VisionOptions::point_bias_weight_px; 1: off or not learned yet).
  double MisfitGainScale(int index) const {
    if (!(options.point_bias_weight_px > 0)) return 1;
    const double m = LearnedMisfitPx(index) / options.point_bias_weight_px;
    return 1 + m * m;
  }
  // The id of the bias every known point shares (VisionOptions::feature_shared_bias_px; -1: none).
  int64_t SharedBiasId() const { return options.feature_shared_bias_px > 0 ? static_cast<int64_t>(map.points.size()) + 1 : -1; }
  // The bias known point `index` shares with others: its class's (above or below the camera,
  // feature_class_bias_px; ids after the acquisition's) or, without classes, every point's.
  PointBias SharedBias(int index, const Eigen::Vector3d& camera_centre) const {
    if (!(options.feature_class_bias_px > 0)) return {SharedBiasId(), options.feature_shared_bias_px};
    const int64_t n = static_cast<int64_t>(map.points.size());
    return {2 * n + 2 + (map.points[index].z() > camera_centre.z() ? 1 : 0), options.feature_class_bias_px};
  }
  cv::Matx33d K;
  cv::Mat distortion;
  // Visibility per static-model feature, computed lazily and reused while the camera stays within
  // options.visibility_cache_m of cache_centre: -1 unknown, 0 hidden, 1 seen.
  Eigen::Vector3d cache_centre = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  std::vector<int8_t> point_seen, point_sky, line_seen, line_mid_seen;
  std::vector<std::vector<uint8_t>> line_sky_samples;  // per line, per chamfer sample: seen with sky above

  // --- Geometry and visibility helpers ---

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

  // --- Model matching (vision_keyframe.cc) ---

  void ConstrainHeight(PoseEkf& ekf, Frame& f);
  bool ApplyCarrierHeight(PoseEkf& ekf);  // true when applied
  // Relocalisation: moves the filter to the best chamfer fit on a grid of positions around its own;
  // kWaiting when the model fits well nowhere on the grid (relocalize_max_score_px).
  enum class Relocation { kStayed, kMoved, kWaiting };
  Relocation Relocalize(PoseEkf& ekf, const cv::Mat& edge_distance, const cv::Mat& skyline_distance, double roll_search, double roll_step,
                        double* best_score = nullptr);
  // The heading search while acquiring (VisionOptions::acquisition_heading_search_deg): the turn
  // about the world's vertical (degrees) that fits the frame clearly best, if any.
  std::optional<double> HeadingCandidate(const PoseEkf& ekf, const cv::Mat& edge_distance, const cv::Mat& skyline_distance, double roll_search,
                                         double roll_step);
  PoseEkf Turned(const PoseEkf& ekf, double degrees) const;
  // Known points the filter's pose predicts visible, skyline corners first.
  std::vector<Prediction> PredictPoints(const PoseEkf& ekf);
  // Sampled frame pixels of the predicted model edges, and those on the skyline.
  void EdgeSamples(const PoseEkf& ekf, std::vector<Eigen::Vector2d>& samples, std::vector<Eigen::Vector2d>& sky_samples,
                   std::vector<int>* sample_lines = nullptr, std::vector<int>* sky_lines = nullptr);
  // The known points and lines whose own stretch of the outline fits on a frame that fits nowhere
  // as a whole; true when enough do (AlignModelEdges, VisionOptions::local_fit_px).
  bool LocalFit(Frame& f, const cv::Mat& edge_distance, std::vector<Eigen::Vector2d>& samples, std::vector<Eigen::Vector2d>& sky_samples,
                const std::vector<int>& sample_lines, const std::vector<int>& sky_lines, const ImageAlignment& alignment) const;
  // `predicted` without the points left out by LocalFit.
  void DropUnfit(const Frame& f, std::vector<std::pair<int, Eigen::Vector2d>>& predicted) const;
  // The longest detected segment along the predicted image of a line feature.
  struct LineCandidate {
    int segment = -1;
    double distance_px = 0;  // mean distance of the segment's ends from the predicted line
  };
  std::optional<LineCandidate> MatchLine(const PoseEkf& ekf, const LineFeature& f, const std::vector<Segment>& segments, bool* overhang = nullptr) const;
  // Each image segment to one model line at most (VisionOptions::line_ambiguity_ratio).
  void ResolveSharedSegments(std::vector<std::optional<LineCandidate>>& candidates, Frame& f) const;
  // A Fast Line Detector segment moved onto the sub-pixel intensity step along it.
  Segment RefineSegment(const cv::Mat& gray, const Segment& s) const;

  // --- Unknown features (vision.cc) ---

  // One more observation of an unknown point's structure; false when it disagrees.
  bool RefineTrack(Track& t, const PoseEkf& ekf, const Eigen::Vector2d& uv) const;
  // Why a converged unknown feature may not join the pose filter's state; nullptr when it may.
  const char* JoinRefusal(const Track& t, const PoseEkf& ekf, double depth) const;
  // A new unknown-feature track at a detected corner.
  Track NewTrack(const PoseEkf& ekf, const cv::Point2f& px, const Eigen::Vector2d& uv);

  // --- The steps of VisionTracker::Update, in order ---

  // 1. KLT (vision.cc).
  bool UnknownWanted() const { return options.use_new_points || options.new_points_in_pose || options.joint_new_points; }
  void TrackByKlt(PoseEkf& ekf, Frame& f);
  cv::Point2f PredictedPx(const PoseEkf& ekf, const Eigen::Vector3d& p, const cv::Point2f& fallback) const;
  std::vector<bool> Klt(Frame& f, const std::vector<cv::Mat>& from, const std::vector<cv::Point2f>& before, std::vector<cv::Point2f>& after) const;
  void TrackKnownByKlt(const PoseEkf& ekf, Frame& f);
  void TrackUnknownByKlt(PoseEkf& ekf, Frame& f);
  void RematchOnKeyframe(Frame& f, std::vector<bool>& ok, std::vector<cv::Point2f>& after) const;
  // 2. Whether this frame is a keyframe: the interval, the lock's state, the tracked features' innovations (vision.cc).
  void DecideKeyframe(const PoseEkf& ekf, Frame& f);
  void RefineTrackedKnown(Frame& f);
  bool WeakLock(const PoseEkf& ekf, const Frame& f) const;
  // The pose's own uncertainty projected at model point `index`, px: sqrt(trace(J P J') / 2); 0 behind the camera.
  double ProjectedSigmaPx(const PoseEkf& ekf, int index, Eigen::Matrix2d* jpj = nullptr, std::optional<Eigen::Vector2d>* uv = nullptr) const;
  // The coarse alignment's search radius: search_radius_px while acquiring, else bounded by the
  // pose's projected sigma at the predicted points (VisionOptions::locked_search_sigmas).
  double AlignmentSearchRadius(const PoseEkf& ekf, const Frame& f) const;
  // 3a. Between keyframes: the tracked known features update the filter (vision.cc).
  void UpdateTrackedPoints(PoseEkf& ekf, Frame& f);
  void UpdateTrackedLines(PoseEkf& ekf, Frame& f);
  // 3b. Keyframes: full model matching, coarse to fine (vision_keyframe.cc).
  void UpdateKeyframe(PoseEkf& ekf, Frame& f);
  void DetectCorners(Frame& f) const;
  std::vector<Segment> DetectSegments(Frame& f);
  ImageAlignment AlignModelEdges(PoseEkf& ekf, Frame& f, bool turn);
  PoseEkf CoarsePass(const PoseEkf& ekf, Frame& f, const ImageAlignment& alignment, bool turn);
  void FinePass(PoseEkf& ekf, Frame& f, const PoseEkf& coarse, const std::vector<Segment>& segments);
  std::vector<double> RobustScales(const PoseEkf& ekf, const Frame& f, const std::vector<std::pair<int, int>>& matches, double acquiring_var) const;
  // The unit direction into known point `index`'s wedge in ideal pixels (the sum of its model
  // edges' projected directions); nullopt when they cancel or do not project.
  std::optional<Eigen::Vector2d> WedgeDirection(const PoseEkf& ekf, int index) const;
  std::optional<Eigen::Vector2d> CornerWhereEdgesMeet(const PoseEkf& ekf, const Frame& f, int index, int corner) const;
  void ApplyFineMatches(PoseEkf& ekf, Frame& f, const std::vector<std::pair<int, int>>& matches,
                        const std::vector<std::optional<Segment>>& line_matches);
  void UpdateLock(PoseEkf& ekf, Frame& f, const ImageAlignment& alignment, bool acquiring);
  // 4. Unknown features (vision.cc).
  void UpdateUnknown(PoseEkf& ekf, Frame& f);
  std::vector<bool> UpdateJointLandmarks(PoseEkf& ekf, Frame& f);
  void UpdateConvergedInPose(PoseEkf& ekf, Frame& f);
  void RefineUnknownStructure(const PoseEkf& ekf, Frame& f, std::vector<bool>& drop);
  void JoinConverged(PoseEkf& ekf, Frame& f);
  void StartNewTracks(const PoseEkf& ekf, Frame& f);
  void DetectThinCorners(Frame& f, const internal::CellGrid& grid) const;
  // 5. The frame's end: pyramids kept, NIS scale, considered orientation (vision.cc).
  void KeepPyramids(Frame& f);
  void ReportNisScale(PoseEkf& ekf, Frame& f);
  void ConsiderFeatureBias(PoseEkf& ekf, const Frame& f) const;
};

}  // namespace ave::pose
