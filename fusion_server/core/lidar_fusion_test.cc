// Rotating-LiDAR foot tracks in the server core (issue 16): fused with camera placements into one
// object per person, listed per sensor in the scene update, their points forwarded once.
#include <algorithm>
#include <memory>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "fusion_server/core/convert.h"
#include "fusion_server/core/scene_state.h"
#include "model_store/scene/campus.h"

namespace ave {
namespace {

using ::testing::HasSubstr;
using ::testing::UnorderedElementsAre;

const scene::SyntheticCampus& Campus() {
  static const scene::SyntheticCampus campus = scene::BuiltinCampus();
  return campus;
}

CameraEntry Lidar(const std::string& id, const Eigen::Vector3d& position) {
  CameraEntry e;
  e.id = id;
  e.name = "LiDAR " + id;
  e.kind = SensorKind::kRotatingLidar;
  e.mounting_pose.translation = position;
  return e;
}

// One sweep with one foot track per (id, position); `points` foreground points labelled 1.
std::shared_ptr<v1::LidarSweepFrame> Sweep(uint64_t sequence, int64_t t_ns,
                                           const std::vector<std::pair<uint32_t, Eigen::Vector3d>>& tracks,
                                           uint32_t points = 0) {
  auto s = std::make_shared<v1::LidarSweepFrame>();
  s->set_sequence(sequence);
  s->set_capture_time_ns(t_ns);
  for (const auto& [id, p] : tracks) {
    v1::FootTrack* t = s->add_tracks();
    t->set_track_id(id);
    t->mutable_position()->set_x(p.x());
    t->mutable_position()->set_y(p.y());
    t->mutable_position()->set_z(p.z());
    for (float c : {0.01f, 0.0f, 0.01f}) t->add_covariance(c);
  }
  if (points > 0) {
    s->mutable_foreground()->set_count(points);
    s->mutable_foreground()->set_packed(std::string(8 * points, '\1'));
  }
  return s;
}

// The wire box of camera `c` whose bottom-middle is the projection of `p` (8 x 20 px).
std::shared_ptr<v1::SensorFrame> BoxFrame(const scene::CameraSpec& c, const Eigen::Vector3d& p, int64_t t_ns,
                                          uint64_t sequence, uint32_t track) {
  const std::optional<Eigen::Vector2d> uv = ProjectToPixel(c.intrinsics, c.world_from_camera.Inverse() * p);
  EXPECT_TRUE(uv.has_value());
  const double u = uv->x() + 0.5, v = uv->y() + 0.5;
  auto frame = std::make_shared<v1::SensorFrame>();
  frame->set_capture_time_ns(t_ns);
  frame->set_sequence(sequence);
  *frame->mutable_pose() = ToProto(c.world_from_camera);
  v1::DetectedBox* box = frame->add_boxes();
  box->set_track_id(track);
  box->set_score(0.9f);
  for (const auto& [x, y] : {std::pair{u - 4, v - 20}, {u + 4, v - 20}, {u + 4, v}, {u - 4, v}}) {
    v1::Point2* corner = box->add_corners();
    corner->set_x(static_cast<float>(x));
    corner->set_y(static_cast<float>(y));
  }
  return frame;
}

// The core case: a walker seen by cam1 (a box placed on the terrain) and by a LiDAR (a foot
// track) is one object listing both sensors, of the camera's measured size; the LiDAR's state
// maps its track to that object.
TEST(LidarFusion, WalkerSeenByCameraAndLidarIsOneObjectListingBoth) {
  SceneState state;
  state.SetStaticModel(scene::BuildStaticMesh(Campus(), 2.0));
  const scene::CameraSpec& c = *Campus().FindCamera("cam1");
  state.UpsertCamera({c.id, c.name, c.intrinsics, c.world_from_camera, "", true});
  state.UpsertCamera(Lidar("hdl", Eigen::Vector3d(-10, -10, Campus().TerrainHeight(-10, -10) + 2)));
  const uint64_t camera_session = state.StreamOpened(c.id, c.intrinsics);
  const uint64_t lidar_session = state.StreamOpened("hdl");
  const int64_t t0 = 1'000'000'000'000;
  for (int f = 0; f < 20; ++f) {
    const double x = -2 + 0.14 * f, y = -5;
    const Eigen::Vector3d truth(x, y, Campus().TerrainHeight(x, y));
    const int64_t t = t0 + f * 100'000'000LL;
    ASSERT_TRUE(state.AcceptFrame(c.id, BoxFrame(c, truth, t, f + 1, 4), t, camera_session).ok());
    // The LiDAR's ground plane sits 0.3 m off the terrain here: the server takes the terrain's height.
    ASSERT_TRUE(state.AcceptLidarSweep("hdl", Sweep(f + 1, t + 30'000'000, {{9, truth + Eigen::Vector3d(0.05, 0, 0.3)}}),
                                       t + 30'000'000, lidar_session)
                    .ok());
  }
  ViewerCursor cursor;
  const v1::SceneUpdate update = state.BuildUpdate({}, false, t0 + 2'000'000'000LL, cursor);
  ASSERT_EQ(update.objects_size(), 1);
  const v1::DynamicObject& o = update.objects(0);
  EXPECT_THAT(o.camera_ids(), UnorderedElementsAre("cam1", "hdl"));
  EXPECT_NEAR(o.position().x(), -2 + 0.14 * 19, 0.3);
  EXPECT_NEAR(o.position().y(), -5, 0.3);
  EXPECT_NEAR(o.position().z(), Campus().TerrainHeight(o.position().x(), o.position().y()), 0.1);
  EXPECT_EQ(o.kind(), 1u);  // person
  EXPECT_EQ(o.model(), v1::OBJECT_MODEL_BILLBOARD);
  // The camera measured the size; the LiDAR's stand-in did not pull it towards its own.
  EXPECT_NE(o.size().z(), kLidarPersonSizeM[2]);
  // The LiDAR is listed as a LiDAR, not as a camera to project, and maps its track to the object.
  ASSERT_EQ(update.cameras_size(), 1);
  ASSERT_EQ(update.lidars_size(), 1);
  const v1::LidarState& lidar = update.lidars(0);
  EXPECT_EQ(lidar.sensor_id(), "hdl");
  EXPECT_EQ(lidar.sweep_sequence(), 20u);
  ASSERT_EQ(lidar.tracks_size(), 1);
  EXPECT_EQ(lidar.tracks(0).track_id(), 9u);
  ASSERT_EQ(lidar.track_object_ids_size(), 1);
  EXPECT_EQ(lidar.track_object_ids(0), o.object_id());
}

// A person only the LiDAR sees is a person-sized billboard standing on the track's ground height
// (no terrain on this server), with the LiDAR as its only sensor.
TEST(LidarFusion, LidarOnlyPersonIsAPersonSizedBillboard) {
  SceneState state;
  state.UpsertCamera(Lidar("hdl", Eigen::Vector3d(0, 0, 2)));
  const int64_t t0 = 5'000'000'000'000;
  ASSERT_TRUE(state.AcceptLidarSweep("hdl", Sweep(1, t0, {{1, {3, 4, 0.25}}, {2, {-6, 1, 0.1}}}), t0, 1).ok());
  ViewerCursor cursor;
  const v1::SceneUpdate update = state.BuildUpdate({}, false, t0 + 100'000'000, cursor);
  ASSERT_EQ(update.objects_size(), 2);
  for (const v1::DynamicObject& o : update.objects()) {
    EXPECT_EQ(o.kind(), 1u);
    EXPECT_EQ(o.model(), v1::OBJECT_MODEL_BILLBOARD);
    EXPECT_DOUBLE_EQ(o.size().x(), kLidarPersonSizeM[0]);
    EXPECT_DOUBLE_EQ(o.size().z(), kLidarPersonSizeM[2]);
    ASSERT_EQ(o.camera_ids_size(), 1);
    EXPECT_EQ(o.camera_ids(0), "hdl");
    EXPECT_EQ(o.source_camera_id(), "hdl");
    ASSERT_EQ(o.position_covariance_size(), 3);
    EXPECT_NEAR(o.position_covariance(0), 0.01, 1e-6);
  }
  const auto near = [&](double x) {
    return std::any_of(update.objects().begin(), update.objects().end(),
                       [&](const v1::DynamicObject& o) { return std::abs(o.position().x() - x) < 1e-9; });
  };
  EXPECT_TRUE(near(3) && near(-6));
  // Unseen for longer than forget_s: gone, like camera objects.
  ASSERT_TRUE(state.AcceptLidarSweep("hdl", Sweep(2, t0 + 5'000'000'000, {}), t0 + 5'000'000'000, 1).ok());
  EXPECT_EQ(state.BuildUpdate({}, false, t0 + 5'000'000'000, cursor).objects_size(), 0);
}

// The sweep's foreground points go to a viewer that asked for them, once per sweep; tracks and
// status go to every viewer.
TEST(LidarFusion, PointsGoOutOnceAndOnlyToViewersThatAskForThem) {
  SceneState state;
  state.UpsertCamera(Lidar("hdl", Eigen::Vector3d(0, 0, 2)));
  ViewerCursor plain, points;
  points.include_lidar_points = true;
  v1::SceneUpdate u = state.BuildUpdate({}, false, 0, points);
  ASSERT_EQ(u.lidars_size(), 1);
  EXPECT_EQ(u.lidars(0).status(), v1::CAMERA_STATUS_LOST);
  EXPECT_EQ(u.lidars(0).pose().position().z(), 2);  // the registered pose until a sweep says otherwise
  const int64_t t0 = 7'000'000'000'000;
  ASSERT_TRUE(state.AcceptLidarSweep("hdl", Sweep(1, t0, {{1, {3, 4, 0}}}, 5), t0, 1).ok());
  u = state.BuildUpdate({}, false, t0, points);
  EXPECT_EQ(u.lidars(0).status(), v1::CAMERA_STATUS_LIVE);
  EXPECT_EQ(u.lidars(0).foreground().count(), 5u);
  EXPECT_EQ(u.lidars(0).foreground().packed().size(), 40u);
  EXPECT_EQ(state.BuildUpdate({}, false, t0, points).lidars(0).foreground().count(), 0u);  // already sent
  u = state.BuildUpdate({}, false, t0, plain);
  EXPECT_EQ(u.lidars(0).foreground().count(), 0u);
  EXPECT_EQ(u.lidars(0).tracks_size(), 1);
  // A sweep that carries its own pose moves the LiDAR in the update.
  auto moved = Sweep(2, t0 + 100'000'000, {}, 1);
  *moved->mutable_world_from_sensor() = ToProto(Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d(1, 2, 3)));
  ASSERT_TRUE(state.AcceptLidarSweep("hdl", moved, t0 + 100'000'000, 1).ok());
  u = state.BuildUpdate({}, false, t0 + 100'000'000, points);
  EXPECT_EQ(u.lidars(0).pose().position().x(), 1);
  EXPECT_EQ(u.lidars(0).foreground().count(), 1u);
  // Removed from the registry: listed as removed, like a camera.
  state.RemoveCamera("hdl");
  u = state.BuildUpdate({}, false, t0 + 200'000'000, points);
  EXPECT_EQ(u.lidars_size(), 0);
  EXPECT_THAT(u.removed_camera_ids(), UnorderedElementsAre("hdl"));
}

TEST(LidarFusion, SweepsAndFramesGoOnlyToTheirKindOfSensor) {
  SceneState state;
  CameraEntry camera;
  camera.id = "cam";
  camera.intrinsics = PinholeIntrinsics::FromFov(64, 48, 60);
  state.UpsertCamera(camera);
  state.UpsertCamera(Lidar("hdl", Eigen::Vector3d(0, 0, 2)));
  absl::Status s = state.AcceptLidarSweep("cam", Sweep(1, 1000, {}), 1000);
  EXPECT_EQ(s.code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_THAT(std::string(s.message()), HasSubstr("'cam' is registered as a camera"));
  auto frame = std::make_shared<v1::SensorFrame>();
  frame->set_sequence(1);
  frame->set_capture_time_ns(1000);
  s = state.AcceptFrame("hdl", frame, 1000);
  EXPECT_EQ(s.code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_THAT(std::string(s.message()), HasSubstr("'hdl' is registered as a rotating LiDAR"));
  EXPECT_EQ(state.AcceptLidarSweep("ghost", Sweep(1, 1000, {}), 1000).code(), absl::StatusCode::kNotFound);
}

}  // namespace
}  // namespace ave
