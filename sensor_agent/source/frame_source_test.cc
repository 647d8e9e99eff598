#include "sensor_agent/source/frame_source.h"

#include <filesystem>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/videoio.hpp>

namespace ave {
namespace {

using ::testing::HasSubstr;

TEST(OpenSource, SimulatedCampusCameraGivesFramesWithItsPose) {
  auto source = OpenSource("sim:campus#cam2", {.fps = 5});
  ASSERT_TRUE(source.ok()) << source.status();
  const PinholeIntrinsics k = (*source)->intrinsics();
  auto a = (*source)->Next();
  auto b = (*source)->Next();
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(a->width, k.width);
  EXPECT_EQ(a->height, k.height);
  EXPECT_EQ(a->bgr.size(), size_t(k.width) * k.height * 3);
  ASSERT_TRUE(a->world_from_camera.has_value());
  EXPECT_NEAR(b->scene_time_s - a->scene_time_s, 0.2, 1e-12);
  EXPECT_GE(b->capture_time_ns, a->capture_time_ns);
  EXPECT_FALSE((*source)->live());
}

TEST(OpenSource, BadSpecsNameTheProblem) {
  EXPECT_THAT(std::string(OpenSource("sim:campus#nope", {}).status().message()), HasSubstr("no camera 'nope'"));
  EXPECT_THAT(std::string(OpenSource("sim:mars#cam1", {}).status().message()), HasSubstr("unknown scene"));
  EXPECT_THAT(std::string(OpenSource("ftp://x", {}).status().message()), HasSubstr("unknown scheme"));
  EXPECT_THAT(std::string(OpenSource("file:/no/such/video.avi", {}).status().message()), HasSubstr("cannot open"));
  EXPECT_THAT(std::string(OpenSource("sim:campus#cam1", {.fps = 0}).status().message()), HasSubstr("fps"));
}

TEST(OpenSource, VideoFileIsReadToItsEnd) {
  const std::string path = (std::filesystem::temp_directory_path() / "ave_source_test.avi").string();
  {
    cv::VideoWriter writer(path, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 10, cv::Size(160, 120));
    ASSERT_TRUE(writer.isOpened());
    for (int i = 0; i < 7; ++i) writer.write(cv::Mat(120, 160, CV_8UC3, cv::Scalar(i * 30, 100, 200)));
  }
  auto source = OpenSource("file:" + path, {});
  ASSERT_TRUE(source.ok()) << source.status();
  int frames = 0;
  absl::StatusOr<CapturedFrame> f;
  while ((f = (*source)->Next()).ok()) {
    EXPECT_EQ(f->width, 160);
    EXPECT_EQ(f->height, 120);
    ++frames;
  }
  EXPECT_EQ(frames, 7);
  EXPECT_EQ(f.status().code(), absl::StatusCode::kOutOfRange);
  EXPECT_EQ((*source)->intrinsics().width, 160);
  std::filesystem::remove(path);
}

}  // namespace
}  // namespace ave
