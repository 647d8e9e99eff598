#include "viewer_client/client/browse_camera.h"

#include <algorithm>
#include <cmath>

#include "model_store/geometry/camera.h"

namespace ave::viewer {
namespace {

Eigen::Vector3d Direction(double yaw, double pitch) {
  return {std::cos(pitch) * std::cos(yaw), std::cos(pitch) * std::sin(yaw), std::sin(pitch)};
}

}  // namespace

BrowseCamera::BrowseCamera(const Eigen::Vector3d& eye, const Eigen::Vector3d& target) : eye_(eye), pivot_(target) {
  const Eigen::Vector3d d = target - eye;
  yaw_ = std::atan2(d.y(), d.x());
  pitch_ = std::clamp(std::atan2(d.z(), d.head<2>().norm()), -kMaxPitchRad, kMaxPitchRad);
}

void BrowseCamera::SetPivot(const Eigen::Vector3d& pivot) {
  if (pivot.allFinite() && (pivot - eye_).norm() > 1e-3) pivot_ = pivot;
}

Eigen::Vector3d BrowseCamera::Forward() const { return Direction(yaw_, pitch_); }

Eigen::Vector3d BrowseCamera::Target() const { return eye_ + std::max(1.0, (pivot_ - eye_).norm()) * Forward(); }

Rigid3d BrowseCamera::WorldFromCamera() const { return LookAt(eye_, Target()); }

void BrowseCamera::Apply(const BrowseMotion& m) {
  // Mouse look turns the view about the eye.
  yaw_ -= kRadPerPx * m.look_px.x();
  pitch_ = std::clamp(pitch_ - kRadPerPx * m.look_px.y(), -kMaxPitchRad, kMaxPitchRad);
  // Orbit turns the eye about the pivot, keeping the pivot where it was on screen (yaw and pitch
  // of the view turn by the same angles as the eye's offset).
  if (!m.orbit_px.isZero()) {
    const Eigen::Vector3d offset = eye_ - pivot_;
    const double r = offset.norm();
    if (r > 1e-6) {
      double o_yaw = std::atan2(offset.y(), offset.x());
      double o_pitch = std::atan2(offset.z(), offset.head<2>().norm());
      const double d_yaw = -kRadPerPx * m.orbit_px.x();
      const double new_pitch = std::clamp(o_pitch + kRadPerPx * m.orbit_px.y(), -kMaxPitchRad, kMaxPitchRad);
      const double d_pitch = new_pitch - o_pitch;
      o_yaw += d_yaw;
      eye_ = pivot_ + r * Direction(o_yaw, new_pitch);
      yaw_ += d_yaw;
      pitch_ = std::clamp(pitch_ - d_pitch, -kMaxPitchRad, kMaxPitchRad);
    }
  }
  // Wheel: move towards the pivot by 10 % of the distance per step (never through it).
  if (m.wheel != 0) {
    const Eigen::Vector3d to_pivot = pivot_ - eye_;
    const double r = to_pivot.norm();
    const double new_r = std::clamp(r * std::pow(0.9, m.wheel), 1.0, 1e5);
    if (r > 1e-6) eye_ = pivot_ - to_pivot / r * new_r;
  }
  // Keys fly along the view direction; moving the eye drags the pivot along, so orbiting after
  // flying turns about the point that was being looked at.
  const double step = speed_m_s_ * (m.fast ? 4.0 : 1.0) * m.dt_s;
  const Eigen::Vector3d forward = Forward();
  const Eigen::Vector3d right = forward.cross(Eigen::Vector3d::UnitZ()).normalized();
  const Eigen::Vector3d move =
      step * (std::clamp(m.forward, -1.0, 1.0) * forward + std::clamp(m.right, -1.0, 1.0) * right +
              std::clamp(m.up, -1.0, 1.0) * Eigen::Vector3d::UnitZ());
  if (move.allFinite()) {
    eye_ += move;
    pivot_ += move;
  }
}

}  // namespace ave::viewer
