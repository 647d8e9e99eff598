#include "sensor_agent/pose/pose_source.h"

#include <cmath>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "sensor_agent/pose/so3.h"

namespace ave::pose {
namespace {

using ::testing::HasSubstr;

std::unique_ptr<FrameSource> Open(const std::string& spec) {
  auto source = OpenSource(spec, {.fps = 30});
  EXPECT_TRUE(source.ok()) << source.status();
  return source.ok() ? std::move(*source) : nullptr;
}

TEST(PoseSource, GpsImuModeStreamsTheFusedPoseWithASymmetricCovariance) {
  const std::string spec = "sim:campus#backpack";
  auto truth_source = Open(spec);
  PoseSourceOptions options;
  options.mode = PoseMode::kGpsImu;
  options.simulate_s = 5;
  auto fused = WithFusedPose(Open(spec), spec, options);
  ASSERT_TRUE(fused.ok()) << fused.status();
  EXPECT_THAT((*fused)->description(), HasSubstr("pose gps-imu"));
  for (int i = 0; i < 3; ++i) {
    auto truth = truth_source->Next();
    auto frame = (*fused)->Next();
    ASSERT_TRUE(truth.ok() && frame.ok());
    ASSERT_TRUE(frame->world_from_camera && truth->world_from_camera);
    ASSERT_EQ(frame->pose_covariance.size(), 36u);
    for (int r = 0; r < 6; ++r) {
      EXPECT_GT(frame->pose_covariance[r * 6 + r], 0);
      for (int c = 0; c < 6; ++c) EXPECT_DOUBLE_EQ(frame->pose_covariance[r * 6 + c], frame->pose_covariance[c * 6 + r]);
    }
    // Measured, not the truth, but near it.
    EXPECT_LT((frame->world_from_camera->translation - truth->world_from_camera->translation).norm(), 2.0);
    EXPECT_LT(AngleBetweenDeg(frame->world_from_camera->rotation, truth->world_from_camera->rotation), 10.0);
  }
}

TEST(PoseSource, TruthModePassesTheSourceThroughAndOtherModesNeedASimSource) {
  const std::string spec = "sim:campus#backpack";
  auto passed = WithFusedPose(Open(spec), spec, {});
  ASSERT_TRUE(passed.ok());
  auto frame = (*passed)->Next();
  ASSERT_TRUE(frame.ok());
  EXPECT_TRUE(frame->pose_covariance.empty());
  PoseSourceOptions options;
  options.mode = PoseMode::kGpsImu;
  EXPECT_THAT(WithFusedPose(Open(spec), "file:/tmp/x.mp4", options).status().message(), HasSubstr("needs a sim:SCENARIO#CAMERA source"));
  EXPECT_THAT(WithFusedPose(Open(spec), "sim:campus#nobody", options).status().message(), HasSubstr("no camera 'nobody'"));
  options.log_dir = "/nonexistent";
  EXPECT_THAT(WithFusedPose(Open(spec), spec, options).status().message(), HasSubstr("gps.csv"));
}

}  // namespace
}  // namespace ave::pose
