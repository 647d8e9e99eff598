// Landmarks in the pose filter's state (issue 19): estimated points whose cross-covariances with
// the pose are kept, so observing them cannot make the pose more certain than they are.
#include <cmath>
#include <random>
#include <vector>

#include <Eigen/Cholesky>

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
  EXPECT_TRUE(Eigen::LLT<StateMatrix>(joint.covariance()).info() == Eigen::Success);
  const auto l = joint.Landmark(7);
  ASSERT_TRUE(l);
  EXPECT_TRUE(Eigen::LLT<Eigen::Matrix3d>(l->second).info() == Eigen::Success);
  EXPECT_LT((l->first - point).norm(), 1e-6);  // seen exactly where it is
  // Removing it marginalises: the pose covariance is untouched.
  const StateMatrix before = joint.covariance();
  joint.RemoveLandmark(7);
  EXPECT_FALSE(joint.HasLandmark(7));
  EXPECT_EQ(joint.covariance(), before);
  EXPECT_EQ(joint.UpdateLandmark(Camera(), 7, *uv).rejection, Rejection::kNotFinite);
}

TEST(PoseEkfLandmarks, AnOffLandmarkFollowsThePoseOnceKnownPointsFixIt) {
  // The camera believes it is 0.4 m off; a landmark initialised from that belief is off the same way,
  // and its cross-covariance says so: known points then correct the pose, and the landmark moves
  // with it before it is seen again; seen from the corrected pose it agrees.
  const Rigid3d truth = LookAt(Eigen::Vector3d(0, 0, 1.7), Eigen::Vector3d(0, 10, 1.7));
  const Eigen::Vector3d offset(0.4, 0, 0);
  PoseEkf ekf;
  ekf.Initialize(0, Rigid3d(truth.rotation, truth.translation + offset), 0.5, 0.2 * kDeg);
  const Eigen::Vector3d landmark(-2.0, 15.0, 2.5);
  const Eigen::Vector3d in_camera = truth.Inverse() * landmark;
  ASSERT_TRUE(ekf.AddLandmarkOnRay(1, Camera(), *ProjectToPixel(Camera(), in_camera), in_camera.z(), 0.3, 1.0));
  EXPECT_LT((ekf.Landmark(1)->first - (landmark + offset)).norm(), 1e-9);
  const std::vector<Eigen::Vector3d> known = {{3, 8, 0}, {3, 8, 6}, {-4, 20, 0}, {-4, 20, 9}, {6, 30, 4}};
  for (int round = 0; round < 3; ++round) {
    for (const Eigen::Vector3d& p : known) ekf.UpdatePoint(Camera(), p, *ProjectToPixel(Camera(), truth.Inverse() * p));
  }
  EXPECT_LT((ekf.world_from_camera().translation - truth.translation).norm(), 0.1);
  EXPECT_LT((ekf.Landmark(1)->first - landmark).norm(), 0.1) << "the cross-covariance carries the pose's correction to the landmark";
  EXPECT_TRUE(ekf.UpdateLandmark(Camera(), 1, *ProjectToPixel(Camera(), in_camera)).accepted());
  EXPECT_LT((ekf.Landmark(1)->first - landmark).norm(), 0.1);
  EXPECT_TRUE(Eigen::LLT<Eigen::MatrixXd>(ekf.FullCovariance()).info() == Eigen::Success);
}

