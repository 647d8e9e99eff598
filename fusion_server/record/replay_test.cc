#include "fusion_server/record/replay.h"

#include <filesystem>
#include <map>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "fusion_server/record/record_test_util.h"
#include "fusion_server/record/recorder.h"

namespace ave::record {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using testing::TempRecording;
using testing::TestFrame;
using testing::TestJpeg;

constexpr int64_t kT0 = 1'700'000'000'000'000'000;
constexpr int64_t kFrameNs = 100'000'000;  // 10 fps

CameraEntry Camera(const std::string& id) {
  CameraEntry e;
  e.id = id;
  e.name = "camera " + id;
  e.intrinsics = PinholeIntrinsics::FromFov(160, 120, 60);
  e.mounting_pose = Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0, 0, 5));
  return e;
}

// Two cameras, 30 frames each over 3 s; cam-b's frames 5 us after cam-a's on the server clock.
// Returns the JPEG of each (camera, sequence).
std::map<std::pair<std::string, uint64_t>, std::string> RecordTwoCameras(const TempRecording& rec,
                                                                         int64_t segment_max_bytes = 64 << 20) {
  std::map<std::pair<std::string, uint64_t>, std::string> sent;
  RecorderOptions o;
  o.dir = rec.dir();
  o.flush_period = std::chrono::milliseconds(50);
  o.segment_max_bytes = segment_max_bytes;
  auto recorder = Recorder::Open(rec.store_path(), o);
  EXPECT_TRUE(recorder.ok()) << recorder.status();
  for (const std::string id : {"cam-a", "cam-b"}) (*recorder)->NoteSensor(id, EntryBytes(Camera(id)));
  for (uint64_t k = 0; k < 30; ++k) {
    for (const std::string id : {"cam-a", "cam-b"}) {
      const int64_t t = kT0 + static_cast<int64_t>(k) * kFrameNs + (id == "cam-b" ? 5000 : 0);
      std::string jpeg = TestJpeg(static_cast<int>(k) + (id == "cam-b" ? 50 : 0));
      sent[{id, k + 1}] = jpeg;
      (*recorder)->SubmitFrame(id, TestFrame(k + 1, t, jpeg), t + 1000, t);
    }
  }
  (*recorder)->Drain();
  return sent;
}

ReplayOptions Range(const TempRecording& rec, int64_t from_ns, int64_t to_ns) {
  ReplayOptions o;
  o.store_path = rec.store_path();
  o.dir = rec.dir();
  o.from_ns = from_ns;
  o.to_ns = to_ns;
  return o;
}

const v1::CameraState* Find(const v1::SceneUpdate& update, const std::string& id) {
  for (const auto& cam : update.cameras()) {
    if (cam.camera_id() == id) return &cam;
  }
  return nullptr;
}

