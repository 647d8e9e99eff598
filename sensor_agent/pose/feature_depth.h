#pragma once
// Structure of an a priori unknown point feature before it joins the pose filter (issue 19,
// docs/POSE.md "New features in the state"): anchored inverse depth. The point is kept in the
// camera of its first sighting (the anchor, frozen at the filter's pose then) as
// (alpha, beta, rho): normalised image coordinates and inverse depth, x_anchor = (alpha, beta, 1) / rho.
// Unlike a Euclidean point with a depth prior (the issue-5 filter: 20 m +- 20 m along the ray), the
// projection into later views is nearly linear in rho, so a far point or a wrong prior does not
// linearise the filter into a confident wrong depth, and a point at infinity (rho = 0) is fine.
#include <Eigen/Core>

#include "model_store/geometry/camera.h"
#include "model_store/geometry/rigid3.h"
#include "sensor_agent/pose/pose_ekf.h"

namespace ave::pose {

struct AnchoredPoint {
  Eigen::Vector3d anchor_position = Eigen::Vector3d::Zero();
  Eigen::Matrix3d anchor_rotation = Eigen::Matrix3d::Identity();  // world_from_anchor camera
  Eigen::Vector3d state = Eigen::Vector3d(0, 0, 0.05);            // alpha, beta, rho (1/m)
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Identity();
  int observations = 0;

  // World point; for rho <= 0 (at or beyond infinity) a point 1 km out along the ray.
  Eigen::Vector3d Point() const;
  // Covariance of Point() (first order).
  Eigen::Matrix3d PointCovariance() const;
  // Largest 1-sigma of Point() (m).
  double LargestSigma() const;
};

// A fresh point seen at ideal pixel `uv` from `world_from_camera`: bearing sigma `pixel_sigma_px`,
// inverse depth 1 / prior_depth_m with sigma `inverse_depth_sigma` (1/m).
AnchoredPoint StartAnchoredPoint(const Rigid3d& world_from_camera, const PinholeIntrinsics& k, const Eigen::Vector2d& uv,
                                 double pixel_sigma_px, double prior_depth_m, double inverse_depth_sigma);

// One more sighting at ideal pixel `uv` from the filter's current pose; the measurement noise is
// the filter's pixel sigma plus `extra_variance_px2` plus the pose's own uncertainty projected at the
// point. Returns false (the point unchanged) when it is outside the filter's 2-dof gate, behind the
// camera or not finite: a mover or a bad track.
bool RefineAnchoredPoint(AnchoredPoint& point, const PoseEkf& ekf, const PinholeIntrinsics& k, const Eigen::Vector2d& uv,
                         double extra_variance_px2 = 0);

// Depth (camera z) of the point from the filter's current pose and its sigma; false when behind.
bool DepthFromPose(const AnchoredPoint& point, const PoseEkf& ekf, double& depth_m, double& depth_sigma_m);

}  // namespace ave::pose
