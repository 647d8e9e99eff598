// The GPS multipath as a persisting bias of every fix (issue 19; PoseFilterOptions::gps_bias_sigma_m):
// a Schmidt consider term, so the reported covariance covers an offset that no number of fixes
// averages away, and the estimate is the filter's without it.
#include <cmath>

#include <gtest/gtest.h>

#include "sensor_agent/pose/pose_ekf.h"
#include "sensor_agent/pose/so3.h"

namespace ave::pose {
namespace {

PoseEkf FixesOnly(double bias_sigma_m, const Eigen::Vector3d& offset, double seconds) {
  PoseFilterOptions o;
  o.gps_bias_sigma_m = bias_sigma_m;
  o.gps_min_sigma_m = 0.05;
  PoseEkf ekf(o);
  ekf.Initialize(0, Rigid3d(Eigen::Quaterniond::Identity(), offset), 0.05, 0.01, /*position_from_gps_fix=*/true);
  for (int step = 1; step <= static_cast<int>(seconds * 5); ++step) {
    ekf.Predict(static_cast<int64_t>(step) * 200'000'000);
    EXPECT_TRUE(ekf.UpdatePosition(offset, Eigen::Matrix3d::Identity() * 0.05 * 0.05).accepted()) << step;
  }
  return ekf;
}

TEST(GpsBias, AMinuteOfFixesOffByTheSameMultipathStaysInsideTheReportedCovariance) {
  const Eigen::Vector3d offset(0.4, -0.3, 0.2);  // the receiver's multipath, the truth is the origin
  const PoseEkf with = FixesOnly(0.5, offset, 60);
  const PoseEkf without = FixesOnly(0.0, offset, 60);
  // The estimate is the same: a consider term changes no gain.
  EXPECT_TRUE(with.world_from_camera().translation.isApprox(without.world_from_camera().translation, 1e-12));
  EXPECT_EQ(with.covariance(), without.covariance());
  const Eigen::Vector3d error = with.world_from_camera().translation;  // truth at the origin
  ASSERT_GT(error.norm(), 0.4);
  const Eigen::Matrix3d reported_with = with.PoseCovariance().topLeftCorner<3, 3>();
  const Eigen::Matrix3d reported_without = without.PoseCovariance().topLeftCorner<3, 3>();
  const double nees_with = error.dot(reported_with.ldlt().solve(error)), nees_without = error.dot(reported_without.ldlt().solve(error));
  EXPECT_LT(nees_with, 7.81) << "chi2(3) 95 %";  // the 0.5 m bias covers the 0.54 m offset
  EXPECT_GT(nees_without, 100) << "300 white fixes claim a few centimetres";
  EXPECT_GT(std::sqrt(reported_with(0, 0)), 0.45);
}

TEST(GpsBias, APositionFromAFixCarriesTheBiasFromTheStart) {
  PoseFilterOptions o;
  o.gps_bias_sigma_m = 0.5;
  PoseEkf ekf(o);
  ekf.Initialize(0, Rigid3d(), 0.1, 0.01, /*position_from_gps_fix=*/true);
  EXPECT_NEAR(ekf.PoseCovariance()(0, 0), 0.1 * 0.1 + 0.5 * 0.5, 1e-12);
  EXPECT_NEAR(ekf.PoseCovariance()(3, 3), 0.01 * 0.01, 1e-12);
  ekf.Initialize(0, Rigid3d(), 0.1, 0.01);  // a position from elsewhere does not
  EXPECT_NEAR(ekf.PoseCovariance()(0, 0), 0.1 * 0.1, 1e-12);
  o.gps_bias_sigma_m = -1;
  EXPECT_NE(o.Check().find("gps_bias_sigma_m"), std::string::npos);
}

}  // namespace
}  // namespace ave::pose
