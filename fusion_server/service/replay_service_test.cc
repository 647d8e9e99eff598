// Issue 18 end to end over a real loopback server: frames streamed by sensors are recorded
// (segments + index), and SceneService.Replay gives them back in server capture-clock order with
// their exact bytes, paced or stepped; roles, audit, empty ranges, removed cameras and deleted
// segments as the issue lists them.
#include <filesystem>
#include <limits>
#include <map>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "fusion_server/admin/export.h"
#include "fusion_server/record/record_index.h"
#include "fusion_server/service/test_fixtures.h"
#include "model_store/common/log.h"
#include "model_store/db/store.h"

namespace ave {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

constexpr char kSensor[] = "sensor-token", kViewer[] = "viewer-token", kAdmin[] = "admin-token";
constexpr int64_t kFrameNs = 50'000'000;  // 20 fps
constexpr int kFrames = 20;

// A 64x48 JPEG whose bytes differ per k.
std::string FrameJpeg(int k) {
  cv::Mat image(48, 64, CV_8UC3, cv::Scalar(k % 256, (k * 37) % 256, 90));
  cv::rectangle(image, cv::Rect(k % 60, 0, 4, 48), cv::Scalar(255, 255, 255), cv::FILLED);
  std::vector<uchar> bytes;
  cv::imencode(".jpg", image, bytes);
  return std::string(bytes.begin(), bytes.end());
}

class ReplayServiceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    log::MinLevel() = log::Level::kWARNING;
    ServerOptions options = server_.Options(kSensor, kViewer, kAdmin);
    options.record_dir = (server_.dir() / "rec").string();
    options.campus_grid_m = 8;
    ASSERT_TRUE(server_.Start(options).ok());
    channel_ = server_.InsecureChannel();
    scene_ = v1::SceneService::NewStub(channel_);
    for (const std::string id : {"cam1", "cam2"}) {
      grpc::ClientContext context;
      context.AddMetadata("authorization", std::string("Bearer ") + kAdmin);
      v1::AddCameraRequest request;
      *request.mutable_camera() = fixtures::CameraRecord(id);
      v1::Camera response;
      ASSERT_TRUE(v1::AdminService::NewStub(channel_)->AddCamera(&context, request, &response).ok());
    }
    // Two agents whose sensor clocks disagree by 1000 s; each sends its clock offset, so on the
    // server clock cam2's frames fall 25 ms after cam1's. cam2 streams after cam1 has finished:
    // arrival order is not capture order.
    base_ns_ = NowNs() - 30'000'000'000;
    auto sensor = v1::SensorService::NewStub(channel_);
    for (const std::string id : {"cam1", "cam2"}) {
      const int64_t sensor_clock0 = base_ns_ - (id == "cam1" ? 5'000'000'000 : 1'000'000'000'000);
      const int64_t offset = base_ns_ - sensor_clock0 + (id == "cam2" ? kFrameNs / 2 : 0);
      std::vector<v1::SensorFrame> frames;
      for (int k = 1; k <= kFrames; ++k) {
        v1::SensorFrame f;
        f.set_sequence(k);
        f.set_capture_time_ns(sensor_clock0 + k * kFrameNs);
        f.set_clock_offset_ns(offset);
        *f.mutable_pose() = ToProto(LookAt({0, 0, 10}, {10, 0, 0}));
        f.set_jpeg(FrameJpeg(k + (id == "cam2" ? 100 : 0)));
        sent_[{id, k}] = f.jpeg();
        frames.push_back(f);
      }
      v1::SensorHello hello;
      hello.set_camera_id(id);
      hello.set_token(kSensor);
      *hello.mutable_intrinsics() = ToProto(PinholeIntrinsics::FromFov(64, 48, 60));
      int acks = 0;
      ASSERT_TRUE(fixtures::StreamFrames(*sensor, hello, frames, &acks).ok());
      ASSERT_EQ(acks, kFrames);
    }
    server_->DrainRecorder();
  }

