#pragma once
// Pinhole camera model shared by the simulator, the server and the viewer.
//
// Pixel convention (OpenCV): integer pixel coordinates are pixel centres; the image spans
// u in [-0.5, width - 0.5], v in [-0.5, height - 0.5], v growing downwards.
// Camera frame (OpenCV): x right, y down, z forward. GL eye frame: x right, y up, looking down -z.
#include <array>
#include <optional>
#include <string>

#include <Eigen/Core>

#include "model_store/geometry/rigid3.h"

namespace ave {

struct PinholeIntrinsics {
  int width = 0;   // pixels
  int height = 0;  // pixels
  double fx = 0, fy = 0, cx = 0, cy = 0;  // pixels
  std::array<double, 5> distortion{};     // k1 k2 p1 p2 k3 (Brown-Conrady, OpenCV order)

  // Empty when usable; otherwise names the first bad field ("fx must be finite and > 0").
  std::string Check() const;

  // An ideal camera of the given size and horizontal field of view.
  static PinholeIntrinsics FromFov(int width, int height, double horizontal_fov_deg);
};

// Projects a point in the camera frame to pixels; nullopt when it is not in front of the camera
// (z <= min_depth_m) or not finite. Distortion is ignored here (ideal pinhole).
std::optional<Eigen::Vector2d> ProjectToPixel(const PinholeIntrinsics& intrinsics, const Eigen::Vector3d& p_in_camera,
                                              double min_depth_m = 1e-6);

// Unit ray direction in the camera frame through pixel (u, v).
Eigen::Vector3d PixelRay(const PinholeIntrinsics& intrinsics, const Eigen::Vector2d& uv);

// world_from_camera for a camera at `eye` looking at `target`; `up` is the world's up. Stays
// well defined when looking straight along `up` (then the camera's image "up" is world +y).
Rigid3d LookAt(const Eigen::Vector3d& eye, const Eigen::Vector3d& target,
               const Eigen::Vector3d& up = Eigen::Vector3d::UnitZ());

// GL view matrix (GL eye from world) for a camera pose.
Eigen::Matrix4d GlViewFromWorld(const Rigid3d& world_from_camera);

// GL projection matrix from intrinsics: a point that projects to pixel (u, v) lands at
// NDC x = 2 (u + 0.5) / width - 1, y = 1 - 2 (v + 0.5) / height (top row at +1); depth maps
// [near, far] to NDC [-1, 1].
Eigen::Matrix4d GlProjection(const PinholeIntrinsics& intrinsics, double near_m, double far_m);

// Column-major float copy, the layout glUniformMatrix4fv(..., GL_FALSE, ...) takes.
std::array<float, 16> ToGlArray(const Eigen::Matrix4d& m);

}  // namespace ave