// The issue-19 bug (new features in the state made the pose worse, 6.6 px vs 0.6 px): a feature's
// 3D point was computed from the filter's own pose estimate but joined the state with zero
// cross-covariance, as if it were independent evidence. Seeing it again then "confirms" the pose's
// own error and shrinks the pose covariance around it. Monte Carlo against the truth, seeded: the
// pose error is drawn from the filter's covariance, landmarks are initialised from the erroneous
// pose at a noisy depth, then seen ten times each with pixel noise. A consistent filter has mean
// NEES = the dimension (6 for the pose); without the cross terms it is several times that.
TEST(PoseEkfLandmarks, LandmarksInitialisedFromThePoseKeepThePoseNeesConsistent) {
  const Rigid3d truth = LookAt(Eigen::Vector3d(0, 0, 1.7), Eigen::Vector3d(0, 10, 1.7));
  const std::vector<Eigen::Vector3d> points = {{-3, 6, 0.5}, {2, 7, 3}, {4, 9, 1}, {-5, 11, 4}, {0, 12, 6}, {6, 14, 2}, {-2, 15, 0.2}, {3, 8, -0.5}};
  PoseFilterOptions fo;
  fo.pixel_sigma_px = 1.0;
  fo.gate_chi2_2dof = 1e9;  // no gating: the statistics must not be censored
  // Pose errors of a filter locked on by vision (0.1 m, 0.3°). At 0.3 m and 1° the linearisation
  // at moving estimates (the EKF-SLAM inconsistency First-Estimates Jacobians address) already shows:
  // the pose NEES is 8.2 instead of 6 after 80 sightings from one place.
  const double pos_sigma = 0.1, rot_sigma = 0.3 * kDeg, depth_sigma = 0.5, px_sigma = 1.0;
  std::mt19937 rng(19);
  std::normal_distribution<double> normal(0.0, 1.0);
  auto gauss3 = [&](double s) -> Eigen::Vector3d { return Eigen::Vector3d(normal(rng), normal(rng), normal(rng)) * s; };
  double nees_joint = 0, nees_uncorrelated = 0, nees_full = 0;
  constexpr int kTrials = 200;
  for (int trial = 0; trial < kTrials; ++trial) {
    // Truth = (Exp(dtheta) q_est, p_est + dp): the estimate is off by a draw from its covariance.
    const Eigen::Vector3d dp = gauss3(pos_sigma), dtheta = gauss3(rot_sigma);
    const Rigid3d estimate((SO3Exp(-dtheta) * truth.rotation).normalized(), truth.translation - dp);
    PoseEkf joint(fo), uncorrelated(fo);
    joint.Initialize(0, estimate, pos_sigma, rot_sigma);
    uncorrelated.Initialize(0, estimate, pos_sigma, rot_sigma);
    for (size_t i = 0; i < points.size(); ++i) {
      const Eigen::Vector3d c = truth.Inverse() * points[i];
      const Eigen::Vector2d uv = *ProjectToPixel(Camera(), c) + Eigen::Vector2d(normal(rng), normal(rng)) * px_sigma;
      const double depth = c.z() + normal(rng) * depth_sigma;
      ASSERT_TRUE(joint.AddLandmarkOnRay(static_cast<int64_t>(i), Camera(), uv, depth, depth_sigma, px_sigma));
      // The old way: the same point and the same marginal covariance, no cross terms.
      const auto l = joint.Landmark(static_cast<int64_t>(i));
      ASSERT_TRUE(uncorrelated.AddLandmark(static_cast<int64_t>(i), l->first, l->second));
    }
    for (int round = 0; round < 10; ++round) {
      for (size_t i = 0; i < points.size(); ++i) {
        const Eigen::Vector2d uv = *ProjectToPixel(Camera(), truth.Inverse() * points[i]) + Eigen::Vector2d(normal(rng), normal(rng)) * px_sigma;
        ASSERT_TRUE(joint.UpdateLandmark(Camera(), static_cast<int64_t>(i), uv).accepted());
        ASSERT_TRUE(uncorrelated.UpdateLandmark(Camera(), static_cast<int64_t>(i), uv).accepted());
      }
    }
    auto pose_nees = [&](const PoseEkf& f) {
      Eigen::Matrix<double, 6, 1> e;
      e << truth.translation - f.world_from_camera().translation, SO3Log(truth.rotation * f.world_from_camera().rotation.conjugate());
      return e.dot(f.PoseCovariance().ldlt().solve(e));
    };
    nees_joint += pose_nees(joint) / kTrials;
    nees_uncorrelated += pose_nees(uncorrelated) / kTrials;
    // Pose and landmarks together (6 + 24 dof).
    const int n = 3 * static_cast<int>(points.size());
    Eigen::VectorXd e(6 + n);
    e.head<3>() = truth.translation - joint.world_from_camera().translation;
    e.segment<3>(3) = SO3Log(truth.rotation * joint.world_from_camera().rotation.conjugate());
    for (size_t i = 0; i < points.size(); ++i) e.segment<3>(6 + 3 * i) = points[i] - joint.Landmark(static_cast<int64_t>(i))->first;
    const Eigen::MatrixXd full = joint.FullCovariance();
    Eigen::MatrixXd c(6 + n, 6 + n);
    const std::vector<int> rows = [&] {
      std::vector<int> r = {kPos, kPos + 1, kPos + 2, kRot, kRot + 1, kRot + 2};
      for (int i = 0; i < n; ++i) r.push_back(kErrorDim + i);
      return r;
    }();
    for (int a = 0; a < 6 + n; ++a)
      for (int b = 0; b < 6 + n; ++b) c(a, b) = full(rows[a], rows[b]);
    nees_full += e.dot(c.ldlt().solve(e)) / kTrials;
  }
  // 200 trials: the mean of chi2(6) lies in 6 +- 0.5 at 95 %; linearisation adds a little.
  EXPECT_GT(nees_joint, 4.5) << "uncorrelated " << nees_uncorrelated << " full " << nees_full;
  EXPECT_LT(nees_joint, 7.5);
  EXPECT_GT(nees_full, 0.8 * 30);
  EXPECT_LT(nees_full, 1.25 * 30);
  // Without the cross terms the pose claims a certainty it does not have.
  EXPECT_GT(nees_uncorrelated, 3 * nees_joint) << "joint " << nees_joint << " uncorrelated " << nees_uncorrelated;
}