  v1::ReplayRequest Request(int64_t from_ns, int64_t to_ns) const {
    v1::ReplayRequest r;
    r.set_viewer_id("replay-test");
    r.set_start_time_ns(from_ns);
    r.set_end_time_ns(to_ns);
    r.set_include_jpeg(true);
    return r;
  }
  // Reads the whole replay; the call's status.
  grpc::Status Replay(const v1::ReplayRequest& request, std::vector<v1::SceneUpdate>& updates,
                      const std::string& token = kViewer) {
    grpc::ClientContext context;
    context.AddMetadata("authorization", "Bearer " + token);
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
    auto reader = scene_->Replay(&context, request);
    v1::SceneUpdate update;
    while (reader->Read(&update)) updates.push_back(update);
    return reader->Finish();
  }

  fixtures::LocalServer server_{"ave_replay_test"};
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<v1::SceneService::Stub> scene_;
  int64_t base_ns_ = 0;
  std::map<std::pair<std::string, int>, std::string> sent_;
};

TEST_F(ReplayServiceTest, SteppedReplayGivesEveryFrameInServerCaptureOrderWithItsBytes) {
  EXPECT_THAT(server_->RenderMetrics(), HasSubstr("ave_record_frames_total 40\n"));
  v1::ReplayRequest request = Request(base_ns_, base_ns_ + 2 * kFrames * kFrameNs);
  request.set_max_updates(1000);  // stepping: one update per recorded frame
  std::vector<v1::SceneUpdate> updates;
  ASSERT_TRUE(Replay(request, updates).ok());
  std::vector<std::pair<std::string, int>> order;
  int64_t previous_ns = 0;
  for (const v1::SceneUpdate& update : updates) {
    ASSERT_TRUE(update.has_replay());
    for (const v1::CameraState& cam : update.cameras()) {
      if (cam.jpeg().empty()) continue;
      EXPECT_EQ(cam.jpeg(), (sent_[{cam.camera_id(), static_cast<int>(cam.frame_sequence())}]));
      EXPECT_GE(cam.frame_capture_server_time_ns(), previous_ns);
      previous_ns = cam.frame_capture_server_time_ns();
      order.emplace_back(cam.camera_id(), static_cast<int>(cam.frame_sequence()));
    }
  }
  ASSERT_EQ(order.size(), 2u * kFrames);
  EXPECT_EQ(order[0], std::make_pair(std::string("cam1"), 1));
  EXPECT_EQ(order[1], std::make_pair(std::string("cam2"), 1));  // interleaved by the server clock
  EXPECT_EQ(order[3], std::make_pair(std::string("cam2"), 2));
  EXPECT_TRUE(updates.back().replay().end());
  EXPECT_EQ(updates.back().replay().frames_replayed(), 2u * kFrames);

  // The request is in the audit log: who, which cameras, which range.
  auto store = store::Store::Open(server_.store_path());
  ASSERT_TRUE(store.ok());
  auto audit = (*store)->ListAudit(10);
  ASSERT_TRUE(audit.ok());
  const auto replay_row = std::find_if(audit->begin(), audit->end(), [](const auto& a) { return a.action == "Replay"; });
  ASSERT_NE(replay_row, audit->end());
  EXPECT_THAT(replay_row->actor, HasSubstr("viewer:"));
  EXPECT_EQ(replay_row->target, "*");
  EXPECT_THAT(replay_row->after_json, HasSubstr(absl::StrCat("\"from_ns\":", base_ns_)));
}

