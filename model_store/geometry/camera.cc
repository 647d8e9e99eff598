#include "model_store/geometry/camera.h"

#include <cmath>

namespace ave {

std::string PinholeIntrinsics::Check() const {
  auto bad = [](double v) { return !std::isfinite(v) || v <= 0; };
  if (width <= 0 || width > 16384) return "width must be in 1..16384";
  if (height <= 0 || height > 16384) return "height must be in 1..16384";
  if (bad(fx)) return "fx must be finite and > 0";
  if (bad(fy)) return "fy must be finite and > 0";
  if (!std::isfinite(cx) || cx < -0.5 || cx > width - 0.5) return "cx must lie inside the image";
  if (!std::isfinite(cy) || cy < -0.5 || cy > height - 0.5) return "cy must lie inside the image";
  for (double d : distortion) {
    if (!std::isfinite(d)) return "distortion coefficients must be finite";
  }
  return {};
}

PinholeIntrinsics PinholeIntrinsics::FromFov(int width, int height, double horizontal_fov_deg) {
  PinholeIntrinsics k;
  k.width = width;
  k.height = height;
  k.fx = k.fy = 0.5 * width / std::tan(0.5 * horizontal_fov_deg * M_PI / 180.0);
  k.cx = 0.5 * width - 0.5;
  k.cy = 0.5 * height - 0.5;
  return k;
}

std::optional<Eigen::Vector2d> ProjectToPixel(const PinholeIntrinsics& k, const Eigen::Vector3d& p, double min_depth_m) {
  if (!p.allFinite() || !(p.z() > min_depth_m)) return std::nullopt;
  const Eigen::Vector2d uv(k.fx * p.x() / p.z() + k.cx, k.fy * p.y() / p.z() + k.cy);
  if (!uv.allFinite()) return std::nullopt;
  return uv;
}

Eigen::Vector3d PixelRay(const PinholeIntrinsics& k, const Eigen::Vector2d& uv) {
  return Eigen::Vector3d((uv.x() - k.cx) / k.fx, (uv.y() - k.cy) / k.fy, 1.0).normalized();
}

Rigid3d LookAt(const Eigen::Vector3d& eye, const Eigen::Vector3d& target, const Eigen::Vector3d& up) {
  Eigen::Vector3d z = target - eye;
  if (z.norm() < 1e-12) z = -up;  // no direction given: look down
  z.normalize();
  Eigen::Vector3d x = z.cross(up);
  if (x.norm() < 1e-9 * std::max(1.0, up.norm())) {
    // Looking along `up`: pick image "up" = world +y, so the image x axis is +-world x.
    x = z.cross(Eigen::Vector3d::UnitY());
  }
  x.normalize();
  const Eigen::Vector3d y = z.cross(x);
  Eigen::Matrix3d world_from_camera_rot;
  world_from_camera_rot << x, y, z;
  return Rigid3d(Eigen::Quaterniond(world_from_camera_rot), eye);
}

Eigen::Matrix4d GlViewFromWorld(const Rigid3d& world_from_camera) {
  Eigen::Matrix4d gl_from_cv = Eigen::Matrix4d::Identity();
  gl_from_cv(1, 1) = -1;
  gl_from_cv(2, 2) = -1;
  return gl_from_cv * world_from_camera.Inverse().ToMatrix();
}

Eigen::Matrix4d GlProjection(const PinholeIntrinsics& k, double n, double f) {
  const double w = k.width, h = k.height;
  Eigen::Matrix4d p = Eigen::Matrix4d::Zero();
  p(0, 0) = 2.0 * k.fx / w;
  p(0, 2) = 1.0 - 2.0 * (k.cx + 0.5) / w;
  p(1, 1) = 2.0 * k.fy / h;
  p(1, 2) = 2.0 * (k.cy + 0.5) / h - 1.0;
  p(2, 2) = -(f + n) / (f - n);
  p(2, 3) = -2.0 * f * n / (f - n);
  p(3, 2) = -1.0;
  return p;
}

std::array<float, 16> ToGlArray(const Eigen::Matrix4d& m) {
  std::array<float, 16> out{};
  for (int c = 0; c < 4; ++c)
    for (int r = 0; r < 4; ++r) out[c * 4 + r] = static_cast<float>(m(r, c));
  return out;
}

}  // namespace ave
