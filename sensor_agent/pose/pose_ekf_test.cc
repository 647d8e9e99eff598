#include "sensor_agent/pose/pose_ekf.h"

#include <cmath>
#include <limits>
#include <random>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "sensor_agent/pose/so3.h"

namespace ave::pose {
namespace {

constexpr double kDeg = 3.14159265358979323846 / 180;

PinholeIntrinsics Camera() {
  PinholeIntrinsics k;
  k.width = 640, k.height = 480, k.fx = 500, k.fy = 500, k.cx = 319.5, k.cy = 239.5;
  return k;
}

bool IsSpd(const StateMatrix& P) {
  if (P != P.transpose()) return false;  // exactly symmetric
  Eigen::LLT<StateMatrix> llt(P);
  return llt.info() == Eigen::Success;
}

// A filter on a camera at `pose` with the given 1-sigma.
PoseEkf Filter(const Rigid3d& pose, double pos_sigma = 1.0, double rot_sigma = 5 * kDeg) {
  PoseEkf ekf;
  ekf.Initialize(0, pose, pos_sigma, rot_sigma);
  return ekf;
}

TEST(So3, ExpLogRoundTripFromTinyAnglesToPi) {
  for (double angle : {0.0, 1e-12, 1e-7, 1e-3, 0.5, 3.0, 3.14159, 3.14159265358979}) {
    const Eigen::Vector3d w = angle * Eigen::Vector3d(1, -2, 0.5).normalized();
    const Eigen::Quaterniond q = SO3Exp(w);
    EXPECT_NEAR(q.norm(), 1.0, 1e-15);
    const Eigen::Vector3d back = SO3Log(q);
    EXPECT_TRUE(back.isApprox(w, 1e-9) || (angle > 3.14 && std::abs(back.norm() - angle) < 1e-9)) << angle << " " << back.transpose();
    EXPECT_TRUE(back.allFinite());
  }
}

TEST(PoseEkf, PointJacobianMatchesFiniteDifferences) {
  PoseEkf ekf = Filter(Rigid3d(SO3Exp(Eigen::Vector3d(0.3, -1.2, 0.4)), Eigen::Vector3d(1, 2, 3)));
  const Eigen::Vector3d point = ekf.world_from_camera() * Eigen::Vector3d(2, -1, 12);
  Eigen::Matrix<double, 2, kErrorDim> J;
  ASSERT_TRUE(ekf.ProjectPoint(Camera(), point, &J));
  // Perturb the point the other way: moving the point by +e is moving the camera by -e.
  for (int i = 0; i < 3; ++i) {
    const double h = 1e-6;
    Eigen::Vector3d e = Eigen::Vector3d::Zero();
    e(i) = h;
    const Eigen::Vector2d fd = (*ekf.ProjectPoint(Camera(), point - e) - *ekf.ProjectPoint(Camera(), point + e)) / (2 * h);
    EXPECT_TRUE(J.col(kPos + i).isApprox(fd, 1e-5)) << J.col(kPos + i).transpose() << " vs " << fd.transpose();
  }
  // Rotation: rotating the camera by Exp(d) about the world equals rotating the point, about the
  // camera centre, by Exp(-d).
  const Eigen::Vector3d c = ekf.world_from_camera().translation;
  for (int i = 0; i < 3; ++i) {
    const double h = 1e-6;
    Eigen::Vector3d d = Eigen::Vector3d::Zero();
    d(i) = h;
    const Eigen::Vector2d plus = *ekf.ProjectPoint(Camera(), c + SO3Exp(-d) * (point - c));
    const Eigen::Vector2d minus = *ekf.ProjectPoint(Camera(), c + SO3Exp(d) * (point - c));
    EXPECT_TRUE(J.col(kRot + i).isApprox((plus - minus) / (2 * h), 1e-5));
  }
}

// Issue 19 (NEES by cause): features found with a shared persisting offset (here +0.5 px in u,
// every sighting) leave an orientation error no number of sightings removes, and the filter's own
// covariance shrinks far below it. The consider term (SetConsideredOrientation) is added to the
// reported covariance only: the estimate and the filter's own covariance are bit-identical, and
// the reported orientation NEES comes back inside its chi2(3) 95 % bound.
TEST(PoseEkf, ConsideredOrientationCoversASharedFeatureBiasWithoutChangingTheEstimate) {
  const Eigen::Vector3d eye(2, 1, 1.7);
  const Rigid3d truth = LookAt(eye, eye + Eigen::Vector3d(0, 1, 0));
  PoseEkf plain = Filter(truth, 0.001, 0.5 * kDeg), considered = plain;  // position known: the rotation takes the bias
  const double bias_px = 0.5;
  considered.SetConsideredOrientation(truth.rotation.toRotationMatrix() * Eigen::Vector3d(0, 1, 0).asDiagonal() *
                                      truth.rotation.toRotationMatrix().transpose() * std::pow(bias_px / Camera().fx, 2));
  for (int round = 0; round < 20; ++round) {
    for (int i = -3; i <= 3; ++i) {
      for (int j = -2; j <= 2; ++j) {
        const Eigen::Vector3d p = eye + Eigen::Vector3d(4.0 * i, 40 + 5 * ((i + j + 9) % 4), 1.5 * j);
        const auto uv = ProjectToPixel(Camera(), truth.Inverse() * p);
        ASSERT_TRUE(uv);
        const Eigen::Vector2d seen = *uv + Eigen::Vector2d(bias_px, 0);
        plain.UpdatePoint(Camera(), p, seen);
        considered.UpdatePoint(Camera(), p, seen);
      }
    }
  }
  EXPECT_EQ(plain.world_from_camera().rotation.coeffs(), considered.world_from_camera().rotation.coeffs());
  EXPECT_EQ(plain.covariance(), considered.covariance());
  const Eigen::Vector3d e = SO3Log(truth.rotation * plain.world_from_camera().rotation.conjugate());
  const Eigen::Matrix3d own = plain.PoseCovariance().bottomRightCorner<3, 3>();
  const Eigen::Matrix3d reported = considered.PoseCovariance().bottomRightCorner<3, 3>();
  EXPECT_GT(e.dot(own.ldlt().solve(e)), 7.81);       // overconfident: the bias is not in it
  EXPECT_LT(e.dot(reported.ldlt().solve(e)), 7.81);  // consistent with the consider term
  // A covariance that is not positive semi-definite is ignored.
  considered.SetConsideredOrientation(-Eigen::Matrix3d::Identity());
  EXPECT_EQ((considered.PoseCovariance().bottomRightCorner<3, 3>()), reported);
}

// Issue 19, session pose19e: each of 12 points carries its own persisting pixel bias (drawn once
// per run), the same at all 20 of its sightings, plus white noise. The filter takes the sightings
// as independent, so its own covariance shrinks below the error the biases leave; with the bias
// named per point (UpdatePoint's bias id) the reported covariance follows the biases' effect
// through every update and is consistent: Monte Carlo over 300 seeded runs against the truth, the
// 6-dof pose NEES averages its dimension. The estimate is bit-identical either way.
TEST(PoseEkf, PerPointBiasesSharedBySightingsKeepTheReportedPoseNeesConsistent) {
  const Eigen::Vector3d eye(2, 1, 1.7);
  const Rigid3d truth = LookAt(eye, eye + Eigen::Vector3d(0, 1, 0));
  const double pos_sigma = 0.2, rot_sigma = 0.5 * kDeg, bias_px = 0.6, noise_px = 1.5;
  std::mt19937_64 rng(19);
  std::normal_distribution<double> n(0, 1);
  double own_sum = 0, reported_sum = 0;
  int reported_in_band = 0;
  constexpr int kRuns = 300;
  for (int run = 0; run < kRuns; ++run) {
    const Eigen::Vector3d dp = pos_sigma * Eigen::Vector3d(n(rng), n(rng), n(rng));
    const Eigen::Vector3d dr = rot_sigma * Eigen::Vector3d(n(rng), n(rng), n(rng));
    const Rigid3d start(SO3Exp(dr) * truth.rotation, truth.translation + dp);  // drawn from the prior covariance
    PoseEkf plain = Filter(start, pos_sigma, rot_sigma), biased = plain;
    std::vector<Eigen::Vector3d> points;
    std::vector<Eigen::Vector2d> biases;
    for (int i = -2; i <= 3; ++i) {
      for (int j = -1; j <= 0; ++j) {
        points.push_back(eye + Eigen::Vector3d(3.0 * i + j, 12 + 6 * ((i + 3 * j + 9) % 4), 2.0 * j + 0.5 * i));
        biases.emplace_back(bias_px * n(rng), bias_px * n(rng));
      }
    }
    for (int sighting = 0; sighting < 20; ++sighting) {
      for (size_t i = 0; i < points.size(); ++i) {
        const auto uv = ProjectToPixel(Camera(), truth.Inverse() * points[i]);
        ASSERT_TRUE(uv);
        const Eigen::Vector2d seen = *uv + biases[i] + noise_px * Eigen::Vector2d(n(rng), n(rng));
        ASSERT_EQ(plain.UpdatePoint(Camera(), points[i], seen).accepted(),
                  biased.UpdatePoint(Camera(), points[i], seen, 0, {{{static_cast<int64_t>(i), bias_px}}}).accepted());
      }
    }
    ASSERT_EQ(plain.world_from_camera().translation, biased.world_from_camera().translation);
    ASSERT_EQ(plain.world_from_camera().rotation.coeffs(), biased.world_from_camera().rotation.coeffs());
    ASSERT_EQ(plain.covariance(), biased.covariance());
    ASSERT_EQ(biased.considered_bias_count(), static_cast<int>(points.size()));
    Eigen::Matrix<double, 6, 1> e;
    e << truth.translation - plain.world_from_camera().translation, SO3Log(truth.rotation * plain.world_from_camera().rotation.conjugate());
    const double own = e.dot(plain.PoseCovariance().ldlt().solve(e)), reported = e.dot(biased.PoseCovariance().ldlt().solve(e));
    own_sum += own, reported_sum += reported;
    reported_in_band += reported >= 1.237 && reported <= 14.449;
  }
  EXPECT_GT(own_sum / kRuns, 9.0);  // the white-noise filter: overconfident
  EXPECT_NEAR(reported_sum / kRuns, 6.0, 0.9);  // the chi2(6) mean; its Monte Carlo sigma is 0.2
  EXPECT_GE(reported_in_band, 0.9 * kRuns);
}

// The bias every feature of a frame shares (a second id on every update) adds to the per-point
// ones, and a bias whose id is never seen again still counts until updates shrink it.
TEST(PoseEkf, ASharedBiasAddsToThePerPointOnesAndTheCovarianceStaysSymmetric) {
  const Eigen::Vector3d eye(0, 0, 1.7);
  const Rigid3d truth = LookAt(eye, eye + Eigen::Vector3d(0, 1, 0));
  PoseFilterOptions o;
  o.gps_bias_sigma_m = 0;  // the fixes below are to shrink the point biases' share only
  PoseEkf own(o);
  own.Initialize(0, truth, 0.2, 0.5 * kDeg);
  PoseEkf per_point = own, shared = own;
  for (int sighting = 0; sighting < 10; ++sighting) {
    for (int i = 0; i < 8; ++i) {
      const Eigen::Vector3d p = eye + Eigen::Vector3d(3.0 * (i % 4) - 4.5, 15 + 4 * i, i < 4 ? -1.0 : 4.0);
      const Eigen::Vector2d uv = *ProjectToPixel(Camera(), truth.Inverse() * p);
      own.UpdatePoint(Camera(), p, uv);
      per_point.UpdatePoint(Camera(), p, uv, 0, {{{i, 0.3}}});
      shared.UpdatePoint(Camera(), p, uv, 0, {{{i, 0.3}, {100, 0.3}}});
    }
  }
  const Matrix6d a = own.PoseCovariance(), b = per_point.PoseCovariance(), c = shared.PoseCovariance();
  EXPECT_EQ(b, b.transpose());
  EXPECT_EQ(shared.considered_bias_count(), 9);
  for (int i = 0; i < 6; ++i) {
    EXPECT_GT(b(i, i), a(i, i)) << i;
    EXPECT_GT(c(i, i), b(i, i)) << i;
  }
  // Without further sightings of these points, GPS-like position fixes shrink what the biases left.
  const double before = shared.ConsideredBiasCovariance().topLeftCorner<3, 3>().trace();
  for (int k = 0; k < 20; ++k) shared.UpdatePosition(truth.translation, Eigen::Matrix3d::Identity() * 0.01);
  const double after = shared.ConsideredBiasCovariance().topLeftCorner<3, 3>().trace();
  EXPECT_LT(after, 0.5 * before);
}

TEST(PoseEkf, PointUpdatesPullAPerturbedPoseToTheTruthEvenLookingStraightDownOrUp) {
  for (const double look : {-1.0, 1.0}) {  // straight down, straight up
    const Eigen::Vector3d eye(5, -3, 10);
    const Rigid3d truth = LookAt(eye, eye + Eigen::Vector3d(0, 0, look));
    PoseEkf ekf = Filter(Rigid3d(truth.rotation * SO3Exp(Eigen::Vector3d(0.02, -0.015, 0.03)), eye + Eigen::Vector3d(0.4, -0.3, 0.2)));
    std::vector<Eigen::Vector3d> points;
    for (int i = -2; i <= 2; ++i)
      for (int j = -2; j <= 2; ++j) points.push_back(eye + Eigen::Vector3d(3.0 * i, 2.5 * j, look * (8 + (i + j) % 3)));
    for (int round = 0; round < 5; ++round) {
      for (const auto& p : points) {
        const auto uv = ProjectToPixel(Camera(), truth.Inverse() * p);
        ASSERT_TRUE(uv);
        ekf.UpdatePoint(Camera(), p, *uv);
      }
    }
    EXPECT_LT((ekf.world_from_camera().translation - truth.translation).norm(), 0.02) << look;
    EXPECT_LT(AngleBetweenDeg(ekf.world_from_camera().rotation, truth.rotation), 0.05) << look;
    EXPECT_TRUE(IsSpd(ekf.covariance()));
  }
}

TEST(PoseEkf, LineUpdatesUseTheInfiniteLineAndItsJacobianIsConsistent) {
  const Rigid3d truth = LookAt(Eigen::Vector3d(0, -20, 1.7), Eigen::Vector3d(0, 0, 5));
  PoseEkf ekf = Filter(Rigid3d(truth.rotation * SO3Exp(Eigen::Vector3d(0.01, 0.02, -0.01)), truth.translation + Eigen::Vector3d(0.3, 0, 0)));
  // Vertical and horizontal building edges; observed segments are arbitrary parts of them.
  std::vector<Line3d> lines;
  for (double x : {-6.0, -2.0, 3.0, 7.0}) lines.push_back({{x, 0, 0}, {0, 0, 1}});
  for (double z : {2.0, 9.0}) lines.push_back({{0, 0, z}, {1, 0, 0}});
  lines.push_back({{0, 5, 0}, {0, 1, 0}});  // going away from the camera
  for (int round = 0; round < 6; ++round) {
    for (const Line3d& l : lines) {
      const auto a = ProjectToPixel(Camera(), truth.Inverse() * (l.point + (1.0 + round) * l.direction));
      const auto b = ProjectToPixel(Camera(), truth.Inverse() * (l.point + (4.0 + round) * l.direction));
      ASSERT_TRUE(a && b);
      Eigen::Matrix<double, 2, kErrorDim> J;
      const auto r = ekf.LineResidual(Camera(), l, *a, *b, &J);
      ASSERT_TRUE(r);
      EXPECT_TRUE(J.allFinite());
      ekf.UpdateLine(Camera(), l, *a, *b);
    }
  }
  // Lines alone fix the orientation and the position across the lines.
  EXPECT_LT(AngleBetweenDeg(ekf.world_from_camera().rotation, truth.rotation), 0.05);
  EXPECT_LT(std::abs(ekf.world_from_camera().translation.x() - truth.translation.x()), 0.02);
}

TEST(PoseEkf, FeaturesBehindTheCameraAreRejectedAndHorizonFeaturesAreHarmless) {
  const Rigid3d truth = LookAt(Eigen::Vector3d(0, 0, 1.7), Eigen::Vector3d(0, 100, 1.7));
  PoseEkf ekf = Filter(truth, 0.5, 1 * kDeg);
  const StateMatrix before = ekf.covariance();
  const Eigen::Vector3d behind(0, -10, 1.7);
  EXPECT_EQ(ekf.UpdatePoint(Camera(), behind, {320, 240}).rejection, Rejection::kBehindCamera);
  EXPECT_EQ(ekf.UpdateLine(Camera(), {{0, -10, 0}, {1, 0, 0}}, {0, 240}, {600, 240}).rejection, Rejection::kBehindCamera);
  EXPECT_EQ(ekf.covariance(), before);
  // A point on the horizon, 1e7 m away: position is unobservable from it, orientation is.
  const Eigen::Vector3d horizon(1e5, 1e7, 1.7);
  const auto uv = ProjectToPixel(Camera(), truth.Inverse() * horizon);
  ASSERT_TRUE(uv);
  Eigen::Matrix<double, 2, kErrorDim> J;
  ASSERT_TRUE(ekf.ProjectPoint(Camera(), horizon, &J));
  const double position_sensitivity = J.block<2, 3>(0, kPos).norm();
  EXPECT_LT(position_sensitivity, 1e-3);
  EXPECT_TRUE(ekf.UpdatePoint(Camera(), horizon, *uv + Eigen::Vector2d(0.5, 0)).accepted());
  EXPECT_TRUE(ekf.world_from_camera().translation.isApprox(truth.translation, 1e-3));
  EXPECT_TRUE(IsSpd(ekf.covariance()));
  // Not finite inputs never touch the state.
  EXPECT_EQ(ekf.UpdatePoint(Camera(), {NAN, 0, 0}, {1, 1}).rejection, Rejection::kNotFinite);
  EXPECT_EQ(ekf.UpdatePosition({INFINITY, 0, 0}, Eigen::Matrix3d::Identity()).rejection, Rejection::kNotFinite);
}

TEST(PoseEkf, A50MetreGpsOutlierIsGatedWithItsDistance) {
  PoseEkf ekf = Filter(Rigid3d(), 0.3, 1 * kDeg);
  ekf.Predict(200'000'000);
  const UpdateResult r = ekf.UpdatePosition(Eigen::Vector3d(50, 0, 0), Eigen::Matrix3d::Identity() * 0.05 * 0.05);
  EXPECT_EQ(r.rejection, Rejection::kGate);
  EXPECT_GT(r.mahalanobis_sq, 1000);
  EXPECT_STREQ(RejectionName(r.rejection), "outside the Mahalanobis gate");
  EXPECT_LT(ekf.world_from_camera().translation.norm(), 1e-9);
  EXPECT_TRUE(ekf.UpdatePosition(Eigen::Vector3d(0.1, 0, 0), Eigen::Matrix3d::Identity() * 0.05 * 0.05).accepted());
}

// Issue 19, eighth session: a height measurement (a carried camera above the ground) moves the
// height alone, by the ratio of the variances; a height tens of metres off is gated, a NaN or a
// zero sigma refused, and the state is then unchanged.
TEST(PoseEkf, AHeightMeasurementMovesTheHeightAloneAndOutliersAreRefused) {
  PoseEkf ekf = Filter(Rigid3d(), 0.5, 1 * kDeg);
  ekf.Predict(100'000'000);
  const StateMatrix before = ekf.covariance();
  const double var = before(kPos + 2, kPos + 2);
  EXPECT_EQ(ekf.UpdateHeight(30.0, 0.1).rejection, Rejection::kGate);
  EXPECT_EQ(ekf.UpdateHeight(std::nan(""), 0.1).rejection, Rejection::kNotFinite);
  EXPECT_EQ(ekf.UpdateHeight(0.5, 0.0).rejection, Rejection::kNotFinite);
  EXPECT_EQ(ekf.world_from_camera().translation, Eigen::Vector3d::Zero());
  ASSERT_TRUE(ekf.UpdateHeight(-1.0, 0.1).accepted());
  const Eigen::Vector3d p = ekf.world_from_camera().translation;
  EXPECT_NEAR(p.z(), -var / (var + 0.01), 1e-9);
  EXPECT_NEAR(p.x(), 0, 1e-12);
  EXPECT_NEAR(p.y(), 0, 1e-12);
  const StateMatrix after = ekf.covariance();
  EXPECT_NEAR(after(kPos + 2, kPos + 2), var * 0.01 / (var + 0.01), 1e-9);
  EXPECT_NEAR(after(kPos, kPos), before(kPos, kPos), 1e-12);
  EXPECT_TRUE(after.isApprox(after.transpose(), 1e-12));
}

// Issue 19, ninth session: a robust weight (UpdatePoint's variance_scale) scales the point's
// pixel variance for the update only. The update moves the pose as an update at the scaled
// variance does, the gate tests at the unscaled one (a match the plain update refuses stays
// refused however far it is down-weighted), and the reported squared distance is the unscaled one.
TEST(PoseEkf, ARobustWeightScalesTheUpdateButNotTheGate) {
  const PoseEkf start = Filter(Rigid3d(), 0.02, 0.05 * kDeg);  // a locked pose: the pixel noise dominates
  const Eigen::Vector3d point(1, -0.5, 20);
  const Eigen::Vector2d predicted = *start.ProjectPoint(Camera(), point);
  const double var = start.options().pixel_sigma_px * start.options().pixel_sigma_px;
  const Eigen::Vector2d near = predicted + Eigen::Vector2d(3, -2);

  PoseEkf weighted = start, plain = start, scaled = start;
  const UpdateResult w = weighted.UpdatePoint(Camera(), point, near, 0, {}, 4.0);
  const UpdateResult p = plain.UpdatePoint(Camera(), point, near);
  ASSERT_TRUE(w.accepted());
  ASSERT_TRUE(p.accepted());
  ASSERT_TRUE(scaled.UpdatePoint(Camera(), point, near, 3 * var).accepted());  // the variance x 4
  EXPECT_TRUE(weighted.world_from_camera().translation.isApprox(scaled.world_from_camera().translation, 1e-12));
  EXPECT_TRUE(weighted.covariance().isApprox(scaled.covariance(), 1e-12));
  const double moved = (weighted.world_from_camera().translation - start.world_from_camera().translation).norm();
  EXPECT_LT(moved, 0.5 * (plain.world_from_camera().translation - start.world_from_camera().translation).norm());
  EXPECT_GT(moved, 0);
  EXPECT_NEAR(w.mahalanobis_sq, p.mahalanobis_sq, 1e-9);  // the unscaled distance

  // Far enough for the plain gate: refused at every weight, and nothing changes.
  const Eigen::Vector2d far = predicted + Eigen::Vector2d(400, 0);
  PoseEkf refused = start;
  ASSERT_EQ(PoseEkf(start).UpdatePoint(Camera(), point, far).rejection, Rejection::kGate);
  for (double scale : {1.0, 10.0, 1e6}) EXPECT_EQ(refused.UpdatePoint(Camera(), point, far, 0, {}, scale).rejection, Rejection::kGate) << scale;
  EXPECT_EQ(refused.covariance(), start.covariance());
  EXPECT_EQ(refused.UpdatePoint(Camera(), point, near, 0, {}, std::nan("")).rejection, Rejection::kNotFinite);
}

// Issue 19, fifteenth session: a weight on the gain alone (UpdatePoint's gain_scale). The pose
// moves as far as an update at the scaled variance moves it, but the covariance is the Joseph
// form of that gain at the true variance: smaller than the scaled update's (the pixel is not
// noisier), larger than the optimal update's (a gain below the optimum leaves more), and exactly
// (I - KH) P (I - KH)' + K R K'.
TEST(PoseEkf, AWeightOnTheGainAloneKeepsTheCovarianceAtTheTrueNoise) {
  const PoseEkf start = Filter(Rigid3d(), 0.02, 0.05 * kDeg);
  const Eigen::Vector3d point(1, -0.5, 20);
  Eigen::Matrix<double, 2, kErrorDim> H;
  const Eigen::Vector2d predicted = *start.ProjectPoint(Camera(), point, &H);
  const double var = start.options().pixel_sigma_px * start.options().pixel_sigma_px;
  const Eigen::Vector2d seen = predicted + Eigen::Vector2d(1.5, -1);

  PoseEkf gained = start, scaled = start, plain = start;
  ASSERT_TRUE(gained.UpdatePoint(Camera(), point, seen, 0, {}, 1, 5.0).accepted());
  ASSERT_TRUE(scaled.UpdatePoint(Camera(), point, seen, 4 * var).accepted());  // the variance x 5
  ASSERT_TRUE(plain.UpdatePoint(Camera(), point, seen).accepted());
  EXPECT_TRUE(gained.world_from_camera().translation.isApprox(scaled.world_from_camera().translation, 1e-12));

  const StateMatrix P = start.covariance();
  const Eigen::Matrix2d S = H * P * H.transpose() + 5 * var * Eigen::Matrix2d::Identity();
  const Eigen::Matrix<double, kErrorDim, 2> K = P * H.transpose() * S.inverse();
  const StateMatrix I_KH = StateMatrix::Identity() - K * H;
  const StateMatrix joseph = I_KH * P * I_KH.transpose() + var * K * K.transpose();
  EXPECT_TRUE(gained.covariance().isApprox(joseph, 1e-9));
  auto position_trace = [](const PoseEkf& e) { return e.covariance().topLeftCorner<3, 3>().trace(); };
  EXPECT_LT(position_trace(gained), position_trace(scaled));
  EXPECT_GT(position_trace(gained), position_trace(plain));
  EXPECT_TRUE(gained.covariance().isApprox(gained.covariance().transpose(), 1e-12));
  EXPECT_EQ(PoseEkf(start).UpdatePoint(Camera(), point, seen, 0, {}, 1, std::nan("")).rejection, Rejection::kNotFinite);
}

TEST(PoseEkf, TimeMustNotGoBackwardsAndZeroDtIsANoOp) {
  PoseEkf ekf = Filter(Rigid3d());
  ASSERT_TRUE(ekf.Predict(1'000'000'000).accepted());
  const StateMatrix P = ekf.covariance();
  EXPECT_TRUE(ekf.Predict(1'000'000'000).accepted());  // dt = 0
  EXPECT_EQ(ekf.covariance(), P);
  EXPECT_EQ(ekf.Predict(999'999'999).rejection, Rejection::kTimeNotIncreasing);
  EXPECT_EQ(ekf.time_ns(), 1'000'000'000);
  EXPECT_EQ(ekf.covariance(), P);
}

TEST(PoseEkf, TracksARotationThroughAndNear180Degrees) {
  // The camera spins about world up at 1 rad/s from 170° away from where the filter starts
  // believing it is, with orientation measurements at 150 Hz.
  const Eigen::Quaterniond start = SO3Exp(Eigen::Vector3d(0, 0, 170 * kDeg));
  PoseEkf ekf;
  ekf.Initialize(0, Rigid3d(), 0.1, 3.0);  // orientation sigma ~170°
  for (int i = 1; i <= 600; ++i) {
    const int64_t t = i * 1'000'000'000LL / 150;
    ASSERT_TRUE(ekf.Predict(t).accepted());
    const Eigen::Quaterniond truth = SO3Exp(Eigen::Vector3d(0, 0, 1.0 * t * 1e-9)) * start;
    ekf.UpdateOrientation(truth, 1 * kDeg);
    ASSERT_NEAR(ekf.world_from_camera().rotation.norm(), 1.0, 1e-12);
    if (i > 300) {
      EXPECT_LT(AngleBetweenDeg(ekf.world_from_camera().rotation, truth), 1.0) << i;
    }
  }
  EXPECT_NEAR(ekf.angular_velocity().z(), 1.0, 0.05);
  // A measurement 179.9° from the estimate is a finite innovation of about pi (gated, not NaN).
  const UpdateResult r = ekf.UpdateOrientation(ekf.world_from_camera().rotation * SO3Exp(Eigen::Vector3d(179.9 * kDeg, 0, 0)), 1 * kDeg);
  EXPECT_EQ(r.rejection, Rejection::kGate);
  EXPECT_TRUE(std::isfinite(r.mahalanobis_sq));
}

TEST(PoseEkf, AMillionUpdatesKeepTheCovarianceSpdAndTheQuaternionUnit) {
  PoseEkf ekf;
  ekf.Initialize(0, Rigid3d(SO3Exp(Eigen::Vector3d(0.1, 0.2, 0.3)), Eigen::Vector3d::Zero()), 1, 0.1);
  std::mt19937_64 rng(7);
  std::normal_distribution<double> n(0, 1);
  const Eigen::Matrix3d gps_cov = Eigen::Matrix3d::Identity() * 0.05 * 0.05;
  int64_t t = 0;
  for (int i = 0; i < 1'000'000; ++i) {
    if (i % 10 == 0) ekf.Predict(t += 10'000'000);  // 100 Hz prediction, ten updates each
    if (i % 2 == 0) {
      ekf.UpdateOrientation(SO3Exp(Eigen::Vector3d(0.1, 0.2, 0.3) + 0.01 * Eigen::Vector3d(n(rng), n(rng), n(rng))), 0.01);
    } else {
      ekf.UpdatePosition(0.05 * Eigen::Vector3d(n(rng), n(rng), n(rng)), gps_cov);
    }
    if (i % 100'000 == 0) {
      ASSERT_TRUE(IsSpd(ekf.covariance())) << i;
      ASSERT_NEAR(ekf.world_from_camera().rotation.norm(), 1.0, 1e-12) << i;
    }
  }
  EXPECT_TRUE(IsSpd(ekf.covariance()));
  EXPECT_NEAR(ekf.world_from_camera().rotation.norm(), 1.0, 1e-12);
  EXPECT_LT(ekf.world_from_camera().translation.norm(), 0.05);
  EXPECT_GT(ekf.covariance().diagonal().minCoeff(), 0);
}

TEST(PoseEkf, TheReportedScaleMultipliesOnlyTheReportedCovariance) {
  PoseEkf ekf = Filter(Rigid3d(), 0.2, 1 * kDeg);
  const Matrix6d before = ekf.PoseCovariance();
  const StateMatrix own = ekf.covariance();
  ekf.SetReportedScale(2.5);
  EXPECT_TRUE(ekf.PoseCovariance().isApprox(2.5 * before, 1e-12));
  EXPECT_EQ(ekf.covariance(), own);
  for (double bad : {0.5, -1.0, std::nan(""), std::numeric_limits<double>::infinity()}) {
    ekf.SetReportedScale(bad);
    EXPECT_EQ(ekf.reported_scale(), 2.5) << bad;
  }
  ekf.Initialize(0, Rigid3d(), 0.2, 1 * kDeg);
  EXPECT_EQ(ekf.reported_scale(), 1.0);
  EXPECT_TRUE(ekf.PoseCovariance().isApprox(before, 1e-12));
}

TEST(PoseFilterOptions, CheckNamesTheBadField) {
  PoseFilterOptions o;
  EXPECT_EQ(o.Check(), "");
  o.pixel_sigma_px = -1;
  EXPECT_THAT(o.Check(), ::testing::HasSubstr("pixel_sigma_px"));
  o = PoseFilterOptions();
  o.gravity_sigma_deg = 0;
  EXPECT_THAT(o.Check(), ::testing::HasSubstr("gravity_sigma_deg"));
  o = PoseFilterOptions();
  o.heading_sigma_deg = -1;
  EXPECT_THAT(o.Check(), ::testing::HasSubstr("heading_sigma_deg"));
  o = PoseFilterOptions();
  o.gravity_window_s = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THAT(o.Check(), ::testing::HasSubstr("gravity_window_s"));
  o = PoseFilterOptions();
  o.gps_reanchor_s = -1;
  EXPECT_THAT(o.Check(), ::testing::HasSubstr("gps_reanchor_s"));
  o = PoseFilterOptions();
  o.gps_reanchor_min_m = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THAT(o.Check(), ::testing::HasSubstr("gps_reanchor_min_m"));
}

}  // namespace
}  // namespace ave::pose

namespace ave::pose {
namespace {

// Relocalisation (issue 19, sixth session): MovePosition sets the position and its covariance and
// cuts its correlations; the rest of the state and the covariance's symmetry and definiteness stay.
// A filter at `truth` whose position and orientation six point updates have correlated (each
// point with its own consider bias), for the Move* tests.
PoseEkf CorrelatedFilter(const Rigid3d& truth) {
  PoseEkf ekf = Filter(truth, 0.5, 2 * kDeg);
  const PinholeIntrinsics k = Camera();
  for (int i = 0; i < 6; ++i) {
    const Eigen::Vector3d p = truth * Eigen::Vector3d(-3 + i, 0.5 * (i % 3) - 0.5, 8 + i);
    (void)ekf.UpdatePoint(k, p, *ProjectToPixel(k, truth.Inverse() * p) + Eigen::Vector2d(0.3, -0.2), 0, {{{i, 0.3}, {}}});
  }
  return ekf;
}

TEST(PoseEkf, MovePositionResetsThePositionAndItsCorrelationsOnly) {
  const Rigid3d truth(SO3Exp(Eigen::Vector3d(0.1, -0.2, 0.3)), Eigen::Vector3d(5, -3, 1.7));
  PoseEkf ekf = CorrelatedFilter(truth);
  const PinholeIntrinsics k = Camera();
  // A landmark in the state too.
  ASSERT_TRUE(ekf.AddLandmark(7, truth * Eigen::Vector3d(0, 0, 12), Eigen::Matrix3d::Identity()));
  (void)ekf.UpdateLandmark(k, 7, *ProjectToPixel(k, Eigen::Vector3d(0, 0, 12)) + Eigen::Vector2d(0.2, 0.1), 1.0);
  const StateMatrix& P0 = ekf.covariance();
  ASSERT_GT(P0.block(kPos, kRot, 3, 3).cwiseAbs().maxCoeff(), 1e-8) << "the updates correlate position and orientation";
  const Eigen::Quaterniond q = ekf.world_from_camera().rotation;
  const StateMatrix before = ekf.covariance();

  const Eigen::Vector3d moved(7.5, -1, 1.7);
  ekf.MovePosition(moved, 0.5);
  EXPECT_EQ(ekf.world_from_camera().translation, moved);
  EXPECT_TRUE(ekf.world_from_camera().rotation.isApprox(q, 1e-15)) << "orientation kept";
  const StateMatrix& P = ekf.covariance();
  const Eigen::Matrix3d position_block = P.block(kPos, kPos, 3, 3);
  EXPECT_TRUE(position_block.isApprox(0.25 * Eigen::Matrix3d::Identity()));
  EXPECT_EQ(P.block(kPos, 3, 3, kErrorDim - 3).cwiseAbs().maxCoeff(), 0.0);
  const Eigen::MatrixXd rest = P.block(3, 3, kErrorDim - 3, kErrorDim - 3), rest_before = before.block(3, 3, kErrorDim - 3, kErrorDim - 3);
  EXPECT_EQ(rest, rest_before) << "the rest of the covariance kept";
  EXPECT_TRUE(IsSpd(ekf.covariance()));
  const Eigen::MatrixXd full = ekf.FullCovariance();
  EXPECT_EQ(full.block(kPos, kErrorDim, 3, 3).cwiseAbs().maxCoeff(), 0.0) << "no position-landmark correlation";
  EXPECT_EQ(Eigen::LLT<Eigen::MatrixXd>(0.5 * (full + full.transpose())).info(), Eigen::Success);
  EXPECT_TRUE(ekf.PoseCovariance().allFinite());

  // Bad input changes nothing.
  const StateMatrix after = ekf.covariance();
  ekf.MovePosition(Eigen::Vector3d(std::numeric_limits<double>::quiet_NaN(), 0, 0), 0.5);
  ekf.MovePosition(Eigen::Vector3d(1, 2, 3), 0);
  ekf.MovePosition(Eigen::Vector3d(1, 2, 3), std::numeric_limits<double>::infinity());
  EXPECT_EQ(ekf.world_from_camera().translation, moved);
  EXPECT_EQ(ekf.covariance(), after);
}


// Issue 19, eighteenth session: the reorientation sets the orientation and its covariance and cuts
// its correlations; position, velocity and the rest of the covariance stay.
TEST(PoseEkf, MoveOrientationResetsTheOrientationAndItsCorrelationsOnly) {
  const Rigid3d truth(SO3Exp(Eigen::Vector3d(0.1, -0.2, 0.3)), Eigen::Vector3d(5, -3, 1.7));
  PoseEkf ekf = CorrelatedFilter(truth);
  ASSERT_GT(ekf.covariance().block(kPos, kRot, 3, 3).cwiseAbs().maxCoeff(), 1e-8) << "the updates correlate position and orientation";
  const StateMatrix before = ekf.covariance();
  const Eigen::Vector3d position = ekf.world_from_camera().translation;
  const Eigen::Quaterniond turned = (Eigen::Quaterniond(Eigen::AngleAxisd(20 * kDeg, Eigen::Vector3d::UnitZ())) * truth.rotation).normalized();

  ekf.MoveOrientation(turned, 3 * kDeg);
  EXPECT_TRUE(ekf.world_from_camera().rotation.isApprox(turned, 1e-12));
  EXPECT_EQ(ekf.world_from_camera().translation, position) << "position kept";
  const StateMatrix& P = ekf.covariance();
  const Eigen::Matrix3d rot = P.block(kRot, kRot, 3, 3);
  EXPECT_TRUE(rot.isApprox(std::pow(3 * kDeg, 2) * Eigen::Matrix3d::Identity()));
  EXPECT_EQ(P.block(kRot, 0, 3, kRot).cwiseAbs().maxCoeff(), 0.0);
  EXPECT_EQ(P.block(kRot, kRot + 3, 3, kErrorDim - kRot - 3).cwiseAbs().maxCoeff(), 0.0);
  EXPECT_EQ(P.block(kPos, kPos, 6, 6), before.block(kPos, kPos, 6, 6)) << "position and velocity blocks kept";
  EXPECT_TRUE(IsSpd(ekf.covariance()));
  EXPECT_TRUE(ekf.PoseCovariance().allFinite());

  // Bad input changes nothing: a NaN, a non-unit quaternion, a sigma of 0 or infinity.
  const StateMatrix after = ekf.covariance();
  ekf.MoveOrientation(Eigen::Quaterniond(std::numeric_limits<double>::quiet_NaN(), 0, 0, 0), kDeg);
  ekf.MoveOrientation(Eigen::Quaterniond(2, 0, 0, 0), kDeg);
  ekf.MoveOrientation(truth.rotation, 0);
  ekf.MoveOrientation(truth.rotation, std::numeric_limits<double>::infinity());
  EXPECT_TRUE(ekf.world_from_camera().rotation.isApprox(turned, 1e-12));
  EXPECT_EQ(ekf.covariance(), after);
}

// Issue 19, eighteenth session: an AHRS's heading has its own sigma. The filter starts with it about
// the world's vertical, and a reading 5 deg off about every world axis, at 1 deg of tilt and 10 deg
// of heading, moves the tilt most of the way and the heading a little.
TEST(PoseEkf, AnAhrsHeadingWeighsLessThanItsTilt) {
  const Rigid3d truth(SO3Exp(Eigen::Vector3d(-1.4, 0.0, 0.3)), Eigen::Vector3d(2, 1, 1.7));
  PoseEkf ekf;
  ekf.Initialize(0, truth, 0.5, 2 * kDeg, false, 10 * kDeg);
  EXPECT_NEAR(ekf.covariance()(kRot + 2, kRot + 2), std::pow(10 * kDeg, 2), 1e-12);
  EXPECT_NEAR(ekf.covariance()(kRot, kRot), std::pow(2 * kDeg, 2), 1e-12);
  const Eigen::Vector3d off = Eigen::Vector3d::Constant(5 * kDeg);
  ASSERT_TRUE(ekf.UpdateOrientation(SO3Exp(off) * truth.rotation, 1 * kDeg, 10 * kDeg).accepted());
  const Eigen::Vector3d moved = SO3Log(ekf.world_from_camera().rotation * truth.rotation.conjugate());
  EXPECT_GT(moved.x(), 0.7 * off.x()) << "tilt: 2 deg prior against a 1 deg reading";
  EXPECT_GT(moved.y(), 0.7 * off.y());
  EXPECT_NEAR(moved.z(), 0.5 * off.z(), 0.05 * off.z()) << "heading: 10 deg prior against a 10 deg reading";
  EXPECT_TRUE(IsSpd(ekf.covariance()));
  // Without a heading sigma the reading's own sigma holds about every axis, as before.
  PoseEkf isotropic;
  isotropic.Initialize(0, truth, 0.5, 2 * kDeg);
  EXPECT_NEAR(isotropic.covariance()(kRot + 2, kRot + 2), std::pow(2 * kDeg, 2), 1e-12);
  ASSERT_TRUE(isotropic.UpdateOrientation(SO3Exp(off) * truth.rotation, 1 * kDeg).accepted());
  EXPECT_GT(SO3Log(isotropic.world_from_camera().rotation * truth.rotation.conjugate()).z(), 0.7 * off.z());
}

// Issue 19, eighteenth session: the accelerometer's gravity levels the filter. A camera whose
// orientation starts 6 deg off in tilt and 10 deg off in heading: readings of the true up bring the
// tilt back within 0.2 deg and leave the heading, which gravity cannot see, where it was, with
// nearly all its variance; degenerate readings are refused.
TEST(PoseEkf, GravityLevelsTheTiltAndLeavesTheHeading) {
  const Rigid3d truth(SO3Exp(Eigen::Vector3d(-1.4, 0.0, 0.3)), Eigen::Vector3d(2, 1, 1.7));  // pitched, looking sideways
  const Eigen::Quaterniond off =
      (Eigen::Quaterniond(Eigen::AngleAxisd(10 * kDeg, Eigen::Vector3d::UnitZ())) * Eigen::Quaterniond(Eigen::AngleAxisd(6 * kDeg, Eigen::Vector3d(1, 1, 0).normalized())) *
       truth.rotation)
          .normalized();
  PoseEkf ekf = Filter(Rigid3d(off, truth.translation), 0.5, 8 * kDeg);
  const double heading_variance = ekf.covariance()(kRot + 2, kRot + 2);
  const Eigen::Vector3d up = truth.rotation.conjugate() * Eigen::Vector3d::UnitZ();
  for (int i = 0; i < 20; ++i) ASSERT_TRUE(ekf.UpdateGravity(9.81 * up, 1 * kDeg).accepted()) << i;
  const Eigen::Vector3d error = SO3Log(ekf.world_from_camera().rotation * truth.rotation.conjugate());  // world frame
  EXPECT_LT(error.head<2>().norm(), 0.2 * kDeg) << "tilt levelled";
  EXPECT_NEAR(error.z(), 10 * kDeg, 0.5 * kDeg) << "heading unseen by gravity";
  // The heading's variance stays nearly as it was (the error-state reset after the first, 6 deg
  // correction correlates heading with tilt, so the later readings take 14 % of it).
  EXPECT_NEAR(ekf.covariance()(kRot + 2, kRot + 2), heading_variance, 0.2 * heading_variance);
  EXPECT_TRUE(IsSpd(ekf.covariance()));
  const StateMatrix before = ekf.covariance();
  EXPECT_EQ(ekf.UpdateGravity(Eigen::Vector3d::Zero(), kDeg).rejection, Rejection::kNotFinite);
  EXPECT_EQ(ekf.UpdateGravity(Eigen::Vector3d(std::numeric_limits<double>::quiet_NaN(), 0, 1), kDeg).rejection, Rejection::kNotFinite);
  EXPECT_EQ(ekf.UpdateGravity(up, 0).rejection, Rejection::kNotFinite);
  EXPECT_EQ(ekf.UpdateGravity(-up, kDeg).rejection, Rejection::kGate) << "an upside-down reading is gated";
  EXPECT_EQ(ekf.covariance(), before);
}

}  // namespace
}  // namespace ave::pose