// Data selection as live (issue 7): a view volume the cameras' frusta do not meet (the unit cube
// at the origin; both cameras look down from 10 m to beyond it) gets poses and status, no JPEG.
TEST_F(ReplayServiceTest, ViewFrustaSelectTheReplayedFramesAsLive) {
  v1::ReplayRequest request = Request(base_ns_, base_ns_ + 2 * kFrames * kFrameNs);
  request.set_max_updates(1000);
  v1::ViewFrustum* view = request.add_views();
  for (int k = 0; k < 16; ++k) view->add_view_projection(k % 5 == 0 ? 1.f : 0.f);
  std::vector<v1::SceneUpdate> updates;
  ASSERT_TRUE(Replay(request, updates).ok());
  ASSERT_FALSE(updates.empty());
  int jpegs = 0;
  for (const v1::SceneUpdate& update : updates) {
    EXPECT_EQ(update.cameras_size(), 2);
    for (const v1::CameraState& cam : update.cameras()) jpegs += !cam.jpeg().empty();
  }
  EXPECT_EQ(jpegs, 0);
  EXPECT_EQ(updates.back().cameras(0).frame_sequence(), static_cast<uint64_t>(kFrames));
}

TEST_F(ReplayServiceTest, PacedReplayEndsWithEveryCamerasLastFrame) {
  v1::ReplayRequest request = Request(base_ns_, base_ns_ + (kFrames + 2) * kFrameNs);
  request.set_rate(16);
  std::vector<v1::SceneUpdate> updates;
  ASSERT_TRUE(Replay(request, updates).ok());
  ASSERT_FALSE(updates.empty());
  int64_t previous_ns = 0;
  for (const v1::SceneUpdate& update : updates) {
    EXPECT_GE(update.replay().replay_time_ns(), previous_ns);
    previous_ns = update.replay().replay_time_ns();
    EXPECT_EQ(update.replay().rate(), 16.0f);
  }
  const v1::SceneUpdate& last = updates.back();
  EXPECT_TRUE(last.replay().end());
  ASSERT_EQ(last.cameras_size(), 2);
  for (const v1::CameraState& cam : last.cameras()) EXPECT_EQ(cam.frame_sequence(), static_cast<uint64_t>(kFrames));
}

