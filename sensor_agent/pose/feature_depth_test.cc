// Anchored inverse-depth structure of unknown features (issue 19) against the truth of a walk.
#include "sensor_agent/pose/feature_depth.h"

#include <cmath>
#include <optional>
#include <random>
#include <vector>

#include <Eigen/Geometry>

#include <gtest/gtest.h>

namespace ave::pose {
namespace {

PinholeIntrinsics Camera() {
  PinholeIntrinsics k;
  k.width = 640, k.height = 480, k.fx = 500, k.fy = 500, k.cx = 319.5, k.cy = 239.5;
  return k;
}

// The camera walks at 1.4 m/s along a path turned 20° from its view direction, 30 Hz; the filter's
// pose is the truth with a small covariance. Returns the anchored point after `frames` sightings
// with 1 px noise, or nullopt when a sighting was refused.
struct Walk {
  Eigen::Vector3d start{0, 0, 1.7};
  Eigen::Vector3d velocity = Eigen::Vector3d(std::sin(0.35), std::cos(0.35), 0) * 1.4;
  Rigid3d PoseAt(int f) const {
    const Eigen::Vector3d eye = start + velocity * (f / 30.0);
    return LookAt(eye, eye + Eigen::Vector3d(0, 10, 0));
  }
};

std::optional<AnchoredPoint> Observe(const Walk& walk, const Eigen::Vector3d& point, const Eigen::Vector3d& point_velocity, int frames,
                                     std::mt19937& rng) {
  std::normal_distribution<double> noise(0.0, 1.0);
  PoseFilterOptions fo;
  fo.pixel_sigma_px = 1.0;
  auto seen = [&](int f) {
    const Eigen::Vector3d p = point + point_velocity * (f / 30.0);
    return Eigen::Vector2d(*ProjectToPixel(Camera(), walk.PoseAt(f).Inverse() * p) + Eigen::Vector2d(noise(rng), noise(rng)));
  };
  AnchoredPoint a = StartAnchoredPoint(walk.PoseAt(0), Camera(), seen(0), 1.0, 20.0, 0.25);
  for (int f = 1; f < frames; ++f) {
    PoseEkf ekf(fo);
    ekf.Initialize(f, walk.PoseAt(f), 0.005, 0.0002);
    if (!RefineAnchoredPoint(a, ekf, Camera(), seen(f))) return std::nullopt;
  }
  return a;
}

TEST(AnchoredPoint, ConvergesToTheTrueDepthNearAndFarWithHonestSigmas) {
  const Walk walk;
  std::mt19937 rng(5);
  int inside_3_sigma = 0, trials = 0;
  for (const double depth : {3.0, 6.0, 12.0, 25.0}) {
    for (int trial = 0; trial < 20; ++trial) {
      const Eigen::Vector3d point(-1.5 + 0.15 * trial, depth, 1.0 + 0.1 * trial);
      const auto a = Observe(walk, point, Eigen::Vector3d::Zero(), 30, rng);
      ASSERT_TRUE(a) << depth << " " << trial;
      EXPECT_EQ(a->observations, 29);
      const Eigen::Vector3d error = a->Point() - point;
      const double nees = error.dot(a->PointCovariance().ldlt().solve(error));
      inside_3_sigma += nees < 14.2;  // chi2(3) 99.7 %
      ++trials;
      if (depth <= 3.0) {
        EXPECT_LT(a->LargestSigma(), 0.3) << "a near point converges in a second of walking";
      }
      EXPECT_LT(error.norm(), depth * 0.5) << depth;
    }
  }
  // The sigma is honest: almost every estimate lies within its 3-sigma ellipsoid.
  EXPECT_GE(inside_3_sigma, trials * 9 / 10);
}

TEST(AnchoredPoint, AMoverIsRefusedAndAFarPointStaysUncertain) {
  const Walk walk;
  std::mt19937 rng(7);
  // A branch waving up at 1 m/s, 8 m ahead: no depth explains its motion across the epipolar
  // lines, so its sightings leave the gate within a second. (Motion along them, e.g. a person
  // walking parallel to the camera, looks like a wrong depth: such points are caught later, once
  // the camera's motion changes, or not at all; the joint filter's gate is the second line.)
  EXPECT_FALSE(Observe(walk, {-2, 8, 1.5}, {0, 0, 1.0}, 30, rng));
  // A point 300 m out: its inverse depth stays near zero and its range sigma stays large, so it
  // never counts as converged (it would not join the pose filter).
  const auto far = Observe(walk, {20, 300, 30}, Eigen::Vector3d::Zero(), 30, rng);
  ASSERT_TRUE(far);
  EXPECT_GT(far->LargestSigma(), 10.0);
}

// Issue 19: the anchor is the filter's pose at the first sighting, frozen and taken as exact, and
// every sighting is taken as independent. An anchor that is off (as every filter pose is, by its
// covariance) is a bias shared by all the sightings: the depth converges to a wrong value with a
// sigma that does not cover it (joined landmarks' 3-dof NEES 8.7 in ave-bench pose). This is why a
// feature joins the state with its depth sigma scaled (VisionOptions::join_depth_sigma_scale = 2).
// Monte Carlo over anchor errors of 5 cm and 0.1° per axis (a vision-locked filter's size), 1 px
// pixel noise, later poses exact, 30 sightings; the depth from the last pose against the truth
// (200 draws: 94 % within 1.96 sigma with an exact anchor, 70 % with the anchor off, 84 % within twice).
TEST(AnchoredPoint, AFrozenAnchorsErrorMakesTheDepthOverconfidentAndTwiceTheSigmaCoversIt) {
  const Walk walk;
  const PinholeIntrinsics k = Camera();
  constexpr double kSigmaP = 0.05, kSigmaR = 0.1 * 3.14159265358979323846 / 180;
  PoseFilterOptions fo;
  fo.pixel_sigma_px = 1.0;
  std::mt19937 rng(11);
  std::normal_distribution<double> n01(0.0, 1.0);
  int inside_1 = 0, inside_2 = 0, inside_exact_anchor = 0, trials = 0;
  for (int trial = 0; trial < 200; ++trial) {
    const Eigen::Vector3d point(-2.0 + 0.02 * trial, 5.0 + 0.03 * trial, 1.0 + 0.01 * trial);
    const Rigid3d truth0 = walk.PoseAt(0);
    const Eigen::Vector3d dp(kSigmaP * n01(rng), kSigmaP * n01(rng), kSigmaP * n01(rng));
    const Eigen::Vector3d dtheta(kSigmaR * n01(rng), kSigmaR * n01(rng), kSigmaR * n01(rng));
    const Rigid3d anchor(Eigen::Quaterniond(Eigen::AngleAxisd(dtheta.norm(), dtheta.normalized())) * truth0.rotation, truth0.translation + dp);
    std::vector<Eigen::Vector2d> seen;
    for (int f = 0; f < 30; ++f) seen.push_back(*ProjectToPixel(k, walk.PoseAt(f).Inverse() * point) + Eigen::Vector2d(n01(rng), n01(rng)));
    const double true_depth = (walk.PoseAt(29).Inverse() * point).z();
    // Depth error over its sigma with the anchor at `a0`: nullopt when a sighting was refused.
    auto normalised_error = [&](const Rigid3d& a0) -> std::optional<double> {
      AnchoredPoint a = StartAnchoredPoint(a0, k, seen[0], 1.0, 20.0, 0.25);
      PoseEkf ekf(fo);
      for (int f = 1; f < 30; ++f) {
        ekf = PoseEkf(fo);
        ekf.Initialize(f, walk.PoseAt(f), 0.005, 0.0002);
        if (!RefineAnchoredPoint(a, ekf, k, seen[f])) return std::nullopt;
      }
      double depth = 0, sigma = 0;
      if (!DepthFromPose(a, ekf, depth, sigma)) return std::nullopt;
      return std::abs(depth - true_depth) / sigma;
    };
    const auto off = normalised_error(anchor), exact = normalised_error(truth0);
    inside_1 += off && *off < 1.96;  // 95 %
    inside_2 += off && *off < 2 * 1.96;
    inside_exact_anchor += exact && *exact < 1.96;
    ++trials;
  }
  EXPECT_GE(inside_exact_anchor, trials * 85 / 100) << "with an exact anchor the depth sigma is honest";
  EXPECT_LT(inside_1, trials * 75 / 100) << "a frozen anchor's error is not in the depth sigma";
  EXPECT_GE(inside_2, trials * 80 / 100) << "twice the sigma covers most of it";
}

}  // namespace
}  // namespace ave::pose