// Issue 19: a landmark's sightings may carry a persisting error (its track's offset repeats); as a
// consider bias it widens the reported pose covariance and leaves the estimate and the filter's own
// covariance as they were.
TEST(PoseEkfLandmarks, APersistingSightingBiasWidensOnlyTheReportedCovariance) {
  const Rigid3d truth = LookAt(Eigen::Vector3d(0, 0, 1.7), Eigen::Vector3d(0, 10, 1.7));
  const Eigen::Vector3d point(1.0, 12.0, 3.0);
  const auto uv = ProjectToPixel(Camera(), truth.Inverse() * point);
  ASSERT_TRUE(uv);
  PoseEkf plain, biased;
  for (PoseEkf* f : {&plain, &biased}) {
    f->Initialize(0, truth, 0.5, 1 * kDeg);
    ASSERT_TRUE(f->AddLandmark(7, point + Eigen::Vector3d(0.1, 0, -0.05), Eigen::Matrix3d::Identity() * 0.01));
  }
  for (int i = 1; i <= 30; ++i) {
    const Eigen::Vector2d seen = *uv + Eigen::Vector2d(0.7, -0.4);  // the same offset every time
    ASSERT_TRUE(plain.UpdateLandmark(Camera(), 7, seen).accepted());
    ASSERT_TRUE(biased.UpdateLandmark(Camera(), 7, seen, 0, {100, 1.0}).accepted());
  }
  EXPECT_TRUE(biased.world_from_camera().translation.isApprox(plain.world_from_camera().translation, 1e-12));
  EXPECT_EQ(biased.covariance(), plain.covariance());
  EXPECT_EQ(biased.considered_bias_count(), 1);
  EXPECT_GT(biased.PoseCovariance().trace(), plain.PoseCovariance().trace());
  EXPECT_EQ(plain.considered_bias_count(), 0);
}