TEST_F(ReplayServiceTest, EmptyRangeBadRateAndSensorRoleAreRefusedClearly) {
  std::vector<v1::SceneUpdate> updates;
  grpc::Status empty = Replay(Request(base_ns_ - 600'000'000'000, base_ns_ - 500'000'000'000), updates);
  EXPECT_EQ(empty.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_THAT(empty.error_message(), HasSubstr("nothing recorded for any camera between"));
  EXPECT_THAT(empty.error_message(), HasSubstr("cam1 "));
  v1::ReplayRequest fast = Request(base_ns_, base_ns_ + 1);
  fast.set_rate(32);
  grpc::Status bad_rate = Replay(fast, updates);
  EXPECT_EQ(bad_rate.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_THAT(bad_rate.error_message(), HasSubstr("rate"));
  grpc::Status sensor = Replay(Request(base_ns_, base_ns_ + kFrameNs * kFrames), updates, kSensor);
  EXPECT_EQ(sensor.error_code(), grpc::StatusCode::PERMISSION_DENIED);
  EXPECT_TRUE(updates.empty());
}

TEST_F(ReplayServiceTest, RemovedCameraStillReplaysAndADeletedSegmentIsAGap) {
  {
    grpc::ClientContext context;
    context.AddMetadata("authorization", std::string("Bearer ") + kAdmin);
    v1::RemoveCameraRequest request;
    request.set_id("cam2");
    v1::RemoveCameraResponse response;
    ASSERT_TRUE(v1::AdminService::NewStub(channel_)->RemoveCamera(&context, request, &response).ok());
  }
  auto index = record::RecordIndex::Open(server_.store_path());
  ASSERT_TRUE(index.ok());
  auto segments = (*index)->Segments();
  ASSERT_TRUE(segments.ok());
  for (const record::SegmentRow& seg : *segments) {
    if (seg.sensor_id == "cam1") {
      ASSERT_TRUE(fs::remove(server_.dir() / "rec" / seg.path));  // by hand
    }
  }
  v1::ReplayRequest request = Request(base_ns_, base_ns_ + 2 * kFrames * kFrameNs);
  request.set_max_updates(1000);
  std::vector<v1::SceneUpdate> updates;
  ASSERT_TRUE(Replay(request, updates).ok());
  int cam2_jpegs = 0, cam1_jpegs = 0;
  std::vector<v1::ReplayGap> gaps;
  for (const v1::SceneUpdate& update : updates) {
    for (const v1::CameraState& cam : update.cameras()) {
      if (cam.jpeg().empty()) continue;
      (cam.camera_id() == "cam2" ? cam2_jpegs : cam1_jpegs)++;
      if (cam.camera_id() == "cam2") {
        EXPECT_EQ(cam.name(), "Test cam2");
      }
    }
    for (const v1::ReplayGap& gap : update.replay().gaps()) gaps.push_back(gap);
  }
  EXPECT_EQ(cam2_jpegs, kFrames);  // removed from the registry, replayed from its recorded entry
  EXPECT_EQ(cam1_jpegs, 0);
  ASSERT_FALSE(gaps.empty());
  uint32_t missing = 0;
  for (const v1::ReplayGap& gap : gaps) {
    EXPECT_EQ(gap.camera_id(), "cam1");
    EXPECT_THAT(gap.reason(), HasSubstr("missing"));
    missing += gap.frames();
  }
  EXPECT_EQ(missing, static_cast<uint32_t>(kFrames));
}

// The panel's time line (issue 18): each camera's recorded interval on the server clock, viewers
// allowed, sensors refused, a camera filter honoured, bad ids named.
TEST_F(ReplayServiceTest, RecordedSpansGiveEachCamerasRecordedIntervalOnTheServerClock) {
  auto spans = [&](const v1::RecordedSpansRequest& request, v1::RecordedSpansResponse& response,
                   const std::string& token = kViewer) {
    grpc::ClientContext context;
    context.AddMetadata("authorization", "Bearer " + token);
    return scene_->RecordedSpans(&context, request, &response);
  };
  v1::RecordedSpansResponse all;
  const int64_t before_ns = NowNs();
  ASSERT_TRUE(spans({}, all).ok());
  EXPECT_GE(all.server_time_ns(), before_ns);
  ASSERT_EQ(all.cameras_size(), 2);
  for (const v1::RecordedCamera& camera : all.cameras()) {
    const int64_t skew_ns = camera.camera_id() == "cam2" ? kFrameNs / 2 : 0;
    EXPECT_EQ(camera.frames(), static_cast<uint64_t>(kFrames)) << camera.camera_id();
    ASSERT_EQ(camera.intervals_size(), 1) << camera.camera_id();
    EXPECT_EQ(camera.intervals(0).from_ns(), base_ns_ + kFrameNs + skew_ns) << camera.camera_id();
    EXPECT_EQ(camera.intervals(0).to_ns(), base_ns_ + kFrames * kFrameNs + skew_ns) << camera.camera_id();
  }
  EXPECT_EQ(all.cameras(0).camera_id(), "cam1");

  v1::RecordedSpansRequest one;
  one.add_camera_ids("cam2");
  v1::RecordedSpansResponse cam2;
  ASSERT_TRUE(spans(one, cam2).ok());
  ASSERT_EQ(cam2.cameras_size(), 1);
  EXPECT_EQ(cam2.cameras(0).camera_id(), "cam2");

  v1::RecordedSpansResponse refused;
  EXPECT_EQ(spans({}, refused, kSensor).error_code(), grpc::StatusCode::PERMISSION_DENIED);
  v1::RecordedSpansRequest bad;
  bad.add_camera_ids("cam 1");
  grpc::Status bad_id = spans(bad, refused);
  EXPECT_EQ(bad_id.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_THAT(bad_id.error_message(), HasSubstr("'cam 1' is not a camera id"));
}

// Acked vs stored: an ack says which of the stream's frames are on disk and indexed. A new stream
// starts at 0 (the fixture's earlier frames are another stream's); once the recorder has drained,
// the next ack names the frame before it, and that frame is in the index.
TEST_F(ReplayServiceTest, AcksSayUpToWhichSequenceTheStreamIsRecorded) {
  auto sensor = v1::SensorService::NewStub(channel_);
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
  auto stream = sensor->Stream(&context);
  v1::SensorMessage m;
  m.mutable_hello()->set_camera_id("cam1");
  m.mutable_hello()->set_token(kSensor);
  *m.mutable_hello()->mutable_intrinsics() = ToProto(PinholeIntrinsics::FromFov(64, 48, 60));
  ASSERT_TRUE(stream->Write(m));
  auto send = [&](int k) {
    v1::SensorFrame& f = *m.mutable_frame();
    f.set_sequence(k);
    f.set_capture_time_ns(NowNs());
    *f.mutable_pose() = ToProto(LookAt({0, 0, 10}, {10, 0, 0}));
    f.set_jpeg(FrameJpeg(k));
    v1::SensorAck ack;
    EXPECT_TRUE(stream->Write(m));
    EXPECT_TRUE(stream->Read(&ack));
    EXPECT_EQ(ack.sequence(), static_cast<uint64_t>(k));
    return ack.recorded_sequence();
  };
  const uint64_t first = send(kFrames + 1);
  EXPECT_TRUE(first == 0 || first == kFrames + 1u) << first;  // never the fixture's stream's frame 20
  // Frame 21 is committed; 22, just accepted, may be too if a flush falls between its acceptance
  // and its ack.
  server_->DrainRecorder();
  EXPECT_THAT(send(kFrames + 2), ::testing::AnyOf(kFrames + 1u, kFrames + 2u));
  server_->DrainRecorder();
  EXPECT_THAT(send(kFrames + 3), ::testing::AnyOf(kFrames + 2u, kFrames + 3u));
  stream->WritesDone();
  EXPECT_TRUE(stream->Finish().ok());
  auto index = record::RecordIndex::Open(server_.store_path());
  ASSERT_TRUE(index.ok());
  auto rows = (*index)->Frames({"cam1"}, 0, std::numeric_limits<int64_t>::max(), 1000);
  ASSERT_TRUE(rows.ok());
  for (const uint64_t k : {kFrames + 1u, kFrames + 2u}) {
    EXPECT_TRUE(std::any_of(rows->begin(), rows->end(), [&](const record::FrameRow& r) { return r.sequence == k; })) << k;
  }
}

TEST_F(ReplayServiceTest, ExportWritesEveryRecordedFrameOfTheCameraAsMotionJpegAndIsAudited) {
  const std::string out = (server_.dir() / "cam2.avi").string();
  auto done = ExportClip(channel_, kAdmin, {"cam2", base_ns_, base_ns_ + 2 * kFrames * kFrameNs, out});
  ASSERT_TRUE(done.ok()) << done.status();
  EXPECT_EQ(done->frames, kFrames);
  EXPECT_EQ(done->gaps, 0);
  EXPECT_NEAR(done->fps, 1e9 / kFrameNs, 0.01);
  cv::VideoCapture clip(out);
  ASSERT_TRUE(clip.isOpened());
  int read = 0;
  for (cv::Mat frame; clip.read(frame); ++read) {
    EXPECT_EQ(frame.cols, 64);
    EXPECT_EQ(frame.rows, 48);
  }
  EXPECT_EQ(read, kFrames);
  auto store = store::Store::Open(server_.store_path());
  auto audit = (*store)->ListAudit(10);
  ASSERT_TRUE(audit.ok());
  EXPECT_TRUE(std::any_of(audit->begin(), audit->end(), [](const auto& a) { return a.action == "Export" && a.target == "cam2"; }));
  auto bad = ExportClip(channel_, kAdmin, {"cam2", base_ns_, base_ns_ + 1, (server_.dir() / "x.mp4").string()});
  EXPECT_THAT(bad.status().message(), HasSubstr(".mkv or .avi"));
}

}  // namespace
}  // namespace ave
