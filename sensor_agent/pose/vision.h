#pragma once
// Vision stabilisation of the camera pose (AVE §5.1, issue 5): known 3D point features (building
// corners) and 3D line features (building edges) of the static model are projected with the
// filter's predicted pose and matched to corners and line segments detected with OpenCV in the
// frame, inside a search window around the prediction; a priori unknown point features are tracked
// (pyramidal KLT) and their 3D position estimated as tracking goes, each by its own small
// prediction-correction filter, and join the pose update once converged (docs/POSE.md).
// OpenCV stays inside vision.cc.
#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "model_store/geometry/camera.h"
#include "model_store/geometry/mesh.h"
#include "model_store/scene/campus.h"
#include "sensor_agent/pose/pose_ekf.h"

namespace ave::pose {

// A 3D line feature with the model segment it comes from (the segment bounds where it is searched
// for; the measurement uses the infinite line).
struct LineFeature {
  Line3d line;
  Eigen::Vector3d a = Eigen::Vector3d::Zero(), b = Eigen::Vector3d::Zero();  // segment end points, local frame
};

struct FeatureMap {
  std::vector<Eigen::Vector3d> points;  // local frame
  std::vector<LineFeature> lines;
};

// Corners of every rectangular building part at the ground and at the eaves, its vertical edges and
// its eaves edges (round parts contribute none).
FeatureMap CampusFeatureMap(const scene::SyntheticCampus& campus);

struct VisionOptions {
  int max_features = 50;          // features used per frame (known points, then lines, then new points)
  double search_radius_px = 60;   // window around each prediction for the first (coarse) match
  double match_radius_px = 3;     // window after the coarse pass
  bool use_lines = true;
  bool use_new_points = true;     // track a priori unknown features and estimate their 3D structure
  // Let converged unknown features correct the pose too. Off by default: without the pose-point
  // cross-correlations (not kept here) their errors feed back into the pose, which then drifts
  // (ave-bench pose shows the row; docs/BENCHMARKS.md).
  bool new_points_in_pose = false;
  int max_new_points = 150;       // tracked unknown features kept
  double new_point_sigma_m = 0.3; // an unknown feature is used for pose once its largest sigma is below this
  double new_point_prior_depth_m = 20;  // depth prior of a fresh unknown feature (sigma the same)

  std::string Check() const;
};

struct VisionFrameStats {
  int points_predicted = 0;  // known points predicted visible
  int points_used = 0, lines_used = 0, new_points_used = 0;
  int new_points_tracked = 0, new_points_converged = 0;
  int rejected = 0;          // gated or behind the camera
  Eigen::Vector2d coarse_offset_px = Eigen::Vector2d::Zero();  // the coarse pass's image shift
  double detect_ms = 0;      // corner/segment detection, KLT tracking, matching
  double update_ms = 0;      // EKF updates (both passes) and unknown-feature filters
  // The fine pass's known-point matches (model point, detected pixel), e.g. for a PnP peer.
  std::vector<std::pair<Eigen::Vector3d, Eigen::Vector2d>> point_matches;
  int features_used() const { return points_used + lines_used + new_points_used; }
};

class VisionTracker {
 public:
  // `mesh` (local frame, the static model) decides which features the predicted camera can see.
  VisionTracker(FeatureMap map, const TriangleMesh& mesh, PinholeIntrinsics intrinsics, VisionOptions options = {});
  VisionTracker(VisionTracker&&) noexcept;
  VisionTracker& operator=(VisionTracker&&) noexcept;
  ~VisionTracker();

  // Measures one frame (BGR, top row first, the intrinsics' size) and updates `ekf`, already
  // predicted to the frame time.
  VisionFrameStats Update(const uint8_t* bgr, int width, int height, PoseEkf& ekf);

  // Model features the given pose sees (visible in the image, not hidden by the mesh).
  std::vector<Eigen::Vector3d> VisiblePoints(const Rigid3d& world_from_camera) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace ave::pose
