// Issue 18, viewer side: SceneClient consumes SceneService.Replay of a real recording server
// instead of the live subscription, through the same snapshot path (decoded images, sequences),
// and knows when the replay ended or was refused.
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "fusion_server/service/test_fixtures.h"
#include "model_store/common/log.h"
#include "viewer_client/client/replay_video.h"
#include "viewer_client/client/scene_client.h"
#include "viewer_client/client/viewer_app.h"

namespace ave {
namespace {

using ::testing::HasSubstr;
constexpr char kSensor[] = "sensor-token", kViewer[] = "viewer-token", kAdmin[] = "admin-token";
constexpr int64_t kFrameNs = 100'000'000;  // 10 fps
constexpr int kFrames = 15;

std::string FrameJpeg(int k) {
  cv::Mat image(48, 64, CV_8UC3, cv::Scalar(k * 9 % 256, 120, 30));
  std::vector<uchar> bytes;
  cv::imencode(".jpg", image, bytes);
  return std::string(bytes.begin(), bytes.end());
}

// Starts a recording server with cam1 and cam2, each having streamed kFrames frames at 10 fps from
// base_ns + 0.1 s on the server clock (a sensor clock 1 ms behind, its offset sent), recorded.
void RecordTwoCameras(fixtures::LocalServer& server, int64_t base_ns) {
  log::MinLevel() = log::Level::kWARNING;
  ServerOptions options = server.Options(kSensor, kViewer, kAdmin);
  options.record_dir = (server.dir() / "rec").string();
  options.campus_grid_m = 8;
  ASSERT_TRUE(server.Start(options).ok());
  auto channel = server.InsecureChannel();
  auto sensor = v1::SensorService::NewStub(channel);
  for (const std::string id : {"cam1", "cam2"}) {
    grpc::ClientContext context;
    context.AddMetadata("authorization", std::string("Bearer ") + kAdmin);
    v1::AddCameraRequest add;
    *add.mutable_camera() = fixtures::CameraRecord(id);
    v1::Camera added;
    ASSERT_TRUE(v1::AdminService::NewStub(channel)->AddCamera(&context, add, &added).ok());
    std::vector<v1::SensorFrame> frames;
    for (int k = 1; k <= kFrames; ++k) {
      v1::SensorFrame f;
      f.set_sequence(k);
      f.set_capture_time_ns(base_ns + k * kFrameNs - 1'000'000);  // a sensor clock 1 ms behind
      f.set_clock_offset_ns(1'000'000);
      *f.mutable_pose() = ToProto(LookAt({0, 0, 10}, {10, 0, 0}));
      f.set_jpeg(FrameJpeg(k));
      frames.push_back(f);
    }
    v1::SensorHello hello;
    hello.set_camera_id(id);
    hello.set_token(kSensor);
    *hello.mutable_intrinsics() = ToProto(PinholeIntrinsics::FromFov(64, 48, 60));
    ASSERT_TRUE(fixtures::StreamFrames(*sensor, hello, frames).ok());
  }
  server->DrainRecorder();
}

TEST(ReplayClient, SceneClientReplaysTheRecordedIntervalInsteadOfLive) {
  fixtures::LocalServer server("ave_replay_client_test");
  const int64_t base_ns = NowNs() - 60'000'000'000;
  ASSERT_NO_FATAL_FAILURE(RecordTwoCameras(server, base_ns));
  auto channel = server.InsecureChannel();

  // The time line's spans through SceneClient: each camera's one interval, frames 1..15 on the
  // server clock; a seek before the recording (a drag to its left) starts at its first frame.
  viewer::SceneClient timeline(channel, kViewer, "replay-client-timeline");
  auto spans = timeline.FetchRecordedSpans();
  ASSERT_TRUE(spans.ok()) << spans.status();
  ASSERT_EQ(spans->cameras.size(), 2u);
  for (const viewer::RecordedCameraSpans& camera : spans->cameras) {
    EXPECT_EQ(camera.frames, static_cast<uint64_t>(kFrames)) << camera.camera_id;
    ASSERT_EQ(camera.intervals_ns.size(), 1u) << camera.camera_id;
    EXPECT_EQ(camera.intervals_ns[0], std::make_pair(base_ns + kFrameNs, base_ns + kFrames * kFrameNs));
  }
  EXPECT_EQ(timeline.FetchRecordedSpans({"cam2"})->cameras.size(), 1u);
  const viewer::ReplaySeek seek = viewer::PlanSeek(base_ns - 5'000'000'000, spans->server_time_ns, *spans);
  ASSERT_FALSE(seek.live);
  EXPECT_EQ(seek.from_ns, base_ns + kFrameNs);
  viewer::SubscribeOptions from_seek;
  from_seek.replay_from_ns = seek.from_ns;
  from_seek.replay_to_ns = seek.to_ns;
  from_seek.replay_rate = 16;
  timeline.Start(from_seek);
  ASSERT_TRUE(timeline.WaitUntil([&](const auto&) { return timeline.replay_ended(); }, std::chrono::seconds(20)))
      << timeline.last_error();
  EXPECT_TRUE(timeline.last_error().empty()) << timeline.last_error();
  for (const viewer::CameraView& cam : timeline.Snapshot()) EXPECT_EQ(cam.frame_sequence, kFrames + 0u) << cam.id;
  timeline.Stop();

  // The first 1.0 s of the 1.5 s recorded (frames 1..9 of each camera at +0.1 s .. +0.9 s), at 16x.
  viewer::SceneClient client(channel, kViewer, "replay-client");
  viewer::SubscribeOptions subscribe;
  subscribe.replay_from_ns = base_ns;
  subscribe.replay_to_ns = base_ns + 1'000'000'000 - 1;
  subscribe.replay_rate = 16;
  client.Start(subscribe);
  const bool ended = client.WaitUntil([&](const auto&) { return client.replay_ended(); }, std::chrono::seconds(20));
  ASSERT_TRUE(ended) << client.last_error();
  EXPECT_TRUE(client.last_error().empty()) << client.last_error();
  const std::vector<viewer::CameraView> cams = client.Snapshot();
  ASSERT_EQ(cams.size(), 2u);
  for (const viewer::CameraView& cam : cams) {
    EXPECT_EQ(cam.frame_sequence, 9u) << cam.id;  // frame 10 is past the range
    ASSERT_NE(cam.image, nullptr) << cam.id;
    EXPECT_EQ(cam.name, "Test " + cam.id);
  }
  EXPECT_GE(client.replay_time_ns(), base_ns + 9 * kFrameNs);
  client.Stop();

  // A range with nothing recorded ends the replay with the server's reason.
  viewer::SceneClient empty(channel, kViewer, "replay-client-empty");
  subscribe.replay_from_ns = base_ns - 3'600'000'000'000;
  subscribe.replay_to_ns = base_ns - 3'500'000'000'000;
  empty.Start(subscribe);
  ASSERT_TRUE(empty.WaitUntil([&](const auto&) { return empty.replay_ended(); }, std::chrono::seconds(20)));
  EXPECT_THAT(empty.last_error(), HasSubstr("nothing recorded"));
  EXPECT_TRUE(empty.Snapshot().empty());
  empty.Stop();
}

// `ave-viewer --headless --replay-from --replay-to --video`: the rendered interval as a Motion-JPEG
// MKV at the recorded timing, 10 frames per recorded second over 2 s however fast the replay ran
// (4x here), each of the window's size; the first frames (before any recorded frame) and the last
// (every camera's image projected) differ.
TEST(ReplayClient, HeadlessReplayWritesTheIntervalAsAVideoAtTheRecordedTiming) {
  fixtures::LocalServer server("ave_replay_video_test");
  const int64_t base_ns = NowNs() - 60'000'000'000;
  ASSERT_NO_FATAL_FAILURE(RecordTwoCameras(server, base_ns));
  viewer::ViewerOptions options;
  options.servers = {server.address()};
  options.token = kViewer;
  options.headless = true;
  options.width = 320;
  options.height = 240;
  options.replay_from_ns = base_ns;
  options.replay_to_ns = base_ns + 2'000'000'000;
  options.replay_rate = 4;
  options.video_path = (server.dir() / "interval.mkv").string();
  options.video_fps = 10;
  options.wait_cameras = 2;
  absl::Status run = viewer::RunViewer(options);
  ASSERT_TRUE(run.ok()) << run;
  EXPECT_EQ(viewer::ReplayVideoFrames(options.replay_from_ns, options.replay_to_ns, 10), 20);
  cv::VideoCapture video(options.video_path);
  ASSERT_TRUE(video.isOpened());
  EXPECT_EQ(video.get(cv::CAP_PROP_FPS), 10);
  std::vector<cv::Mat> frames;
  for (cv::Mat frame; video.read(frame);) frames.push_back(frame.clone());
  ASSERT_EQ(frames.size(), 20u);
  for (const cv::Mat& frame : frames) {
    EXPECT_EQ(frame.cols, 320);
    EXPECT_EQ(frame.rows, 240);
  }
  cv::imwrite((server.dir() / "last.png").string(), frames.back());
  EXPECT_GT(cv::norm(frames.front(), frames.back(), cv::NORM_L1), 0.0) << "the video does not change";

  options.video_path = (server.dir() / "interval.mp4").string();
  absl::Status bad = viewer::RunViewer(options);
  EXPECT_THAT(std::string(bad.message()), HasSubstr(".mkv or .avi"));
}

}  // namespace
}  // namespace ave
