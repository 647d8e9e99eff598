#include "fusion_server/core/scene_state.h"

#include <thread>

#include <gtest/gtest.h>

#include "fusion_server/core/convert.h"

namespace ave {
namespace {

CameraEntry Camera(const std::string& id) {
  CameraEntry c;
  c.id = id;
  c.name = "Camera " + id;
  c.intrinsics = PinholeIntrinsics::FromFov(640, 480, 60);
  c.mounting_pose = LookAt({0, 0, 10}, {10, 10, 0});
  return c;
}

std::shared_ptr<const v1::SensorFrame> Frame(uint64_t seq, std::string jpeg = "jpeg-bytes") {
  auto f = std::make_shared<v1::SensorFrame>();
  f->set_sequence(seq);
  f->set_capture_time_ns(static_cast<int64_t>(seq) * 1000);
  f->set_jpeg(std::move(jpeg));
  return f;
}

TEST(SceneState, SendsEachJpegOnceAndOnlyTheLatest) {
  SceneState state;
  state.UpsertCamera(Camera("a"));
  ViewerCursor cursor;
  ASSERT_TRUE(state.AcceptFrame("a", Frame(1, "one"), 0).ok());
  ASSERT_TRUE(state.AcceptFrame("a", Frame(2, "two"), 0).ok());
  v1::SceneUpdate u = state.BuildUpdate({}, true, 0, cursor);
  ASSERT_EQ(u.cameras_size(), 1);
  EXPECT_EQ(u.cameras(0).jpeg(), "two");  // latest-frame semantics: frame 1 is never sent
  EXPECT_EQ(u.cameras(0).frame_sequence(), 2u);
  u = state.BuildUpdate({}, true, 0, cursor);
  EXPECT_TRUE(u.cameras(0).jpeg().empty());  // nothing new
  ASSERT_TRUE(state.AcceptFrame("a", Frame(3, "three"), 0).ok());
  EXPECT_EQ(state.BuildUpdate({}, true, 0, cursor).cameras(0).jpeg(), "three");
}

TEST(SceneState, MatricesFollowThePoseAndFilterAndRemovalWork) {
  SceneState state;
  state.UpsertCamera(Camera("a"));
  state.UpsertCamera(Camera("b"));
  ViewerCursor cursor;
  v1::SceneUpdate u = state.BuildUpdate({"b"}, false, 0, cursor);
  ASSERT_EQ(u.cameras_size(), 1);
  EXPECT_EQ(u.cameras(0).camera_id(), "b");
  ASSERT_EQ(u.cameras(0).view_matrix_size(), 16);
  const Eigen::Matrix4d view = GetMatrix(u.cameras(0).view_matrix());
  const Eigen::Matrix4d expected = GlViewFromWorld(Camera("b").mounting_pose);
  EXPECT_LT((view - expected).cwiseAbs().maxCoeff(), 1e-4);
  EXPECT_EQ(u.cameras(0).status(), v1::CAMERA_STATUS_LOST);
  state.RemoveCamera("b");
  u = state.BuildUpdate({"b"}, false, 0, cursor);
  EXPECT_EQ(u.cameras_size(), 0);
  ASSERT_EQ(u.removed_camera_ids_size(), 1);
  EXPECT_EQ(u.removed_camera_ids(0), "b");
  EXPECT_FALSE(state.AcceptFrame("b", Frame(1), 0).ok());
}

TEST(SceneState, StatusGoesLiveThenStale) {
  SceneState state({.live_window = std::chrono::milliseconds(100), .stale_window = std::chrono::milliseconds(1000)});
  state.UpsertCamera(Camera("a"));
  ASSERT_TRUE(state.AcceptFrame("a", Frame(1), 0).ok());
  ViewerCursor cursor;
  EXPECT_EQ(state.BuildUpdate({}, false, 50'000'000, cursor).cameras(0).status(), v1::CAMERA_STATUS_LIVE);
  EXPECT_EQ(state.BuildUpdate({}, false, 500'000'000, cursor).cameras(0).status(), v1::CAMERA_STATUS_STALE);
  EXPECT_EQ(state.BuildUpdate({}, false, 5'000'000'000, cursor).cameras(0).status(), v1::CAMERA_STATUS_LOST);
}

TEST(SceneState, WaitersWakeOnChangeAndShutdown) {
  SceneState state;
  const uint64_t v = state.version();
  std::thread writer([&] { state.UpsertCamera(Camera("a")); });
  EXPECT_TRUE(state.WaitForChange(v, std::chrono::seconds(5)));
  writer.join();
  state.Shutdown();
  EXPECT_FALSE(state.WaitForChange(state.version(), std::chrono::seconds(5)));
}

TEST(SceneState, SlowViewerSkipsOldFramesForItselfOnlyAndCountsThem) {
  SceneState state;
  state.UpsertCamera(Camera("a"));
  ViewerCursor fast, slow;
  uint64_t fast_skipped = 0;
  ASSERT_TRUE(state.AcceptFrame("a", Frame(1), 10).ok());
  state.BuildUpdate({}, true, 0, fast);
  state.BuildUpdate({}, true, 0, slow);
  for (uint64_t seq = 2; seq <= 6; ++seq) {
    ASSERT_TRUE(state.AcceptFrame("a", Frame(seq), 10).ok());
    state.BuildUpdate({}, true, 0, fast);  // the fast viewer takes every frame
    fast_skipped += fast.last_skipped;
  }
  const v1::SceneUpdate u = state.BuildUpdate({}, true, 0, slow);  // the slow one only now
  EXPECT_EQ(u.cameras(0).frame_sequence(), 6u);
  // The slow viewer last got frame 1; frames 2..5 were replaced before it asked again.
  EXPECT_EQ(u.cameras(0).frames_skipped(), 4u);
  EXPECT_EQ(slow.last_skipped, 4u);
  EXPECT_EQ(fast_skipped, 0u);
  EXPECT_EQ(state.AcceptedCount("a"), 6u);
  ASSERT_EQ(slow.last_sent.size(), 1u);
  EXPECT_EQ(slow.last_sent[0].first, 10);
}

TEST(SceneState, MetadataOnlyFrameIsCountedButKeepsTheLatestImage) {
  SceneState state;
  state.UpsertCamera(Camera("a"));
  ASSERT_TRUE(state.AcceptFrame("a", Frame(5, "image"), 0).ok());
  auto meta = std::make_shared<v1::SensorFrame>();
  meta->set_sequence(6);
  meta->set_capture_time_ns(6000);
  meta->set_metadata_only(true);
  ASSERT_TRUE(state.AcceptFrame("a", meta, 0).ok());
  EXPECT_EQ(state.LatestFrame("a")->jpeg(), "image");
  EXPECT_EQ(state.MetadataCount("a"), 1u);
  EXPECT_EQ(state.AcceptedCount("a"), 1u);
}

TEST(SceneState, ClockOffsetPlacesCaptureOnTheServerClock) {
  SceneState state;
  state.UpsertCamera(Camera("a"));
  auto f = std::make_shared<v1::SensorFrame>(*Frame(1));
  f->set_clock_offset_ns(-250);
  ASSERT_TRUE(state.AcceptFrame("a", f, 0).ok());
  ViewerCursor cursor;
  const v1::SceneUpdate u = state.BuildUpdate({}, true, 0, cursor);
  EXPECT_EQ(u.cameras(0).frame_capture_time_ns(), 1000);
  EXPECT_EQ(u.cameras(0).frame_capture_server_time_ns(), 750);
}

}  // namespace
}  // namespace ave