// Issue 19, twelfth session: known corners whose detections carry persisting biases (drawn per
// trial, 1 px, declared to the filter as consider biases) leave the pose off by an error that only
// the reported covariance covers. Landmarks placed on rays from that pose inherit the error. Seen
// again after the camera has moved 1.5 m sideways (a precise position fix moves the filter), they
// measure the pose against themselves, so the biases' part of the error is in both. The reported
// pose covariance stays consistent (mean NEES ~6) only if the landmarks' rows of the bias
// sensitivities are kept: without them every sighting shrank the pose's bias covariance as if the
// landmark were independent evidence (mean NEES 14.8 here against 6.1; the joint mode's pose under-covered its
// error at 2-3 s of the campus run).
TEST(PoseEkfLandmarks, LandmarksPlacedFromABiasedPoseKeepItsReportedCovarianceConsistent) {
  const Rigid3d first = LookAt(Eigen::Vector3d(0, 0, 1.7), Eigen::Vector3d(0, 10, 1.7));
  const Rigid3d second = LookAt(Eigen::Vector3d(1.5, 0, 1.7), Eigen::Vector3d(1.5, 10, 1.7));
  const std::vector<Eigen::Vector3d> corners = {{-6, 18, 0}, {5, 20, 0}, {-7, 22, 9}, {6, 24, 8}, {0, 25, 4}, {-2, 16, 6}};
  const std::vector<Eigen::Vector3d> points = {{-3, 8, 0.5}, {2, 9, 3}, {4, 11, 1}, {-4, 12, 4}, {0, 13, 5}, {3, 14, 2}};
  PoseFilterOptions fo;
  fo.pixel_sigma_px = 0.3;
  fo.gate_chi2_2dof = fo.gate_chi2_3dof = 1e9;  // no gating: the statistics must not be censored
  fo.gps_bias_sigma_m = 0, fo.gps_min_sigma_m = 0.01;
  const double pos_sigma = 0.1, rot_sigma = 0.3 * kDeg, bias_px = 1.0, depth_sigma = 0.3;
  std::mt19937 rng(1912);
  std::normal_distribution<double> normal(0.0, 1.0);
  auto gauss2 = [&](double s) -> Eigen::Vector2d { return Eigen::Vector2d(normal(rng), normal(rng)) * s; };
  auto gauss3 = [&](double s) -> Eigen::Vector3d { return Eigen::Vector3d(normal(rng), normal(rng), normal(rng)) * s; };
  constexpr int kTrials = 300;
  double nees = 0, bias_share = 0;
  for (int trial = 0; trial < kTrials; ++trial) {
    const Rigid3d estimate((SO3Exp(-gauss3(rot_sigma)) * first.rotation).normalized(), first.translation - gauss3(pos_sigma));
    PoseEkf f(fo);
    f.Initialize(0, estimate, pos_sigma, rot_sigma);
    std::vector<Eigen::Vector2d> bias;
    for (size_t c = 0; c < corners.size(); ++c) bias.push_back(gauss2(bias_px));
    for (int round = 0; round < 3; ++round)
      for (size_t c = 0; c < corners.size(); ++c) {
        const Eigen::Vector2d uv = *ProjectToPixel(Camera(), first.Inverse() * corners[c]) + bias[c] + gauss2(fo.pixel_sigma_px);
        ASSERT_TRUE(f.UpdatePoint(Camera(), corners[c], uv, 0, {PointBias{static_cast<int64_t>(c), bias_px}, PointBias{}}).accepted());
      }
    for (size_t i = 0; i < points.size(); ++i) {
      const Eigen::Vector3d c = first.Inverse() * points[i];
      const Eigen::Vector2d uv = *ProjectToPixel(Camera(), c) + gauss2(fo.pixel_sigma_px);
      ASSERT_TRUE(f.AddLandmarkOnRay(static_cast<int64_t>(100 + i), Camera(), uv, c.z() + normal(rng) * depth_sigma, depth_sigma,
                                     fo.pixel_sigma_px));
    }
    // The walk to the second place, unknown to the filter but for a precise fix there.
    f.InflatePose(2.0, 0);
    ASSERT_TRUE(f.UpdatePosition(second.translation + gauss3(0.01), Eigen::Matrix3d::Identity() * 1e-4).accepted());
    for (int round = 0; round < 5; ++round)
      for (size_t i = 0; i < points.size(); ++i) {
        const Eigen::Vector2d uv = *ProjectToPixel(Camera(), second.Inverse() * points[i]) + gauss2(fo.pixel_sigma_px);
        const UpdateResult r = f.UpdateLandmark(Camera(), static_cast<int64_t>(100 + i), uv);
        ASSERT_TRUE(r.accepted()) << RejectionName(r.rejection) << " " << r.mahalanobis_sq << " trial " << trial << " point " << i;
      }
    Eigen::Matrix<double, 6, 1> e;
    e << second.translation - f.world_from_camera().translation, SO3Log(second.rotation * f.world_from_camera().rotation.conjugate());
    const Matrix6d reported = f.PoseCovariance();
    ASSERT_TRUE(reported.allFinite());
    nees += e.dot(reported.ldlt().solve(e)) / kTrials;
    bias_share += f.ConsideredBiasCovariance().block<3, 3>(kRot, kRot).trace() / reported.bottomRightCorner<3, 3>().trace() / kTrials;
  }
  // The biases matter here: most of the orientation's reported variance is theirs.
  EXPECT_GT(bias_share, 0.5) << nees;
  // 300 trials: the mean of chi2(6) lies in 6 +- 0.4 at 95 %; linearisation adds a little.
  EXPECT_GT(nees, 4.5) << "bias share " << bias_share;
  EXPECT_LT(nees, 7.5) << "bias share " << bias_share;
}

