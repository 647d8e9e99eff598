// Issue 18, viewer side: SceneClient consumes SceneService.Replay of a real recording server
// instead of the live subscription, through the same snapshot path (decoded images, sequences),
// and knows when the replay ended or was refused.
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "fusion_server/service/test_fixtures.h"
#include "model_store/common/log.h"
#include "viewer_client/client/scene_client.h"

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

TEST(ReplayClient, SceneClientReplaysTheRecordedIntervalInsteadOfLive) {
  log::MinLevel() = log::Level::kWARNING;
  fixtures::LocalServer server("ave_replay_client_test");
  ServerOptions options = server.Options(kSensor, kViewer, kAdmin);
  options.record_dir = (server.dir() / "rec").string();
  options.campus_grid_m = 8;
  ASSERT_TRUE(server.Start(options).ok());
  auto channel = server.InsecureChannel();
  const int64_t base_ns = NowNs() - 60'000'000'000;
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

}  // namespace
}  // namespace ave
