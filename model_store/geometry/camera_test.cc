#include "model_store/geometry/camera.h"

#include <cmath>

#include <gtest/gtest.h>

namespace ave {
namespace {

// The GL matrices must put a world point on the same pixel as the pinhole model: this is what
// makes projective texturing in the viewer land where the camera saw it.
TEST(Camera, GlMatricesAgreeWithPinholeProjection) {
  PinholeIntrinsics k = PinholeIntrinsics::FromFov(640, 480, 60);
  k.cx = 300.25;
  k.cy = 250.75;
  const Rigid3d world_from_camera = LookAt({10, -20, 15}, {30, 40, 0});
  const Eigen::Matrix4d clip_from_world = GlProjection(k, 0.5, 500) * GlViewFromWorld(world_from_camera);
  for (const Eigen::Vector3d& p : {Eigen::Vector3d(30, 40, 0), Eigen::Vector3d(25, 35, 2), Eigen::Vector3d(12, 30, -1)}) {
    const auto uv = ProjectToPixel(k, world_from_camera.Inverse() * p);
    ASSERT_TRUE(uv.has_value());
    const Eigen::Vector4d clip = clip_from_world * p.homogeneous();
    ASSERT_GT(clip.w(), 0);
    const double ndc_x = clip.x() / clip.w(), ndc_y = clip.y() / clip.w();
    EXPECT_NEAR(ndc_x, 2 * (uv->x() + 0.5) / k.width - 1, 1e-9);
    EXPECT_NEAR(ndc_y, 1 - 2 * (uv->y() + 0.5) / k.height, 1e-9);
  }
}

TEST(Camera, PointsBehindTheCameraDoNotProject) {
  const PinholeIntrinsics k = PinholeIntrinsics::FromFov(640, 480, 60);
  EXPECT_FALSE(ProjectToPixel(k, {0, 0, -1}).has_value());
  EXPECT_FALSE(ProjectToPixel(k, {1, 1, 0}).has_value());
  EXPECT_FALSE(ProjectToPixel(k, {NAN, 0, 1}).has_value());
  EXPECT_TRUE(ProjectToPixel(k, {0, 0, 1}).has_value());
}

TEST(Camera, LookingStraightDownOrUpStaysFiniteAndOrthonormal) {
  for (const Eigen::Vector3d& target : {Eigen::Vector3d(0, 0, -10), Eigen::Vector3d(0, 0, 10), Eigen::Vector3d(0, 0, 0)}) {
    const Rigid3d pose = LookAt({0, 0, 0.0}, target);
    const Eigen::Matrix3d r = pose.rotation.toRotationMatrix();
    ASSERT_TRUE(r.allFinite());
    EXPECT_NEAR((r.transpose() * r - Eigen::Matrix3d::Identity()).norm(), 0, 1e-12);
    EXPECT_NEAR(r.determinant(), 1, 1e-12);
  }
  // Optical axis really points at the target.
  const Rigid3d down = LookAt({5, 5, 50}, {5, 5, 0});
  EXPECT_NEAR((down.rotation * Eigen::Vector3d::UnitZ() - Eigen::Vector3d(0, 0, -1)).norm(), 0, 1e-12);
}

TEST(Camera, PixelRayRoundTrips) {
  const PinholeIntrinsics k = PinholeIntrinsics::FromFov(1920, 1080, 90);
  for (const Eigen::Vector2d& uv : {Eigen::Vector2d(0, 0), Eigen::Vector2d(1919, 1079), Eigen::Vector2d(960.3, 10)}) {
    const auto back = ProjectToPixel(k, 7.5 * PixelRay(k, uv));
    ASSERT_TRUE(back.has_value());
    EXPECT_NEAR((*back - uv).norm(), 0, 1e-9);
  }
}

TEST(Camera, CheckNamesTheBadField) {
  PinholeIntrinsics k = PinholeIntrinsics::FromFov(640, 480, 60);
  EXPECT_EQ(k.Check(), "");
  k.fx = NAN;
  EXPECT_NE(k.Check().find("fx"), std::string::npos);
  k = PinholeIntrinsics::FromFov(640, 480, 60);
  k.cy = 5000;
  EXPECT_NE(k.Check().find("cy"), std::string::npos);
  k = PinholeIntrinsics::FromFov(0, 480, 60);
  EXPECT_NE(k.Check().find("width"), std::string::npos);
}

// At UTM-like magnitudes the transform chain must keep millimetres (double everywhere).
TEST(Camera, LargeWorldCoordinatesKeepMillimetres) {
  const Eigen::Vector3d eye(384512.25, 3768201.5, 95.0);
  const Rigid3d pose = LookAt(eye, eye + Eigen::Vector3d(10, 10, -5));
  const Eigen::Vector3d p = eye + Eigen::Vector3d(20.001, 20.0, -10.0);
  const Eigen::Vector3d back = pose * (pose.Inverse() * p);
  EXPECT_NEAR((back - p).norm(), 0, 1e-6);
}

}  // namespace
}  // namespace ave