// The landmarks' rows of the bias sensitivities stay in step with the biases and the landmarks
// through every change of size: landmarks that join before any bias exists, biases that join after,
// more biases than the filter keeps (the weakest is forgotten, 256 at most), a landmark removed from
// the middle, and a new Initialize. The covariance stays finite and symmetric throughout.
TEST(PoseEkfLandmarks, BiasSensitivitiesFollowEveryChangeOfSize) {
  const Rigid3d truth = LookAt(Eigen::Vector3d(0, 0, 1.7), Eigen::Vector3d(0, 10, 1.7));
  PoseEkf f;
  f.Initialize(0, truth, 0.3, 1 * kDeg);
  for (int64_t id = 0; id < 3; ++id)
    ASSERT_TRUE(f.AddLandmarkOnRay(id, Camera(), Eigen::Vector2d(200 + 100 * id, 200), 10 + id, 0.5, 1.0));
  auto healthy = [&](const char* when) {
    const StateMatrix b = f.ConsideredBiasCovariance();
    EXPECT_TRUE(b.allFinite()) << when;
    EXPECT_TRUE(b.isApprox(b.transpose(), 1e-9)) << when;
    EXPECT_TRUE(f.FullCovariance().allFinite()) << when;
    EXPECT_TRUE(f.PoseCovariance().allFinite()) << when;
  };
  // 300 corners, each with its own bias, interleaved with landmark sightings carrying theirs.
  for (int c = 0; c < 300; ++c) {
    const Eigen::Vector3d corner(-8 + (c % 17), 20 + (c % 7), (c % 5) * 2.0);
    const auto uv = ProjectToPixel(Camera(), truth.Inverse() * corner);
    ASSERT_TRUE(uv);
    f.UpdatePoint(Camera(), corner, *uv + Eigen::Vector2d(0.2, -0.1), 0, {PointBias{1000 + c, 1.0}, PointBias{}});
    const int64_t id = c % 3;
    if (f.HasLandmark(id)) f.UpdateLandmark(Camera(), id, *ProjectToPixel(Camera(), truth.Inverse() * f.Landmark(id)->first), 0, {2000 + id, 2.0});
    if (c == 150) {
      f.RemoveLandmark(1);
      ASSERT_TRUE(f.AddLandmarkOnRay(7, Camera(), Eigen::Vector2d(320, 260), 12, 0.5, 1.0));
    }
  }
  EXPECT_EQ(f.considered_bias_count(), 256);
  EXPECT_EQ(f.landmark_count(), 3);
  healthy("after 300 biases");
  f.RemoveLandmark(0);
  healthy("after a removal");
  f.Initialize(1, truth, 0.3, 1 * kDeg);  // the landmarks stay; their bias rows start again empty
  EXPECT_EQ(f.considered_bias_count(), 0);
  EXPECT_TRUE(f.UpdateLandmark(Camera(), 7, *ProjectToPixel(Camera(), truth.Inverse() * f.Landmark(7)->first), 0, {5, 1.0}).accepted());
  healthy("after Initialize");
  EXPECT_EQ(f.considered_bias_count(), 1);
}

}  // namespace
}  // namespace ave::pose
