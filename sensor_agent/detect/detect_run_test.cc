// --detect-only on a real video file through the file: source (written here with OpenCV).
#include "sensor_agent/detect/detect_run.h"

#include <filesystem>
#include <sstream>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

namespace ave::detect {
namespace {

TEST(RunDetectOnly, VideoFileGivesOneJsonPerFrameAndATrack) {
  const std::string path = (std::filesystem::temp_directory_path() / "ave_detect_run_test.avi").string();
  {
    cv::VideoWriter writer(path, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 15, cv::Size(160, 120));
    if (!writer.isOpened()) GTEST_SKIP() << "this OpenCV cannot write MJPG video";
    cv::RNG rng(7);
    cv::Mat background(120, 160, CV_8UC3);
    rng.fill(background, cv::RNG::UNIFORM, 40, 120);
    cv::GaussianBlur(background, background, {0, 0}, 3);
    for (int f = 0; f < 60; ++f) {
      cv::Mat frame = background.clone();
      if (f >= 10) cv::rectangle(frame, cv::Rect(10 + 2 * (f - 10), 40, 14, 30), cv::Scalar(220, 200, 60), cv::FILLED);
      writer.write(frame);
    }
  }
  absl::StatusOr<std::unique_ptr<FrameSource>> source = OpenSource("file:" + path, {});
  ASSERT_TRUE(source.ok()) << source.status();
  std::ostringstream out;
  DetectorOptions options;
  options.window_s = 2;
  absl::StatusOr<DetectRunSummary> summary = RunDetectOnly(**source, options, out);
  ASSERT_TRUE(summary.ok()) << summary.status();
  EXPECT_EQ(summary->frames, 60);
  EXPECT_EQ(summary->distinct_tracks, 1);
  std::istringstream lines(out.str());
  std::string line;
  int n = 0, with_track = 0;
  while (std::getline(lines, line)) {
    EXPECT_THAT(line, testing::StartsWith("{\"frame\":" + std::to_string(n) + ",\"t\":"));
    with_track += line.find("\"id\":1,\"box\":[[") != std::string::npos;
    ++n;
  }
  EXPECT_EQ(n, 60);
  EXPECT_GE(with_track, 30);
  EXPECT_THAT(summary->ToJson(), testing::HasSubstr("\"frames\":60,\"distinct_tracks\":1,\"fps\":"));
  std::filesystem::remove(path);
}

}  // namespace
}  // namespace ave::detect
