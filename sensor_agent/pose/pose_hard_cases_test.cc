// The numerically hard cases of issue 19 that pose_ekf_test.cc and pose_inputs_test.cc do not
// already cover: a huge time step, GPS out for the whole run, features all on one line, a line at
// infinity (the sky line), a half-turn in one second with world coordinates near 1e6 m.
#include <cmath>
#include <limits>
#include <random>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "sensor_agent/pose/pose_ekf.h"
#include "sensor_agent/pose/pose_inputs.h"
#include "sensor_agent/pose/so3.h"

namespace ave::pose {
namespace {

constexpr double kDeg = 3.14159265358979323846 / 180;
constexpr int64_t kSecond = 1'000'000'000;

PinholeIntrinsics Camera() {
  PinholeIntrinsics k;
  k.width = 640, k.height = 480, k.fx = 500, k.fy = 500, k.cx = 319.5, k.cy = 239.5;
  return k;
}

bool IsSpd(const StateMatrix& P) {
  if (!P.allFinite() || P != P.transpose()) return false;
  return Eigen::LLT<StateMatrix>(P).info() == Eigen::Success;
}

TEST(PoseEkfHardCases, AHugeTimeStepStaysFiniteAndTheNextFixPullsThePositionBack) {
  PoseEkf ekf;
  ekf.Initialize(0, Rigid3d(), 0.3, 1 * kDeg);
  // A day without any measurement (predicted in 5 s steps): the uncertainty explodes, the state does not.
  ASSERT_TRUE(ekf.Predict(24LL * 3600 * kSecond).accepted());
  EXPECT_TRUE(IsSpd(ekf.covariance()));
  EXPECT_TRUE(ekf.world_from_camera().translation.allFinite());
  EXPECT_NEAR(ekf.world_from_camera().rotation.norm(), 1.0, 1e-12);
  EXPECT_GT(ekf.covariance()(kPos, kPos), 1e6);
  // A fix afterwards is accepted (not gated: the filter knows it is lost) and lands the position.
  const Eigen::Vector3d fix(12.0, -3.0, 1.7);
  ASSERT_TRUE(ekf.UpdatePosition(fix, Eigen::Matrix3d::Identity() * 0.05 * 0.05).accepted());
  EXPECT_LT((ekf.world_from_camera().translation - fix).norm(), 0.5);
  EXPECT_TRUE(IsSpd(ekf.covariance()));
}

TEST(PoseEkfHardCases, AllFeaturesOnOneWallEdgeKeepTheCovarianceSpdAndDoNotInventPosition) {
  // Ten points on one vertical edge 10 m ahead: the camera's distance along the view ray and its
  // rotation about the edge are poorly constrained; the updates must not make them up.
  const Rigid3d truth = LookAt(Eigen::Vector3d(0, 0, 1.7), Eigen::Vector3d(0, 10, 1.7));
  PoseEkf ekf;
  ekf.Initialize(0, Rigid3d(truth.rotation, truth.translation + Eigen::Vector3d(0.2, 0.3, 0)), 0.5, 1 * kDeg);
  const StateMatrix before = ekf.covariance();
  for (int round = 0; round < 20; ++round) {
    for (int i = 0; i < 10; ++i) {
      const Eigen::Vector3d p(0.5, 10, 0.3 * i);
      const auto uv = ProjectToPixel(Camera(), truth.Inverse() * p);
      ASSERT_TRUE(uv);
      ekf.UpdatePoint(Camera(), p, *uv);
      ASSERT_TRUE(IsSpd(ekf.covariance())) << round << " " << i;
    }
  }
  // Collinear points still fix the edge's image: they line up again.
  const auto top = ekf.ProjectPoint(Camera(), Eigen::Vector3d(0.5, 10, 2.7));
  ASSERT_TRUE(top);
  EXPECT_LT((*top - *ProjectToPixel(Camera(), truth.Inverse() * Eigen::Vector3d(0.5, 10, 2.7))).norm(), 1.0);
  // Nothing is made up: the estimate stays near the truth and every variance stays positive.
  EXPECT_LT((ekf.world_from_camera().translation - truth.translation).norm(), 0.5);
  EXPECT_GT(ekf.covariance().diagonal().minCoeff(), 0);
  EXPECT_LE(ekf.covariance().trace(), before.trace());
}

TEST(PoseEkfHardCases, ASkyLineAtInfinityCorrectsOrientationOnly) {
  const Rigid3d truth = LookAt(Eigen::Vector3d(0, 0, 1.7), Eigen::Vector3d(0, 100, 1.7));
  PoseEkf ekf;
  const Eigen::Quaterniond tilted = SO3Exp(Eigen::Vector3d(1.0 * kDeg, 0, 0)) * truth.rotation;
  ekf.Initialize(0, Rigid3d(tilted, truth.translation), 0.5, 2 * kDeg);
  // The horizon 1e7 m away as an infinite horizontal line seen across the whole image.
  const Line3d horizon{Eigen::Vector3d(0, 1e7, 1.7), Eigen::Vector3d::UnitX()};
  const auto a = ProjectToPixel(Camera(), truth.Inverse() * Eigen::Vector3d(-1e6, 1e7, 1.7));
  const auto b = ProjectToPixel(Camera(), truth.Inverse() * Eigen::Vector3d(1e6, 1e7, 1.7));
  ASSERT_TRUE(a && b);
  const double pitch_before = AngleBetweenDeg(ekf.world_from_camera().rotation, truth.rotation);
  for (int i = 0; i < 5; ++i) ASSERT_TRUE(ekf.UpdateLine(Camera(), horizon, *a, *b).accepted()) << i;
  EXPECT_LT(AngleBetweenDeg(ekf.world_from_camera().rotation, truth.rotation), 0.2 * pitch_before);
  EXPECT_LT((ekf.world_from_camera().translation - truth.translation).norm(), 1e-3);  // position unobservable from it
  EXPECT_TRUE(IsSpd(ekf.covariance()));
}

// GPS and AHRS readings of a camera at world coordinates near 1e6 m (local frame after the origin).
TEST(PoseTrackerHardCases, GpsOutForTheWholeRunGivesNoPoseAndNoNan) {
  SensorLog log;
  log.origin = Eigen::Vector3d(4.0e5, 4.4e6, 30);
  for (int64_t t = 0; t <= 10 * kSecond; t += kSecond / 5) log.gps.push_back({t, false, Eigen::Vector3d::Zero(), Eigen::Matrix3d::Zero()});
  for (int64_t t = 0; t <= 10 * kSecond; t += kSecond / 150) log.imu.push_back({t, Eigen::Quaterniond::Identity(), Eigen::Vector3d::Zero()});
  PoseTracker tracker(log);
  for (int64_t t = 0; t <= 10 * kSecond; t += kSecond / 30) {
    const PoseSample s = tracker.Advance(t);
    ASSERT_FALSE(s.valid) << t;  // no pose is better than an invented one
    ASSERT_TRUE(s.covariance.allFinite());
  }
  EXPECT_EQ(tracker.stats().gps_used, 0);
  EXPECT_GE(tracker.stats().gps_dropouts, static_cast<int64_t>(log.gps.size()) - 1);  // all but the fix at 10 s, not yet due
}

TEST(PoseTrackerHardCases, AHalfTurnInOneSecondIsFollowedWithinTwoDegrees) {
  // The camera turns 180° about world up in one second while standing, GPS at 5 Hz and
  // AHRS + gyro at 150 Hz (0.5° noise); the local frame's origin is at ~1e6 m.
  std::mt19937_64 rng(3);
  std::normal_distribution<double> n(0, 1);
  SensorLog log;
  log.origin = Eigen::Vector3d(1.0e6, 1.0e6, 120);
  const Eigen::Quaterniond start = LookAt(Eigen::Vector3d::Zero(), Eigen::Vector3d(0, 1, 0)).rotation;
  // A smooth turn (smoothstep of the angle; peak 4.7 rad/s at 1.5 s), as a person turns.
  constexpr double kPi = 3.14159265358979323846;
  auto truth = [&](double t) {
    const double u = std::clamp(t - 1.0, 0.0, 1.0);
    return SO3Exp(Eigen::Vector3d(0, 0, kPi * u * u * (3 - 2 * u))) * start;
  };
  for (int64_t t = 0; t <= 3 * kSecond; t += kSecond / 5) {
    log.gps.push_back({t, true, Eigen::Vector3d(0, 0, 1.7) + 0.05 * Eigen::Vector3d(n(rng), n(rng), n(rng)), Eigen::Matrix3d::Identity() * 0.0025});
  }
  for (int64_t t = 0; t <= 3 * kSecond; t += kSecond / 150) {
    const double ts = t * 1e-9;
    const double u = std::clamp(ts - 1.0, 0.0, 1.0);
    const double rate = kPi * 6 * u * (1 - u);
    log.imu.push_back({t, truth(ts) * SO3Exp(0.5 * kDeg * Eigen::Vector3d(n(rng), n(rng), n(rng))),
                       truth(ts).conjugate() * Eigen::Vector3d(0, 0, rate)});
  }
  PoseTracker tracker(log);
  double worst_deg = 0;
  for (int64_t t = kSecond / 2; t <= 3 * kSecond; t += kSecond / 30) {
    const PoseSample s = tracker.Advance(t);
    ASSERT_TRUE(s.valid);
    ASSERT_TRUE(s.covariance.allFinite());
    worst_deg = std::max(worst_deg, AngleBetweenDeg(s.world_from_camera.rotation, truth(t * 1e-9)));
  }
  EXPECT_LT(worst_deg, 2.0);
  EXPECT_EQ(tracker.stats().imu_gated, 0);
  EXPECT_TRUE(IsSpd(tracker.filter().covariance()));
}

}  // namespace
}  // namespace ave::pose
