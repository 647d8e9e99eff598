#include "sensor_agent/sim/gps_imu.h"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "sensor_agent/sim/sensor_test_site.h"

namespace ave::sim {
namespace {

const scene::CameraSpec& Backpack(const scene::SyntheticCampus& site) { return *site.FindCamera("backpack"); }

GpsImuSpec Spec(double duration_s = 20) {
  GpsImuSpec spec;
  spec.camera_id = "backpack";
  spec.duration_s = duration_s;
  return spec;
}

double AngleBetween(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b) { return a.angularDistance(b); }

TEST(GpsImu, WithoutEffectsEveryMeasurementIsTheTruth) {
  const scene::SyntheticCampus site = testing::CourtyardSite();
  ResetEvaluations();
  const GpsImuStreams s = SimulateGpsImu(site, Backpack(site), Spec(), EffectSet{}, 1);
  ASSERT_EQ(s.gps.size(), 101u);   // 20 s at 5 Hz, both ends
  ASSERT_EQ(s.imu.size(), 3001u);  // 20 s at 150 Hz
  ASSERT_EQ(s.truth_at_video_rate.size(), 601u);
  for (size_t k = 0; k < s.gps.size(); ++k) {
    const GpsFix& f = s.gps[k];
    EXPECT_TRUE(f.valid);
    EXPECT_EQ(f.position_m, f.true_position_m);
    EXPECT_EQ(f.t_ns, static_cast<int64_t>(k) * 200'000'000);
    EXPECT_EQ(f.true_position_m, scene::CameraPoseAt(site, Backpack(site), k * (1.0 / 5)).translation);
  }
  for (const ImuSample& m : s.imu) {
    EXPECT_EQ(m.orientation.coeffs(), m.true_orientation.coeffs());
    EXPECT_TRUE(m.gyro_rad_s.allFinite() && m.accel_m_s2.allFinite());
    EXPECT_NEAR((m.true_orientation * m.magnetic - kEarthField_uT).norm(), 0, 1e-9);
  }
  for (int k = 0; k < kEffectCount; ++k) EXPECT_EQ(Evaluations(static_cast<EffectKind>(k)), 0u) << EffectName(static_cast<EffectKind>(k));
}

TEST(GpsImu, AccelerometerReadsGravityWhileWalkingStraight) {
  const scene::SyntheticCampus site = testing::CourtyardSite();
  const GpsImuStreams s = SimulateGpsImu(site, Backpack(site), Spec(5), EffectSet{}, 1);
  // t in [1, 10] s lies on the first straight leg (20 m at 1.4 m/s), gently up and down the hills.
  for (const ImuSample& m : s.imu) {
    const double t = m.t_ns * 1e-9;
    if (t < 1 || t > 5) continue;
    const Eigen::Vector3d f_world = m.true_orientation * m.accel_m_s2;
    EXPECT_NEAR(f_world.z(), kGravity_m_s2, 0.05);
    EXPECT_LT(f_world.head<2>().norm(), 0.05);
    EXPECT_LT(m.gyro_rad_s.norm(), 1e-9);  // constant heading and pitch
  }
}

// Issue 19: the first sample's window used to reach back before t = 0, where the ping-pong path
// turns round, and read a 180-degree turn (~470 rad/s): integrated from t = 0 the gyro was 1.57 rad
// off. The run starts at t = 0; from sample 0 on, the integrated gyro is the truth's rotation.
TEST(GpsImu, GyroFromTheFirstSampleIntegratesToTheTruth) {
  const scene::SyntheticCampus site = testing::CourtyardSite();
  const GpsImuStreams s = SimulateGpsImu(site, Backpack(site), Spec(5), EffectSet{}, 1);
  const double dt = 1.0 / 150;
  ASSERT_FALSE(s.imu.empty());
  EXPECT_LT(s.imu[0].gyro_rad_s.norm(), 1e-9);  // the walk starts on a straight leg
  EXPECT_NEAR((s.imu[0].true_orientation * s.imu[0].accel_m_s2).z(), kGravity_m_s2, 0.05);
  Eigen::Quaterniond integrated = Eigen::Quaterniond::Identity();
  for (size_t k = 0; k < s.imu.size(); ++k) {
    const double window = k == 0 ? 0.5 * dt : dt;
    const Eigen::Vector3d w = s.imu[k].gyro_rad_s * window;
    const double angle = w.norm();
    if (angle > 0) integrated = integrated * Eigen::Quaterniond(Eigen::AngleAxisd(angle, w / angle));
  }
  const Eigen::Quaterniond start = scene::CameraPoseAt(site, Backpack(site), 0).rotation;
  const Eigen::Quaterniond end = scene::CameraPoseAt(site, Backpack(site), (s.imu.size() - 0.5) * dt).rotation;
  EXPECT_LT(AngleBetween(integrated, start.conjugate() * end), 1e-9);
}

TEST(GpsImu, GyroIntegratesToTheTrueOrientationChangeThroughTurns) {
  const scene::SyntheticCampus site = testing::CourtyardSite();
  // 60 s: two corners and the ping-pong reversal at the path's end (turned at the path's 90°/s).
  const GpsImuStreams s = SimulateGpsImu(site, Backpack(site), Spec(60), EffectSet{}, 1);
  const double dt = 1.0 / 150;
  double max_rate = 0;
  Eigen::Quaterniond integrated = Eigen::Quaterniond::Identity();
  const Eigen::Quaterniond start = scene::CameraPoseAt(site, Backpack(site), 0.5 * dt).rotation;
  for (size_t k = 1; k < s.imu.size(); ++k) {
    const Eigen::Vector3d w = s.imu[k].gyro_rad_s * dt;
    max_rate = std::max(max_rate, s.imu[k].gyro_rad_s.norm());
    const double angle = w.norm();
    const Eigen::Quaterniond step = angle > 0 ? Eigen::Quaterniond(Eigen::AngleAxisd(angle, w / angle)) : Eigen::Quaterniond::Identity();
    integrated = integrated * step;
    if (k % 1500 == 0 || k + 1 == s.imu.size()) {
      const Eigen::Quaterniond truth = start.conjugate() * scene::CameraPoseAt(site, Backpack(site), (k + 0.5) * dt).rotation;
      EXPECT_LT(AngleBetween(integrated, truth), 1e-9) << "after sample " << k;
    }
  }
  EXPECT_GT(max_rate, 1.0);  // the turns were in the window
}

TEST(GpsImu, GpsNoiseHasItsSigmaAndReportsIt) {
  const scene::SyntheticCampus site = testing::CourtyardSite();
  EffectSet e;
  e.Enable(EffectKind::kGpsNoise, {{{"sigma_m", 0.05}, {"sigma_vertical_m", 0.1}}});
  GpsImuSpec spec = Spec(400);
  spec.gps_rate_hz = 10;
  ResetEvaluations();
  const GpsImuStreams s = SimulateGpsImu(site, Backpack(site), spec, e, 7);
  Eigen::Vector3d sum = Eigen::Vector3d::Zero(), sum2 = Eigen::Vector3d::Zero();
  for (const GpsFix& f : s.gps) {
    const Eigen::Vector3d err = f.position_m - f.true_position_m;
    sum += err;
    sum2 += err.cwiseProduct(err);
    EXPECT_NEAR(f.covariance(0, 0), 0.0025, 1e-15);
    EXPECT_NEAR(f.covariance(2, 2), 0.01, 1e-15);
  }
  const double n = static_cast<double>(s.gps.size());
  EXPECT_EQ(Evaluations(EffectKind::kGpsNoise), s.gps.size());
  // 4001 samples: the sample standard deviation is within ~3 % of sigma (4 standard errors).
  EXPECT_NEAR(std::sqrt(sum2.x() / n), 0.05, 0.05 * 0.045);
  EXPECT_NEAR(std::sqrt(sum2.y() / n), 0.05, 0.05 * 0.045);
  EXPECT_NEAR(std::sqrt(sum2.z() / n), 0.10, 0.10 * 0.045);
  EXPECT_LT(sum.head<2>().norm() / n, 4 * 0.05 / std::sqrt(n));
  for (EffectKind k : {EffectKind::kGpsMultipath, EffectKind::kGpsDropout, EffectKind::kImuNoise, EffectKind::kGyroDrift,
                       EffectKind::kMagneticDisturbance}) {
    EXPECT_EQ(Evaluations(k), 0u) << EffectName(k);
  }
}

TEST(GpsImu, DropoutIntervalHasNoValidFixAndTheRestAreUntouched) {
  const scene::SyntheticCampus site = testing::CourtyardSite();
  EffectSet e;
  e.Enable(EffectKind::kGpsDropout, {{{"start_s", 5.0}, {"outage_s", 30.0}}});
  const GpsImuStreams s = SimulateGpsImu(site, Backpack(site), Spec(60), e, 3);
  int invalid = 0;
  for (const GpsFix& f : s.gps) {
    const double t = f.t_ns * 1e-9;
    const bool inside = t >= 5.0 - 1e-9 && t < 35.0 - 1e-9;
    EXPECT_EQ(f.valid, !inside) << "t = " << t;
    if (!f.valid) {
      ++invalid;
      EXPECT_TRUE(f.position_m.array().isNaN().all());
      EXPECT_TRUE(f.true_position_m.allFinite());  // the truth is still known
    } else {
      EXPECT_EQ(f.position_m, f.true_position_m);
    }
  }
  EXPECT_EQ(invalid, 150);  // 30 s at 5 Hz
}

TEST(GpsImu, MultipathIsSlowAndLargerNearBuildings) {
  const scene::SyntheticCampus site = testing::CourtyardSite();
  EffectSet e;
  e.Enable(EffectKind::kGpsMultipath, {{{"sigma_m", 0.3}, {"tau_s", 30.0}}});
  const GpsImuStreams s = SimulateGpsImu(site, Backpack(site), Spec(120), e, 5);
  // Slowly varying: fix-to-fix changes are far smaller than the bias itself.
  double step2 = 0, bias2 = 0;
  for (size_t k = 1; k < s.gps.size(); ++k) {
    const Eigen::Vector3d b0 = s.gps[k - 1].position_m - s.gps[k - 1].true_position_m, b1 = s.gps[k].position_m - s.gps[k].true_position_m;
    step2 += (b1 - b0).squaredNorm();
    bias2 += b1.squaredNorm();
  }
  EXPECT_LT(step2, 0.05 * bias2);
  EXPECT_GT(bias2 / s.gps.size(), 0.01);
}

TEST(GpsImu, GyroDriftGrowsThenStaysBoundedAndImuNoiseMatchesSigma) {
  const scene::SyntheticCampus site = testing::CourtyardSite();
  EffectSet drift;
  drift.Enable(EffectKind::kGyroDrift, {{{"bias_rad_s", 0.01}, {"random_walk_rad_s_sqrt_s", 0.0}, {"correction_tau_s", 20.0}}});
  const GpsImuStreams s = SimulateGpsImu(site, Backpack(site), Spec(200), drift, 2);
  const double err_1s = AngleBetween(s.imu[150].orientation, s.imu[150].true_orientation);
  const double err_end = AngleBetween(s.imu.back().orientation, s.imu.back().true_orientation);
  EXPECT_NEAR(err_1s, 0.01 * std::sqrt(3.0) * 1.0, 0.002);          // ~ bias * t early on
  EXPECT_NEAR(err_end, 0.01 * std::sqrt(3.0) * 20.0, 0.02);         // ~ bias * tau when settled
  EXPECT_NEAR(std::abs((s.imu[10].gyro_rad_s - SimulateGpsImu(site, Backpack(site), Spec(1), EffectSet{}, 2).imu[10].gyro_rad_s).x()), 0.01, 1e-9);

  EffectSet noise;
  noise.Enable(EffectKind::kImuNoise, {{{"gyro_sigma_rad_s", 0.01}, {"orientation_sigma_deg", 2.0}}});
  const GpsImuStreams clean = SimulateGpsImu(site, Backpack(site), Spec(30), EffectSet{}, 2);
  const GpsImuStreams noisy = SimulateGpsImu(site, Backpack(site), Spec(30), noise, 2);
  double g2 = 0, a2 = 0;
  for (size_t k = 0; k < noisy.imu.size(); ++k) {
    g2 += (noisy.imu[k].gyro_rad_s - clean.imu[k].gyro_rad_s).squaredNorm();
    a2 += std::pow(AngleBetween(noisy.imu[k].orientation, clean.imu[k].orientation), 2);
  }
  const double n = static_cast<double>(noisy.imu.size());
  EXPECT_NEAR(std::sqrt(g2 / (3 * n)), 0.01, 0.0006);
  EXPECT_NEAR(std::sqrt(a2 / (3 * n)), 2.0 * M_PI / 180, 0.0015);
}

TEST(GpsImu, MagneticDisturbanceTurnsTheHeadingOnlyNearBuildings) {
  scene::SyntheticCampus site = testing::CourtyardSite();
  EffectSet e;
  e.Enable(EffectKind::kMagneticDisturbance, {{{"radius_m", 10.0}, {"strength_uT", 20.0}}});
  const GpsImuStreams s = SimulateGpsImu(site, Backpack(site), Spec(60), e, 4);
  double near_err = 0, far_err = 1;
  for (const ImuSample& m : s.imu) {
    const Eigen::Vector3d p = scene::CameraPoseAt(site, Backpack(site), m.t_ns * 1e-9).translation;
    // Distance to the east building (x = 24 +- 4): the path's leg at x = 10 is 10 m away.
    const double err = AngleBetween(m.orientation, m.true_orientation);
    if (std::abs(p.x()) < 1 && std::abs(p.y() + 15) < 1) far_err = std::min(far_err, err);
    near_err = std::max(near_err, err);
    EXPECT_TRUE(m.magnetic.allFinite());
  }
  EXPECT_LT(far_err, 1e-6);
  EXPECT_GT(near_err, 0.05);
}

TEST(GpsImu, ZeroDurationAndBadRatesAreHandled) {
  const scene::SyntheticCampus site = testing::CourtyardSite();
  GpsImuSpec spec = Spec(0);
  const GpsImuStreams s = SimulateGpsImu(site, Backpack(site), spec, EffectSet{}, 1);
  ASSERT_EQ(s.gps.size(), 1u);
  ASSERT_EQ(s.imu.size(), 1u);
  EXPECT_EQ(s.gps[0].t_ns, 0);
  EXPECT_TRUE(s.imu[0].gyro_rad_s.allFinite());
  EXPECT_TRUE(s.imu[0].accel_m_s2.allFinite());
  for (double bad : std::vector<double>{0.0, -5.0, NAN, INFINITY}) {
    spec = Spec(1);
    spec.gps_rate_hz = bad;
    EXPECT_THAT(spec.Check(), ::testing::HasSubstr("gps_rate_hz"));
    EXPECT_TRUE(SimulateGpsImu(site, Backpack(site), spec, EffectSet{}, 1).gps.empty());
    spec = Spec(1);
    spec.imu_rate_hz = bad;
    EXPECT_THAT(spec.Check(), ::testing::HasSubstr("imu_rate_hz"));
  }
  spec = Spec(-1);
  EXPECT_THAT(spec.Check(), ::testing::HasSubstr("duration_s"));
  // A fixed camera: zero rates, gravity only.
  scene::CameraSpec fixed = Backpack(site);
  fixed.path.reset();
  const GpsImuStreams still = SimulateGpsImu(site, fixed, Spec(1), EffectSet{}, 1);
  for (const ImuSample& m : still.imu) {
    EXPECT_EQ(m.gyro_rad_s.norm(), 0.0);
    EXPECT_NEAR((m.true_orientation * m.accel_m_s2 - Eigen::Vector3d(0, 0, kGravity_m_s2)).norm(), 0, 1e-12);
  }
}

TEST(GpsImu, DeterministicAndCsvKeepsHugeWorldCoordinatesExactly) {
  scene::SyntheticCampus site = testing::CourtyardSite();
  site.origin = Eigen::Vector3d(4'500'123.456, 5'432'109.876, 1234.5);  // state-plane-like magnitudes
  EffectSet e;
  e.Enable(EffectKind::kGpsNoise, {});
  e.Enable(EffectKind::kImuNoise, {});
  const GpsImuStreams a = SimulateGpsImu(site, Backpack(site), Spec(3), e, 11);
  const GpsImuStreams b = SimulateGpsImu(site, Backpack(site), Spec(3), e, 11);
  ASSERT_EQ(a.gps.size(), b.gps.size());
  for (size_t k = 0; k < a.gps.size(); ++k) EXPECT_EQ(a.gps[k].position_m, b.gps[k].position_m);
  for (size_t k = 0; k < a.imu.size(); ++k) EXPECT_EQ(a.imu[k].orientation.coeffs(), b.imu[k].orientation.coeffs());

  const std::string dir = (std::filesystem::temp_directory_path() / ("ave_gps_" + std::to_string(::getpid()))).string();
  ASSERT_TRUE(WriteGpsImu(a, dir).ok());
  std::ifstream gps(dir + "/gps.csv");
  std::string line;
  std::getline(gps, line);
  EXPECT_THAT(line, ::testing::StartsWith("t_ns,valid,x_m,y_m,z_m,cov_xx"));
  size_t rows = 0;
  while (std::getline(gps, line)) {
    std::stringstream ss(line);
    std::string cell;
    std::vector<double> v;
    while (std::getline(ss, cell, ',')) v.push_back(std::stod(cell));
    ASSERT_EQ(v.size(), 14u);
    EXPECT_EQ(static_cast<int64_t>(v[0]), a.gps[rows].t_ns);
    // Back in the local frame to the last bit a double at 5e6 m holds (~1 nm).
    EXPECT_NEAR(v[2] - site.origin.x(), a.gps[rows].position_m.x(), 2e-9);
    EXPECT_NEAR(v[3] - site.origin.y(), a.gps[rows].position_m.y(), 2e-9);
    EXPECT_NEAR(v[11] - site.origin.x(), a.gps[rows].true_position_m.x(), 2e-9);
    ++rows;
  }
  EXPECT_EQ(rows, a.gps.size());
  std::ifstream imu(dir + "/imu.csv"), truth(dir + "/truth.csv");
  size_t imu_rows = 0, truth_rows = 0;
  while (std::getline(imu, line)) ++imu_rows;
  while (std::getline(truth, line)) ++truth_rows;
  EXPECT_EQ(imu_rows, a.imu.size() + 1);
  EXPECT_EQ(truth_rows, a.truth_at_video_rate.size() + 1);
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace ave::sim
