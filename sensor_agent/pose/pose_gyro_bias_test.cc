// Issue 19: the gyro bias as a filter state (docs/POSE.md, "Gyro bias").
#include <cmath>
#include <random>

#include <Eigen/Cholesky>
#include <gtest/gtest.h>

#include "sensor_agent/pose/pose_ekf.h"
#include "sensor_agent/pose/so3.h"

namespace ave::pose {
namespace {

constexpr double kDeg = 3.14159265358979323846 / 180;
// Two-sided chi-square(3) 95 % band.
constexpr double kChi2Low3 = 0.2158, kChi2High3 = 9.3484;

struct BiasRun {
  Eigen::Vector3d bias_error = Eigen::Vector3d::Zero();  // estimate - truth at the end
  Eigen::Vector3d bias_sigma = Eigen::Vector3d::Zero();
  double attitude_in_band = 0;   // share of the attitude checks (after the first second) in band
  double attitude_nees_mean = 0;
};

// A camera turning at a constant world rate, a gyro at 150 Hz with a constant bias and white
// noise, and an absolute attitude fix (standing in for a vision lock) every `fix_period_s` at
// 0.5 degrees. Deterministic (fixed seed).
BiasRun SimulateTurn(bool estimate_bias, double fix_period_s) {
  const Eigen::Vector3d rate_world(0.10, -0.20, 0.30), bias(0.005, -0.005, 0.005);
  const Eigen::Quaterniond start = Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized()));
  const double gyro_noise = 0.002, fix_sigma = 0.5 * kDeg;
  PoseFilterOptions o;
  o.estimate_gyro_bias = estimate_bias;
  PoseEkf ekf(o);
  ekf.Initialize(0, Rigid3d(start, Eigen::Vector3d::Zero()), 1.0, 2 * kDeg);
  std::mt19937_64 rng(19);
  std::normal_distribution<double> normal;
  auto noise3 = [&](double s) { return Eigen::Vector3d(s * normal(rng), s * normal(rng), s * normal(rng)); };
  BiasRun out;
  int checks = 0, in_band = 0;
  const int64_t gyro_step_ns = 1'000'000'000 / 150, fix_step_ns = static_cast<int64_t>(fix_period_s * 1e9);
  const int64_t end_ns = 30'000'000'000;
  for (int64_t t = gyro_step_ns; t <= end_ns; t += gyro_step_ns) {
    const Eigen::Quaterniond truth = SO3Exp(rate_world * (t * 1e-9)) * start;
    EXPECT_TRUE(ekf.Predict(t).accepted());
    ekf.UpdateRate(truth.conjugate() * rate_world + bias + noise3(gyro_noise), o.gyro_sigma_rad_s);
    if (t % fix_step_ns < gyro_step_ns) {
      // Attitude NEES just before the fix (the filter's prediction, the hardest moment).
      if (t > 1'000'000'000) {
        const Eigen::Vector3d e = SO3Log(truth * ekf.world_from_camera().rotation.conjugate());
        const double nees = e.dot(ekf.covariance().block<3, 3>(kRot, kRot).ldlt().solve(e));
        ++checks;
        in_band += nees >= kChi2Low3 && nees <= kChi2High3;
        out.attitude_nees_mean += nees;
      }
      const Eigen::Quaterniond measured = SO3Exp(noise3(fix_sigma)) * truth;
      ekf.UpdateOrientation(measured, fix_sigma);
    }
  }
  out.bias_error = ekf.gyro_bias() - bias;
  out.bias_sigma = ekf.covariance().block<3, 3>(kGyroBias, kGyroBias).diagonal().cwiseSqrt();
  out.attitude_in_band = checks > 0 ? static_cast<double>(in_band) / checks : 0;
  out.attitude_nees_mean /= std::max(1, checks);
  return out;
}

TEST(GyroBias, TheEstimateConvergesToAConstantBiasWithinItsSigmaAndTheAttitudeStaysConsistent) {
  const BiasRun r = SimulateTurn(true, 1.0);
  for (int i = 0; i < 3; ++i) {
    EXPECT_LT(std::abs(r.bias_error[i]), 3 * r.bias_sigma[i]) << i;
    EXPECT_LT(r.bias_sigma[i], 0.002) << i;  // learnt: from 0.01 rad/s to under half the bias
  }
  EXPECT_GE(r.attitude_in_band, 0.9);
  EXPECT_GT(r.attitude_nees_mean, 1.5);  // not inflated into uselessness either (chi2(3) mean 3)
  EXPECT_LT(r.attitude_nees_mean, 4.5);
}

TEST(GyroBias, WithoutTheBiasStateTheSameRunIsOverconfident) {
  // The pre-issue-19 filter integrates the biased rate as if it were the truth.
  const BiasRun r = SimulateTurn(false, 1.0);
  EXPECT_EQ(r.bias_sigma.maxCoeff(), std::sqrt(PoseFilterOptions{}.min_variance));
  EXPECT_LT(r.attitude_in_band, 0.8);
}

TEST(GyroBias, FrequentFixesKeepTheBiasObservableAndTheCovarianceSpd) {
  const BiasRun r = SimulateTurn(true, 1.0 / 30);
  for (int i = 0; i < 3; ++i) EXPECT_LT(std::abs(r.bias_error[i]), 3 * r.bias_sigma[i]) << i;
  EXPECT_GE(r.attitude_in_band, 0.9);
}

TEST(GyroBias, HardCasesKeepTheFifteenStateCovarianceSpdAndFinite) {
  // Zero and huge time steps, rates through a 180 degree turn, no absolute fix for a long while.
  PoseFilterOptions o;
  o.estimate_gyro_bias = true;
  PoseEkf ekf(o);
  ekf.Initialize(0, Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d(1e3, -2e3, 5)), 1.0, 2 * kDeg);
  int64_t t = 0;
  for (int i = 0; i < 100000; ++i) {
    t += i % 1000 == 0 ? 0 : (i % 9973 == 0 ? 3'600'000'000'000 : 6'666'667);
    ASSERT_TRUE(ekf.Predict(t).accepted());
    (void)ekf.UpdateRate(Eigen::Vector3d(0, 0, i < 50000 ? 3.14159 : 0.01), o.gyro_sigma_rad_s);
    if (i % 5000 == 0) (void)ekf.UpdateOrientation(ekf.world_from_camera().rotation, 2 * kDeg);
    if (i % 10000 == 0) {
      ASSERT_TRUE(ekf.covariance().allFinite()) << i;
      ASSERT_EQ(Eigen::LLT<StateMatrix>(ekf.covariance()).info(), Eigen::Success) << i;
    }
  }
  EXPECT_TRUE(ekf.gyro_bias().allFinite());
  EXPECT_NEAR(ekf.world_from_camera().rotation.norm(), 1.0, 1e-12);
}

TEST(GyroBias, OptionsCheckNamesTheBiasFields) {
  PoseFilterOptions o;
  o.gyro_bias_sigma_rad_s = 0;
  EXPECT_NE(o.Check().find("gyro_bias_sigma_rad_s"), std::string::npos);
  o = {};
  o.gyro_bias_random_walk_rad_s_sqrt_s = -1;
  EXPECT_NE(o.Check().find("gyro_bias_random_walk_rad_s_sqrt_s"), std::string::npos);
  o.gyro_bias_random_walk_rad_s_sqrt_s = 0;
  EXPECT_EQ(o.Check(), "");
}

}  // namespace
}  // namespace ave::pose
