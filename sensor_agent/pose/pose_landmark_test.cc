// Landmarks in the pose filter's state (issue 19): estimated points whose cross-covariances with
// the pose are kept, so observing them cannot make the pose more certain than they are.
#include <cmath>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "sensor_agent/pose/pose_ekf.h"
#include "sensor_agent/pose/so3.h"

namespace ave::pose {
namespace {

constexpr double kDeg = 3.14159265358979323846 / 180;

PinholeIntrinsics Camera() {
  PinholeIntrinsics k;
  k.width = 640, k.height = 480, k.fx = 500, k.fy = 500, k.cx = 319.5, k.cy = 239.5;
  return k;
}

TEST(PoseEkfLandmarks, RepeatedSightingsOfAnUncertainPointDoNotMakeThePoseOverconfident) {
  const Rigid3d truth = LookAt(Eigen::Vector3d(0, 0, 1.7), Eigen::Vector3d(0, 10, 1.7));
  const Eigen::Vector3d point(1.0, 12.0, 3.0);
  const auto uv = ProjectToPixel(Camera(), truth.Inverse() * point);
  ASSERT_TRUE(uv);
  const Eigen::Matrix3d point_cov = Eigen::Matrix3d::Identity() * 0.5 * 0.5;
  PoseEkf joint, naive;
  joint.Initialize(0, truth, 1.0, 2 * kDeg);
  naive.Initialize(0, truth, 1.0, 2 * kDeg);
  ASSERT_TRUE(joint.AddLandmark(7, point, point_cov));
  EXPECT_FALSE(joint.AddLandmark(7, point, point_cov)) << "duplicate id";
  EXPECT_FALSE(joint.AddLandmark(8, point, -point_cov)) << "not positive definite";
  EXPECT_FALSE(joint.AddLandmark(9, Eigen::Vector3d(NAN, 0, 0), point_cov));
  EXPECT_EQ(joint.landmark_count(), 1);
  for (int i = 0; i < 50; ++i) {
    ASSERT_TRUE(joint.UpdateLandmark(Camera(), 7, *uv).accepted()) << i;
    // The shortcut without cross-covariances: the estimated point taken as if it were known.
    naive.UpdatePoint(Camera(), point, *uv);
  }
  // One point fixes two directions of the image once; fifty sightings of it from one place do not
  // add information about the camera beyond the point's own uncertainty.
  const Matrix6d joint_pose = joint.PoseCovariance(), naive_pose = naive.PoseCovariance();
  const double naive_rot = naive_pose.bottomRightCorner<3, 3>().trace(), joint_rot = joint_pose.bottomRightCorner<3, 3>().trace();
  // Across the view ray (world x and z) the shortcut claims twice the certainty it has.
  EXPECT_GT(joint_pose(0, 0), 1.5 * naive_pose(0, 0));
  EXPECT_GT(joint_pose(2, 2), 1.5 * naive_pose(2, 2));
  EXPECT_GE(joint_rot, naive_rot);
  // The camera's tilt cannot be known better than the point's 0.5 m at 11 m allows (~0.045 rad).
  EXPECT_GT(std::sqrt(joint_pose(3, 3)), 0.5 * 0.5 / 11.0);
  EXPECT_TRUE(Eigen::LLT<Matrix12d>(joint.covariance()).info() == Eigen::Success);
  const auto l = joint.Landmark(7);
  ASSERT_TRUE(l);
  EXPECT_TRUE(Eigen::LLT<Eigen::Matrix3d>(l->second).info() == Eigen::Success);
  EXPECT_LT((l->first - point).norm(), 1e-6);  // seen exactly where it is
  // Removing it marginalises: the pose covariance is untouched.
  const Matrix12d before = joint.covariance();
  joint.RemoveLandmark(7);
  EXPECT_FALSE(joint.HasLandmark(7));
  EXPECT_EQ(joint.covariance(), before);
  EXPECT_EQ(joint.UpdateLandmark(Camera(), 7, *uv).rejection, Rejection::kNotFinite);
}

TEST(PoseEkfLandmarks, AnOffLandmarkIsPulledBackOnceKnownPointsFixThePose) {
  // The camera believes it is 0.4 m off; a landmark initialised from that belief is off the same way.
  // Known points then correct the pose, and the landmark seen from the corrected pose follows.
  const Rigid3d truth = LookAt(Eigen::Vector3d(0, 0, 1.7), Eigen::Vector3d(0, 10, 1.7));
  const Eigen::Vector3d offset(0.4, 0, 0);
  PoseEkf ekf;
  ekf.Initialize(0, Rigid3d(truth.rotation, truth.translation + offset), 0.5, 0.2 * kDeg);
  const Eigen::Vector3d landmark(-2.0, 15.0, 2.5);
  // Its estimate shares the camera's error: covariance = camera position covariance + a little.
  ASSERT_TRUE(ekf.AddLandmark(1, landmark + offset, Eigen::Matrix3d::Identity() * 0.3 * 0.3));
  const std::vector<Eigen::Vector3d> known = {{3, 8, 0}, {3, 8, 6}, {-4, 20, 0}, {-4, 20, 9}, {6, 30, 4}};
  for (int round = 0; round < 3; ++round) {
    for (const Eigen::Vector3d& p : known) ekf.UpdatePoint(Camera(), p, *ProjectToPixel(Camera(), truth.Inverse() * p));
    ekf.UpdateLandmark(Camera(), 1, *ProjectToPixel(Camera(), truth.Inverse() * landmark));
  }
  EXPECT_LT((ekf.world_from_camera().translation - truth.translation).norm(), 0.1);
  EXPECT_LT((ekf.Landmark(1)->first - landmark).norm(), 0.25);
}

}  // namespace
}  // namespace ave::pose
