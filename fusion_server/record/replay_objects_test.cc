// Issue 18 "done when": a replay shows the fused objects on the same paths as the live scene did.
// A live SceneState on the campus terrain records through the recorder (its accepted-frame
// observer, as the server wires it); a walker's boxes from two cameras fuse into one object. The
// replay of the recording, asked at the same instants, gives the same objects: ids, positions,
// covariances, paths and cameras, exactly.
#include <gtest/gtest.h>

#include "fusion_server/core/convert.h"
#include "fusion_server/core/placement.h"
#include "fusion_server/record/record_test_util.h"
#include "fusion_server/record/recorder.h"
#include "fusion_server/record/replay.h"
#include "model_store/scene/campus.h"

namespace ave::record {
namespace {

const scene::SyntheticCampus& Campus() {
  static const scene::SyntheticCampus campus = scene::BuiltinCampus();
  return campus;
}

// A frame of camera `c` (with a real JPEG) holding one box whose bottom-middle pixel is `p_in_world`.
std::shared_ptr<v1::SensorFrame> WalkerFrame(const scene::CameraSpec& c, const Eigen::Vector3d& p_in_world,
                                             int64_t t_ns, uint64_t sequence, uint32_t track) {
  const std::optional<Eigen::Vector2d> uv = ProjectToPixel(c.intrinsics, c.world_from_camera.Inverse() * p_in_world);
  EXPECT_TRUE(uv.has_value());
  const double u = uv->x() + 0.5, v = uv->y() + 0.5;
  auto frame = testing::TestFrame(sequence, t_ns, testing::TestJpeg(static_cast<int>(sequence)));
  *frame->mutable_pose() = ToProto(c.world_from_camera);
  frame->clear_boxes();
  v1::DetectedBox* box = frame->add_boxes();
  box->set_track_id(track);
  box->set_score(0.9f);
  for (const auto& [x, y] : {std::pair{u - 4, v - 20}, {u + 4, v - 20}, {u + 4, v}, {u - 4, v}}) {
    v1::Point2* p = box->add_corners();
    p->set_x(static_cast<float>(x));
    p->set_y(static_cast<float>(y));
  }
  return frame;
}

TEST(ReplayObjects, ReplayShowsTheObjectsOnTheSamePathsAsLive) {
  testing::TempRecording rec;
  SceneState live;
  live.SetStaticModel(scene::BuildStaticMesh(Campus(), 2.0));
  std::vector<CameraEntry> registry;
  for (const char* id : {"cam1", "cam3"}) {
    const scene::CameraSpec& c = *Campus().FindCamera(id);
    registry.push_back({c.id, c.name, c.intrinsics, c.world_from_camera, "", true});
    live.UpsertCamera(registry.back());
  }
  RecorderOptions o;
  o.dir = rec.dir();
  o.flush_period = std::chrono::milliseconds(50);
  auto recorder = Recorder::Open(rec.store_path(), o);
  ASSERT_TRUE(recorder.ok()) << recorder.status();
  live.SetObservers(
      [&](const std::string& id, const std::shared_ptr<const v1::SensorFrame>& frame, int64_t received_ns,
          int64_t capture_server_ns) { (*recorder)->SubmitFrame(id, frame, received_ns, capture_server_ns); },
      {});

  const int64_t t0 = 1'700'000'000'000'000'000;
  std::vector<std::pair<int64_t, v1::SceneUpdate>> seen_live;
  for (int f = 0; f < 30; ++f) {
    const double x = -2 + 0.14 * f, y = -5;  // walking east at 1.4 m/s, 10 fps
    const Eigen::Vector3d truth(x, y, Campus().TerrainHeight(x, y));
    const int64_t t = t0 + f * 100'000'000LL;
    for (const char* id : {"cam1", "cam3"}) {
      const scene::CameraSpec& c = *Campus().FindCamera(id);
      auto frame = WalkerFrame(c, truth, t + (std::string(id) == "cam3" ? 1000 : 0), f + 1, std::string(id) == "cam1" ? 4 : 11);
      ASSERT_TRUE(live.AcceptFrame(id, frame, frame->capture_time_ns()).ok());
    }
    if (f % 5 == 4) {
      ViewerCursor cursor;
      seen_live.emplace_back(t + 1000, live.BuildUpdate({}, false, t + 1000, cursor));
    }
  }
  (*recorder)->Drain();
  ASSERT_EQ((*recorder)->Stats().frames_recorded, 60u);
  ASSERT_GE(seen_live.back().second.objects_size(), 1);

  ReplayOptions ro;
  ro.store_path = rec.store_path();
  ro.dir = rec.dir();
  ro.from_ns = t0;
  ro.to_ns = t0 + 4'000'000'000LL;
  auto replay = ReplaySession::Open(ro, registry, live.terrain());
  ASSERT_TRUE(replay.ok()) << replay.status();
  for (const auto& [t, want] : seen_live) {
    ASSERT_TRUE((*replay)->AdvanceTo(t).ok());
    ViewerCursor cursor;
    const v1::SceneUpdate got = (*replay)->state().BuildUpdate({}, false, t, cursor);
    ASSERT_EQ(got.objects_size(), want.objects_size()) << "at " << (t - t0) / 1e6 << " ms";
    for (int i = 0; i < want.objects_size(); ++i) {
      const v1::DynamicObject& a = want.objects(i);
      const v1::DynamicObject& b = got.objects(i);
      EXPECT_EQ(b.object_id(), a.object_id());
      EXPECT_EQ(b.position().x(), a.position().x());
      EXPECT_EQ(b.position().y(), a.position().y());
      EXPECT_EQ(b.position().z(), a.position().z());
      EXPECT_EQ(b.heading_rad(), a.heading_rad());
      ASSERT_EQ(b.path_size(), a.path_size());
      for (int k = 0; k < a.path_size(); ++k) {
        EXPECT_EQ(b.path(k).x(), a.path(k).x());
        EXPECT_EQ(b.path(k).y(), a.path(k).y());
      }
      ASSERT_EQ(b.position_covariance_size(), a.position_covariance_size());
      for (int k = 0; k < a.position_covariance_size(); ++k) EXPECT_EQ(b.position_covariance(k), a.position_covariance(k));
      EXPECT_EQ(b.camera_ids_size(), a.camera_ids_size());
    }
  }
  EXPECT_GE(seen_live.back().second.objects(0).path_size(), 5);
}

}  // namespace
}  // namespace ave::record