TEST(Replay, FramesComeBackInServerCaptureOrderWithTheirBytes) {
  TempRecording rec;
  auto sent = RecordTwoCameras(rec);
  auto session = ReplaySession::Open(Range(rec, kT0, kT0 + 3'000'000'000), {}, nullptr);
  ASSERT_TRUE(session.ok()) << session.status();
  ViewerCursor cursor;
  int64_t previous_ns = 0;
  int updates_with_jpeg = 0;
  for (;;) {
    auto next = (*session)->NextEventNs();
    ASSERT_TRUE(next.ok());
    if (!*next) break;
    EXPECT_GE(**next, previous_ns);
    previous_ns = **next;
    ASSERT_EQ(*(*session)->AdvanceTo(**next), 1u);  // one recorded frame at each instant
    const v1::SceneUpdate update = (*session)->state().BuildUpdate({}, true, **next, cursor);
    for (const auto& cam : update.cameras()) {
      if (cam.jpeg().empty()) continue;
      ++updates_with_jpeg;
      EXPECT_EQ(cam.jpeg(), (sent[{cam.camera_id(), cam.frame_sequence()}]));
      EXPECT_EQ(cam.frame_capture_server_time_ns(), **next);
      EXPECT_EQ(cam.status(), v1::CAMERA_STATUS_LIVE);
      EXPECT_EQ(cam.name(), "camera " + cam.camera_id());
      EXPECT_EQ(cam.projection_matrix_size(), 16);
    }
  }
  EXPECT_EQ(updates_with_jpeg, 60);
  EXPECT_EQ((*session)->frames_replayed(), 60u);
  EXPECT_TRUE((*session)->TakeGaps().empty());
}

TEST(Replay, SeekShowsEachCamerasNewestImageBeforeTheStart) {
  TempRecording rec;
  auto sent = RecordTwoCameras(rec);
  // Start between frame 11 (t0 + 1.0 s) and frame 12 of both cameras.
  const int64_t from_ns = kT0 + 1'050'000'000;
  auto session = ReplaySession::Open(Range(rec, from_ns, kT0 + 2'000'000'000), {}, nullptr);
  ASSERT_TRUE(session.ok()) << session.status();
  ViewerCursor cursor;
  const v1::SceneUpdate update = (*session)->state().BuildUpdate({}, true, from_ns, cursor);
  ASSERT_EQ(update.cameras_size(), 2);
  for (const std::string id : {"cam-a", "cam-b"}) {
    const v1::CameraState* cam = Find(update, id);
    ASSERT_NE(cam, nullptr);
    EXPECT_EQ(cam->frame_sequence(), 11u);
    EXPECT_EQ(cam->jpeg(), (sent[{id, 11}]));
  }
  auto next = (*session)->NextEventNs();
  ASSERT_TRUE(next.ok() && *next);
  EXPECT_EQ(**next, kT0 + 11 * kFrameNs);
}

TEST(Replay, DeletedSegmentIsSkippedAsAGap) {
  TempRecording rec;
  // About five frames per segment: deleting one of cam-a's middle segments loses ~5 frames.
  RecordTwoCameras(rec, 5 * static_cast<int64_t>(TestJpeg(0).size()));
  auto index = RecordIndex::Open(rec.store_path());
  auto segments = (*index)->Segments();
  ASSERT_TRUE(segments.ok());
  std::vector<SegmentRow> cam_a;
  for (const SegmentRow& s : *segments) {
    if (s.sensor_id == "cam-a") cam_a.push_back(s);
  }
  ASSERT_GE(cam_a.size(), 3u);
  const SegmentRow& victim = cam_a[1];
  ASSERT_TRUE(fs::remove(fs::path(rec.dir()) / victim.path));  // deleted by hand

  auto session = ReplaySession::Open(Range(rec, kT0, kT0 + 3'000'000'000), {}, nullptr);
  ASSERT_TRUE(session.ok()) << session.status();
  auto fed = (*session)->AdvanceTo(kT0 + 3'000'000'000);
  ASSERT_TRUE(fed.ok()) << fed.status();
  EXPECT_EQ(*fed, 60u);
  const std::vector<v1::ReplayGap> gaps = (*session)->TakeGaps();
  ASSERT_EQ(gaps.size(), 1u);
  EXPECT_EQ(gaps[0].camera_id(), "cam-a");
  EXPECT_EQ(gaps[0].from_ns(), victim.start_ns);
  EXPECT_EQ(gaps[0].to_ns(), victim.end_ns);
  EXPECT_THAT(gaps[0].reason(), HasSubstr("missing"));
  EXPECT_EQ((*session)->frames_replayed(), 60u - gaps[0].frames());
  // The camera's image after the gap is shown again.
  ViewerCursor cursor;
  const v1::SceneUpdate update = (*session)->state().BuildUpdate({"cam-a"}, true, kT0 + 3'000'000'000, cursor);
  ASSERT_EQ(update.cameras_size(), 1);
  EXPECT_EQ(update.cameras(0).frame_sequence(), 30u);
  EXPECT_FALSE(update.cameras(0).jpeg().empty());
}

TEST(Replay, CameraRemovedFromTheRegistryStillReplays) {
  TempRecording rec;
  RecordTwoCameras(rec);
  // The live registry now holds only an unrelated camera: cam-b's recorded entry is used.
  auto session = ReplaySession::Open(Range(rec, kT0, kT0 + 1'000'000'000), {Camera("other")}, nullptr);
  ASSERT_TRUE(session.ok()) << session.status();
  EXPECT_THAT((*session)->sensor_ids(), ::testing::ElementsAre("cam-a", "cam-b"));
  ASSERT_TRUE((*session)->AdvanceTo(kT0 + 1'000'000'000).ok());
  ViewerCursor cursor;
  const v1::SceneUpdate update = (*session)->state().BuildUpdate({"cam-b"}, true, kT0 + 1'000'000'000, cursor);
  ASSERT_EQ(update.cameras_size(), 1);
  EXPECT_EQ(update.cameras(0).name(), "camera cam-b");
  EXPECT_EQ(update.cameras(0).intrinsics().width(), 160u);
  EXPECT_FALSE(update.cameras(0).jpeg().empty());
}

TEST(Replay, EmptyRangeAnswersWithTheRecordedSpans) {
  TempRecording rec;
  RecordTwoCameras(rec);
  auto before = ReplaySession::Open(Range(rec, kT0 - 60'000'000'000, kT0 - 1), {}, nullptr);
  ASSERT_EQ(before.status().code(), absl::StatusCode::kNotFound);
  EXPECT_THAT(before.status().message(), HasSubstr("nothing recorded for any camera between"));
  EXPECT_THAT(before.status().message(), HasSubstr("cam-a 1700000000.000 s .. 1700000002.900 s (30 frames)"));
  auto unknown = ReplaySession::Open([&] {
    ReplayOptions o = Range(rec, kT0, kT0 + 1'000'000'000);
    o.sensor_ids = {"gate-9"};
    return o;
  }(), {}, nullptr);
  EXPECT_EQ(unknown.status().code(), absl::StatusCode::kNotFound);
  EXPECT_THAT(unknown.status().message(), HasSubstr("gate-9"));
  auto reversed = ReplaySession::Open(Range(rec, kT0, kT0), {}, nullptr);
  EXPECT_EQ(reversed.status().code(), absl::StatusCode::kInvalidArgument);
}

TEST(Replay, EntryBytesRoundTrip) {
  CameraEntry e = Camera("gate-1");
  e.kind = SensorKind::kCamera;
  auto back = EntryFromBytes(EntryBytes(e));
  ASSERT_TRUE(back.ok());
  EXPECT_EQ(back->id, "gate-1");
  EXPECT_EQ(back->intrinsics.fx, e.intrinsics.fx);
  EXPECT_EQ(back->mounting_pose.translation.z(), 5.0);
  EXPECT_FALSE(EntryFromBytes("\xff\xff not a proto").ok());
}

}  // namespace
}  // namespace ave::record
