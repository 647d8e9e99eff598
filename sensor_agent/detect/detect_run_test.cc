// --detect-only on a real video file through the file: source (written here with OpenCV).
#include "sensor_agent/detect/detect_run.h"

#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

namespace ave::detect {
namespace {

// A 60-frame MJPG video: a textured background, a plain box walking in from frame 10. Empty when
// this OpenCV cannot write MJPG.
std::string WriteWalkerVideo(const std::string& name) {
  const std::string path = (std::filesystem::temp_directory_path() / name).string();
  cv::VideoWriter writer(path, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 15, cv::Size(160, 120));
  if (!writer.isOpened()) return "";
  cv::RNG rng(7);
  cv::Mat background(120, 160, CV_8UC3);
  rng.fill(background, cv::RNG::UNIFORM, 40, 120);
  cv::GaussianBlur(background, background, {0, 0}, 3);
  for (int f = 0; f < 60; ++f) {
    cv::Mat frame = background.clone();
    if (f >= 10) cv::rectangle(frame, cv::Rect(10 + 2 * (f - 10), 40, 14, 30), cv::Scalar(220, 200, 60), cv::FILLED);
    writer.write(frame);
  }
  return path;
}

// Runs --detect-only on `path` with `latency_s`; the JSON lines go to `lines`.
absl::StatusOr<DetectRunSummary> RunOnVideo(const std::string& path, double latency_s, std::vector<std::string>& lines) {
  absl::StatusOr<std::unique_ptr<FrameSource>> source = OpenSource("file:" + path, {});
  if (!source.ok()) return source.status();
  std::ostringstream out;
  DetectorOptions options;
  options.window_s = 2;
  absl::StatusOr<DetectRunSummary> summary = RunDetectOnly(**source, options, out, 0, latency_s);
  std::istringstream text(out.str());
  lines.clear();
  for (std::string line; std::getline(text, line);) lines.push_back(line);
  return summary;
}

TEST(RunDetectOnly, VideoFileGivesOneJsonPerFrameAndATrack) {
  const std::string path = WriteWalkerVideo("ave_detect_run_test.avi");
  if (path.empty()) GTEST_SKIP() << "this OpenCV cannot write MJPG video";
  std::vector<std::string> lines;
  absl::StatusOr<DetectRunSummary> summary = RunOnVideo(path, 0, lines);
  ASSERT_TRUE(summary.ok()) << summary.status();
  EXPECT_EQ(summary->frames, 60);
  EXPECT_EQ(summary->distinct_tracks, 1);
  int n = 0, with_track = 0;
  for (const std::string& line : lines) {
    EXPECT_THAT(line, testing::StartsWith("{\"frame\":" + std::to_string(n) + ",\"t\":"));
    with_track += line.find("\"id\":1,\"box\":[[") != std::string::npos;
    ++n;
  }
  EXPECT_EQ(n, 60);
  EXPECT_GE(with_track, 30);
  EXPECT_THAT(summary->ToJson(), testing::HasSubstr("\"frames\":60,\"distinct_tracks\":1,\"fps\":"));
  std::filesystem::remove(path);
}

TEST(RunDetectOnly, LatencyWritesTheValidationSecondBackWithTheTracksId) {
  const std::string path = WriteWalkerVideo("ave_detect_run_latency_test.avi");
  if (path.empty()) GTEST_SKIP() << "this OpenCV cannot write MJPG video";
  std::vector<std::string> live, held;
  absl::StatusOr<DetectRunSummary> live_summary = RunOnVideo(path, 0, live);
  absl::StatusOr<DetectRunSummary> held_summary = RunOnVideo(path, 1.0, held);  // validate_s
  ASSERT_TRUE(live_summary.ok()) << live_summary.status();
  ASSERT_TRUE(held_summary.ok()) << held_summary.status();
  EXPECT_EQ(held_summary->frames, live_summary->frames);
  EXPECT_EQ(held_summary->distinct_tracks, live_summary->distinct_tracks);
  ASSERT_EQ(held.size(), live.size());
  const std::string track = "{\"id\":1,\"box\":[[";
  int first_live = -1, gained = 0, first_gained = -1;
  for (size_t f = 0; f < live.size(); ++f) {
    // Every live box is still there, in the same place of the record: back-fill is appended.
    ASSERT_GE(held[f].size(), live[f].size() - 2) << "frame " << f;
    EXPECT_EQ(held[f].substr(0, live[f].size() - 2), live[f].substr(0, live[f].size() - 2)) << "frame " << f;
    const bool in_live = live[f].find(track) != std::string::npos;
    const bool in_held = held[f].find(track) != std::string::npos;
    EXPECT_TRUE(!in_live || in_held) << "frame " << f;
    if (in_live && first_live < 0) first_live = static_cast<int>(f);
    if (in_held && !in_live) {
      ++gained;
      if (first_gained < 0) first_gained = static_cast<int>(f);
      EXPECT_EQ(held[f].find("\"id\":2"), std::string::npos) << "only the one track's id: " << held[f];
    }
  }
  ASSERT_GT(first_live, 0);
  // The validation second (15 frames at 15 fps) before the first live box, and nothing else.
  EXPECT_GE(gained, 12);
  EXPECT_LE(gained, 16);
  EXPECT_EQ(first_gained + gained, first_live);
  std::filesystem::remove(path);
}

TEST(DelayedWriter, HeldRecordGainsBackfillAndOlderOnesAreWritten) {
  std::ostringstream out;
  DelayedWriter writer(out, 1.0);
  const Detection box{7, {{{1, 2}, {3, 2}, {3, 4}, {1, 4}}}, 0.5f};
  writer.Add(0, 0.0, {}, {});
  writer.Add(1, 0.5, {}, {});
  EXPECT_EQ(out.str(), "");  // held
  writer.Add(2, 1.0, {box}, {{0.0, box}, {0.5, box}, {-3.0, box}});  // -3 s: no longer held, dropped
  EXPECT_EQ(writer.backfilled(), 2);
  EXPECT_EQ(out.str(), "");  // 0.0 is exactly one latency old: still held
  writer.Add(3, 1.5, {}, {});
  EXPECT_EQ(out.str(), FrameJson(0, 0.0, {box}) + "\n");
  writer.Flush();
  EXPECT_EQ(out.str(), FrameJson(0, 0.0, {box}) + "\n" + FrameJson(1, 0.5, {box}) + "\n" + FrameJson(2, 1.0, {box}) +
                           "\n" + FrameJson(3, 1.5, {}) + "\n");
}

TEST(DelayedWriter, ZeroLatencyWritesEachFrameAtOnce) {
  std::ostringstream out;
  DelayedWriter writer(out, 0);
  writer.Add(0, 0.0, {}, {});
  EXPECT_EQ(out.str(), FrameJson(0, 0.0, {}) + "\n");
}

}  // namespace
}  // namespace ave::detect
