#include "sensor_agent/pose/feature_depth.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>

namespace ave::pose {
namespace {

constexpr double kMinInverseDepth = 1e-3;  // 1 km: beyond it a point is at infinity for this camera
constexpr double kMinDepth_m = 0.1;

// d Point / d (alpha, beta, rho).
Eigen::Matrix3d PointJacobian(const AnchoredPoint& a) {
  const double rho = std::max(a.state.z(), kMinInverseDepth);
  Eigen::Matrix3d J;
  J.col(0) = a.anchor_rotation.col(0) / rho;
  J.col(1) = a.anchor_rotation.col(1) / rho;
  J.col(2) = -a.anchor_rotation * Eigen::Vector3d(a.state.x(), a.state.y(), 1.0) / (rho * rho);
  return J;
}

}  // namespace

Eigen::Vector3d AnchoredPoint::Point() const {
  const double rho = std::max(state.z(), kMinInverseDepth);
  return anchor_position + anchor_rotation * Eigen::Vector3d(state.x(), state.y(), 1.0) / rho;
}

Eigen::Matrix3d AnchoredPoint::PointCovariance() const {
  const Eigen::Matrix3d J = PointJacobian(*this);
  return J * covariance * J.transpose();
}

double AnchoredPoint::LargestSigma() const {
  const Eigen::Matrix3d c = PointCovariance();
  return std::sqrt(std::max(0.0, Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(0.5 * (c + c.transpose()), Eigen::EigenvaluesOnly).eigenvalues().maxCoeff()));
}

AnchoredPoint StartAnchoredPoint(const Rigid3d& world_from_camera, const PinholeIntrinsics& k, const Eigen::Vector2d& uv,
                                 double pixel_sigma_px, double prior_depth_m, double inverse_depth_sigma) {
  AnchoredPoint a;
  a.anchor_position = world_from_camera.translation;
  a.anchor_rotation = world_from_camera.rotation.normalized().toRotationMatrix();
  a.state = Eigen::Vector3d((uv.x() - k.cx) / k.fx, (uv.y() - k.cy) / k.fy, 1.0 / prior_depth_m);
  a.covariance.setZero();
  a.covariance(0, 0) = std::pow(pixel_sigma_px / k.fx, 2);
  a.covariance(1, 1) = std::pow(pixel_sigma_px / k.fy, 2);
  a.covariance(2, 2) = inverse_depth_sigma * inverse_depth_sigma;
  return a;
}

bool RefineAnchoredPoint(AnchoredPoint& a, const PoseEkf& ekf, const PinholeIntrinsics& k, const Eigen::Vector2d& uv, double extra_variance_px2) {
  if (!uv.allFinite() || !std::isfinite(extra_variance_px2)) return false;
  const Rigid3d pose = ekf.world_from_camera();
  const Eigen::Matrix3d Rt = pose.rotation.conjugate().toRotationMatrix();
  // rho * (point in the current camera) = Rt (rho (anchor - p) + R_a (alpha, beta, 1)): finite at rho = 0.
  const double rho = a.state.z();
  const Eigen::Vector3d m(a.state.x(), a.state.y(), 1.0);
  const Eigen::Vector3d baseline = a.anchor_position - pose.translation;
  const Eigen::Vector3d h = Rt * (rho * baseline + a.anchor_rotation * m);
  if (!(h.z() > 1e-6) || !h.allFinite()) return false;
  if (rho > 0 && !(h.z() / rho > kMinDepth_m)) return false;
  const double iz = 1.0 / h.z();
  const Eigen::Vector2d predicted(k.fx * h.x() * iz + k.cx, k.fy * h.y() * iz + k.cy);
  Eigen::Matrix<double, 2, 3> dpi;
  dpi << k.fx * iz, 0, -k.fx * h.x() * iz * iz, 0, k.fy * iz, -k.fy * h.y() * iz * iz;
  Eigen::Matrix3d dh;
  dh << Rt * a.anchor_rotation.col(0), Rt * a.anchor_rotation.col(1), Rt * baseline;
  const Eigen::Matrix<double, 2, 3> H = dpi * dh;
  // The pose's uncertainty, projected at the point (as a noise: the anchor is frozen).
  Eigen::Matrix<double, 2, kErrorDim> J;
  Eigen::Matrix2d pose_var = Eigen::Matrix2d::Zero();
  if (ekf.ProjectPoint(k, a.Point(), &J)) pose_var = J * ekf.covariance() * J.transpose();
  const double s = ekf.options().pixel_sigma_px;
  const Eigen::Matrix2d R = Eigen::Matrix2d::Identity() * (s * s + std::max(0.0, extra_variance_px2)) + pose_var;
  const Eigen::Matrix2d S = H * a.covariance * H.transpose() + R;
  const Eigen::Vector2d innovation = uv - predicted;
  const Eigen::LDLT<Eigen::Matrix2d> ldlt(S);
  if (ldlt.info() != Eigen::Success || !(innovation.dot(ldlt.solve(innovation)) <= ekf.options().gate_chi2_2dof)) return false;
  const Eigen::Matrix<double, 3, 2> K = ldlt.solve(H * a.covariance).transpose();
  const Eigen::Matrix3d I_KH = Eigen::Matrix3d::Identity() - K * H;
  const Eigen::Vector3d state = a.state + K * innovation;
  Eigen::Matrix3d cov = I_KH * a.covariance * I_KH.transpose() + K * R * K.transpose();
  if (!state.allFinite() || !cov.allFinite()) return false;
  a.state = state;
  a.covariance = 0.5 * (cov + cov.transpose());
  ++a.observations;
  return true;
}

bool DepthFromPose(const AnchoredPoint& a, const PoseEkf& ekf, double& depth_m, double& depth_sigma_m) {
  if (!(a.state.z() > kMinInverseDepth)) return false;
  const Rigid3d pose = ekf.world_from_camera();
  const Eigen::Vector3d z_axis = pose.rotation * Eigen::Vector3d::UnitZ();
  depth_m = z_axis.dot(a.Point() - pose.translation);
  depth_sigma_m = std::sqrt(std::max(0.0, z_axis.dot(a.PointCovariance() * z_axis)));
  return std::isfinite(depth_m) && depth_m > kMinDepth_m && std::isfinite(depth_sigma_m) && depth_sigma_m > 0;
}

}  // namespace ave::pose
