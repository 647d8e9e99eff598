#pragma once
// The free browse view's camera (AVE §8: the control-room operator flies through the model):
// fly with the keyboard (W/S forward/back along the view, A/D sideways, E/Q up/down, Shift fast)
// and mouse look (right drag), or orbit about a picked point (left drag; the wheel moves towards
// it). Local frame of the static model, metres, z up. Pure: no GL, no window.
#include <Eigen/Core>

#include "model_store/geometry/rigid3.h"

namespace ave::viewer {

struct BrowseMotion {
  double forward = 0, right = 0, up = 0;  // key axes, each in [-1, 1]
  bool fast = false;
  Eigen::Vector2d look_px = Eigen::Vector2d::Zero();   // mouse-look drag (pixels, x right, y down)
  Eigen::Vector2d orbit_px = Eigen::Vector2d::Zero();  // orbit drag
  double wheel = 0;                                    // steps, positive = towards the pivot
  double dt_s = 1.0 / 30;                              // frame time for the key speeds
};

class BrowseCamera {
 public:
  // Looking from `eye` at `target`, which becomes the orbit pivot.
  BrowseCamera(const Eigen::Vector3d& eye, const Eigen::Vector3d& target);

  // Fly speed: metres per second at normal speed (Shift: 4x).
  void set_speed(double metres_per_s) { speed_m_s_ = metres_per_s; }
  // Orbit about this point from now on (a point picked under the cursor); the view is unchanged.
  void SetPivot(const Eigen::Vector3d& pivot);
  void Apply(const BrowseMotion& motion);

  const Eigen::Vector3d& eye() const { return eye_; }
  const Eigen::Vector3d& pivot() const { return pivot_; }
  Eigen::Vector3d Forward() const;  // unit view direction
  // A point straight ahead, at the pivot's distance (for LookAt).
  Eigen::Vector3d Target() const;
  Rigid3d WorldFromCamera() const;  // OpenCV camera convention (camera.h)

  static constexpr double kMaxPitchRad = 1.55;  // just short of straight up / down (LookAt stays defined)
  static constexpr double kRadPerPx = 0.005;

 private:
  Eigen::Vector3d eye_, pivot_;
  double yaw_ = 0, pitch_ = 0;  // view direction: yaw from +x counter-clockwise, pitch above horizontal
  double speed_m_s_ = 20;
};

}  // namespace ave::viewer
