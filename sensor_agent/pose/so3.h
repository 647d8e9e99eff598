#pragma once
// SO(3) exponential / logarithm and the skew matrix for the pose filter (docs/POSE.md), with the
// guards Sophus uses: a Taylor branch near zero, atan2 in the logarithm (exact near pi), and the
// quaternion kept unit and on the w >= 0 hemisphere.
#include <cmath>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace ave::pose {

inline Eigen::Matrix3d Skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}

// Rotation vector (rad) -> unit quaternion.
inline Eigen::Quaterniond SO3Exp(const Eigen::Vector3d& rotation_vector) {
  const double theta_sq = rotation_vector.squaredNorm();
  if (!std::isfinite(theta_sq)) return Eigen::Quaterniond::Identity();
  // sin(theta/2)/theta and cos(theta/2); 4th-order Taylor below 1e-4 rad keeps full precision.
  const double theta = std::sqrt(theta_sq);
  const bool small = theta < 1e-4;
  const double half_sinc = small ? 0.5 - theta_sq / 48.0 : std::sin(0.5 * theta) / theta;
  const double w = small ? 1.0 - theta_sq / 8.0 : std::cos(0.5 * theta);
  Eigen::Quaterniond q(w, half_sinc * rotation_vector.x(), half_sinc * rotation_vector.y(), half_sinc * rotation_vector.z());
  return q.normalized();
}

// Unit quaternion -> rotation vector of the shortest rotation (norm in [0, pi]).
inline Eigen::Vector3d SO3Log(const Eigen::Quaterniond& q_in) {
  Eigen::Quaterniond q = q_in.normalized();
  if (q.w() < 0) q.coeffs() = -q.coeffs();
  const double n = q.vec().norm();
  // theta = 2 atan2(n, w); for tiny n, 2/w (1 - n^2 / (3 w^2)) is its Taylor expansion over n.
  const double scale = n < 1e-8 ? 2.0 / q.w() * (1.0 - n * n / (3.0 * q.w() * q.w())) : 2.0 * std::atan2(n, q.w()) / n;
  return scale * q.vec();
}

inline double AngleBetweenDeg(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b) {
  return SO3Log(a.conjugate() * b).norm() * 180.0 / 3.14159265358979323846;
}

}  // namespace ave::pose
