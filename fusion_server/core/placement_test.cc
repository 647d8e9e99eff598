// Ground-contact placement and cross-camera fusion (issue 6): the campus terrain against its
// analytic heights, the hard cases (grazing, sky, off the model, border boxes) and fusion ids.
#include "fusion_server/core/placement.h"

#include <cmath>
#include <memory>
#include <set>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "fusion_server/core/convert.h"
#include "fusion_server/core/objects.h"
#include "fusion_server/core/scene_state.h"
#include "model_store/scene/campus.h"

namespace ave {
namespace {

const scene::SyntheticCampus& Campus() {
  static const scene::SyntheticCampus campus = scene::BuiltinCampus();
  return campus;
}

const TerrainModel& Ground() {
  static const TerrainModel terrain(scene::BuildStaticMesh(Campus(), 2.0));
  return terrain;
}

// The wire box whose bottom-middle pixel centre is the projection of `p_in_world`.
std::array<double, 4> BoxAbove(const PinholeIntrinsics& k, const Rigid3d& world_from_camera,
                               const Eigen::Vector3d& p_in_world, double w_px = 10, double h_px = 30) {
  const std::optional<Eigen::Vector2d> uv = ProjectToPixel(k, world_from_camera.Inverse() * p_in_world);
  EXPECT_TRUE(uv.has_value());
  const double u = uv->x() + 0.5, v = uv->y() + 0.5;
  return {u - w_px / 2, v - h_px, u + w_px / 2, v};
}

TEST(TerrainModel, KeepsOnlyGroundTriangles) {
  const TriangleMesh mesh = scene::BuildStaticMesh(Campus(), 2.0);
  EXPECT_LT(Ground().TriangleCount(), mesh.TriangleCount());
  EXPECT_GT(Ground().TriangleCount(), 10000u);
}

TEST(PlaceBox, ContactLandsOnTheHillyTerrainNotAPlane) {
  const scene::CameraSpec& cam = *Campus().FindCamera("cam1");
  for (const Eigen::Vector2d& xy : {Eigen::Vector2d(-3, -30), Eigen::Vector2d(10, -20), Eigen::Vector2d(-20, -40)}) {
    const Eigen::Vector3d truth(xy.x(), xy.y(), Campus().TerrainHeight(xy.x(), xy.y()));
    std::string why;
    const auto placed = PlaceBox(Ground(), cam.intrinsics, cam.world_from_camera, nullptr,
                                 BoxAbove(cam.intrinsics, cam.world_from_camera, truth), {}, &why);
    ASSERT_TRUE(placed) << why;
    // 2 m terrain facets stay within a few cm of the analytic hills.
    EXPECT_LT((placed->position - truth).norm(), 0.08) << xy.transpose();
    EXPECT_TRUE(placed->covariance_xy.allFinite());
    EXPECT_GT(placed->covariance_xy.determinant(), 0);
    EXPECT_NEAR(placed->range_m, (truth - cam.world_from_camera.translation).norm(), 0.1);
    EXPECT_NEAR(placed->size_m.z(), 30 * (cam.world_from_camera.Inverse() * truth).z() / cam.intrinsics.fy, 0.05);
  }
}

TEST(PlaceBox, UncertaintyGrowsWithThePoseCovarianceAndRange) {
  const scene::CameraSpec& cam = *Campus().FindCamera("cam1");
  const Eigen::Vector3d near(-3, -40, Campus().TerrainHeight(-3, -40)), far(5, 20, Campus().TerrainHeight(5, 20));
  Eigen::Matrix<double, 6, 6> small = Eigen::Matrix<double, 6, 6>::Identity() * 1e-6;
  Eigen::Matrix<double, 6, 6> large = small;
  large.block<3, 3>(3, 3) *= 100;  // 1 mrad -> 10 mrad
  const auto a = PlaceBox(Ground(), cam.intrinsics, cam.world_from_camera, &small,
                          BoxAbove(cam.intrinsics, cam.world_from_camera, near));
  const auto b = PlaceBox(Ground(), cam.intrinsics, cam.world_from_camera, &large,
                          BoxAbove(cam.intrinsics, cam.world_from_camera, near));
  const auto c = PlaceBox(Ground(), cam.intrinsics, cam.world_from_camera, &large,
                          BoxAbove(cam.intrinsics, cam.world_from_camera, far));
  ASSERT_TRUE(a && b && c);
  EXPECT_GT(b->covariance_xy.trace(), 4 * a->covariance_xy.trace());
  EXPECT_GT(c->covariance_xy.trace(), b->covariance_xy.trace());
  // 10 mrad at ~40 m slant: on the order of decimetres, not metres.
  EXPECT_LT(std::sqrt(b->covariance_xy.trace()), 3.0);
}

// A camera 1.7 m above the ground looking level (a backpack camera).
Rigid3d LevelCamera(const Eigen::Vector2d& xy, const Eigen::Vector2d& towards) {
  const Eigen::Vector3d eye(xy.x(), xy.y(), Campus().TerrainHeight(xy.x(), xy.y()) + 1.7);
  const Eigen::Vector3d target(towards.x(), towards.y(), eye.z());
  return LookAt(eye, target);
}

TEST(PlaceBox, GrazingRayIsRefusedWithoutNaN) {
  const PinholeIntrinsics k = PinholeIntrinsics::FromFov(640, 480, 60);
  const Rigid3d pose = LevelCamera({0, -60}, {0, 60});
  // Pixel rows just under the horizon: the ray dips by atan((v - cy) / fy).
  std::string why;
  const double dip_small = std::tan(0.3 * M_PI / 180) * k.fy;  // 0.3 deg below level
  const auto grazing = PlaceBox(Ground(), k, pose, nullptr, {310, 200, 330, k.cy + 0.5 + dip_small}, {}, &why);
  EXPECT_FALSE(grazing.has_value());
  EXPECT_THAT(why, testing::AnyOf(testing::HasSubstr("grazes"), testing::HasSubstr("no ground")));
  const double dip = std::tan(4.0 * M_PI / 180) * k.fy;  // 4 deg: ~25 m ahead
  const auto steep = PlaceBox(Ground(), k, pose, nullptr, {310, 200, 330, k.cy + 0.5 + dip}, {}, &why);
  ASSERT_TRUE(steep) << why;
  EXPECT_TRUE(steep->position.allFinite());
  EXPECT_TRUE(steep->covariance_xy.allFinite());
  EXPECT_NEAR(steep->range_m, 1.7 / std::sin(4.0 * M_PI / 180), 8.0);
}

TEST(PlaceBox, SkyAndOffTheModelGiveNoObject) {
  const PinholeIntrinsics k = PinholeIntrinsics::FromFov(640, 480, 60);
  std::string why;
  // Above the horizon.
  EXPECT_FALSE(PlaceBox(Ground(), k, LevelCamera({0, -60}, {0, 60}), nullptr, {300, 10, 340, 100}, {}, &why));
  EXPECT_THAT(why, testing::HasSubstr("no ground"));
  // At the model's edge looking outwards and down: the ground ends 5 m ahead.
  const Rigid3d edge = LookAt(Eigen::Vector3d(0, 115, 30), Eigen::Vector3d(0, 160, 0));
  why.clear();
  EXPECT_FALSE(PlaceBox(Ground(), k, edge, nullptr, {300, 200, 340, 250}, {}, &why));
  EXPECT_THAT(why, testing::HasSubstr("no ground"));
  // Non-finite inputs.
  EXPECT_FALSE(PlaceBox(Ground(), k, edge, nullptr, {NAN, 0, 1, 1}));
}

TEST(PlaceBox, BoxOnTheImageBorderStillPlaces) {
  const scene::CameraSpec& cam = *Campus().FindCamera("cam1");
  const PinholeIntrinsics& k = cam.intrinsics;
  // A box clipped by the bottom-left corner of the image.
  const auto placed = PlaceBox(Ground(), k, cam.world_from_camera, nullptr, {0, k.height - 40.0, 12, double(k.height)});
  ASSERT_TRUE(placed);
  EXPECT_TRUE(placed->position.allFinite());
}

// Issue 6: a person cut by a building in front has the box's bottom edge on the wall. Cast into
// the ground only, the contact lands behind the building; with the walls as occluders it is
// refused with a reason.
TEST(PlaceBox, BottomEdgeOnAWallIsRefusedNotPlacedBehindIt) {
  const scene::SyntheticCampus& campus = Campus();
  const PinholeIntrinsics k = PinholeIntrinsics::FromFov(640, 480, 60);
  const double edge = campus.half_extent_m - 5;
  for (const scene::BoxBuilding& b : campus.buildings) {
    if (b.height_m < 4) continue;
    const double r = 0.5 * b.size_m.norm();  // the main part's footprint lies within r of its centre
    const Eigen::Vector2d eye_xy = b.center_m - Eigen::Vector2d(r + 15, 0);
    const Eigen::Vector2d behind_xy = b.center_m + Eigen::Vector2d(r + 4, 0);
    if (campus.BuildingAt(eye_xy.x(), eye_xy.y()) >= 0 || campus.BuildingAt(behind_xy.x(), behind_xy.y()) >= 0 ||
        eye_xy.cwiseAbs().maxCoeff() > edge || behind_xy.cwiseAbs().maxCoeff() > edge) {
      continue;
    }
    const Eigen::Vector3d eye(eye_xy.x(), eye_xy.y(), campus.TerrainHeight(eye_xy.x(), eye_xy.y()) + 2);
    const Eigen::Vector3d behind(behind_xy.x(), behind_xy.y(), campus.TerrainHeight(behind_xy.x(), behind_xy.y()));
    const Rigid3d pose = LookAt(eye, behind);
    const auto box = BoxAbove(k, pose, behind);
    TriangleMesh no_walls = scene::BuildStaticMesh(campus, 2.0);
    for (SurfaceMaterial& m : no_walls.triangle_material) {
      if (m == SurfaceMaterial::kWall || m == SurfaceMaterial::kRoof) m = SurfaceMaterial::kObject;
    }
    const TerrainModel ground_only(no_walls);
    EXPECT_EQ(ground_only.OccluderTriangleCount(), 0u);
    const auto behind_wall = PlaceBox(ground_only, k, pose, nullptr, box);
    ASSERT_TRUE(behind_wall) << b.id;  // the old behaviour: a contact behind the building
    EXPECT_LT((behind_wall->position - behind).norm(), 0.1);
    EXPECT_GT(Ground().OccluderTriangleCount(), 0u);
    std::string why;
    EXPECT_FALSE(PlaceBox(Ground(), k, pose, nullptr, box, {}, &why)) << b.id;
    EXPECT_THAT(why, testing::HasSubstr("building"));
    // The same camera still places a contact in front of the building.
    const Eigen::Vector2d front_xy = eye_xy + Eigen::Vector2d(8, 0);
    const Eigen::Vector3d front(front_xy.x(), front_xy.y(), campus.TerrainHeight(front_xy.x(), front_xy.y()));
    EXPECT_TRUE(PlaceBox(Ground(), k, pose, nullptr, BoxAbove(k, pose, front), {}, &why)) << why;
    return;
  }
  FAIL() << "no campus building with free ground on both sides along x";
}

TEST(UndistortedRay, InvertsBrownConrady) {
  PinholeIntrinsics k = PinholeIntrinsics::FromFov(640, 480, 70);
  k.distortion = {-0.12, 0.03, 0.001, -0.0005, 0.0};
  for (const Eigen::Vector2d& xy : {Eigen::Vector2d(0.3, -0.2), Eigen::Vector2d(-0.5, 0.35), Eigen::Vector2d(0, 0)}) {
    const double x = xy.x(), y = xy.y(), r2 = x * x + y * y;
    const auto& d = k.distortion;
    const double radial = 1 + d[0] * r2 + d[1] * r2 * r2 + d[4] * r2 * r2 * r2;
    const double xd = x * radial + 2 * d[2] * x * y + d[3] * (r2 + 2 * x * x);
    const double yd = y * radial + d[2] * (r2 + 2 * y * y) + 2 * d[3] * x * y;
    const Eigen::Vector3d ray = UndistortedRay(k, {k.cx + k.fx * xd, k.cy + k.fy * yd});
    EXPECT_NEAR(ray.x() / ray.z(), x, 1e-9);
    EXPECT_NEAR(ray.y() / ray.z(), y, 1e-9);
  }
}

Placement At(double x, double y, double sigma = 0.2) {
  Placement p;
  p.position = Eigen::Vector3d(x, y, 0);
  p.covariance_xy = Eigen::Matrix2d::Identity() * sigma * sigma;
  p.size_m = Eigen::Vector3d(0.6, 0.6, 1.8);
  p.kind = ObjectKind::kPerson;
  return p;
}

TEST(ObjectFusion, TwoCamerasOneObjectOneId) {
  ObjectFusion fusion;
  std::set<uint64_t> ids;
  for (int f = 0; f < 30; ++f) {
    const int64_t t = f * 100'000'000LL;
    const double x = 1.4 * f * 0.1;
    ids.insert(fusion.Observe({"camA", 7, t, At(x + 0.15, 0.1)}));
    ids.insert(fusion.Observe({"camB", 3, t + 1000, At(x - 0.1, -0.12)}));
    fusion.Expire(t);
  }
  EXPECT_EQ(ids.size(), 1u);
  const auto live = fusion.Live(29 * 100'000'000LL);
  ASSERT_EQ(live.size(), 1u);
  EXPECT_EQ(live[0]->cameras.size(), 2u);
  EXPECT_NEAR(live[0]->heading_rad, 0.0, 0.2);  // walking east
  EXPECT_NEAR(live[0]->position.x(), 1.4 * 2.9, 0.5);
  EXPECT_GE(live[0]->path.size(), 10u);
}

TEST(ObjectFusion, SeparateObjectsKeepSeparateIdsAndPathsAreBounded) {
  ObjectOptions o;
  o.max_path = 8;
  ObjectFusion fusion(o);
  uint64_t a = 0, b = 0;
  for (int f = 0; f < 100; ++f) {
    const int64_t t = f * 100'000'000LL;
    const uint64_t ia = fusion.Observe({"camA", 1, t, At(0, 0.5 * f * 0.1)});
    const uint64_t ib = fusion.Observe({"camA", 2, t, At(10, -0.5 * f * 0.1)});
    if (f == 0) a = ia, b = ib;
    EXPECT_EQ(ia, a);
    EXPECT_EQ(ib, b);
  }
  EXPECT_NE(a, b);
  for (const FusedObject* obj : fusion.Live(99 * 100'000'000LL)) EXPECT_LE(obj->path.size(), 8u);
  // Both vanish after forget_s.
  fusion.Expire(99 * 100'000'000LL + 3'000'000'000LL);
  EXPECT_EQ(fusion.size(), 0u);
}

// Issue 6: a restarted agent numbers its tracks from 1 again; its new stream session must not
// continue the object its previous session's track 1 left behind.
TEST(ObjectFusion, NewStreamSessionDoesNotInheritTheOldSessionsTrack) {
  ObjectFusion fusion;
  const uint64_t old_object = fusion.Observe({"camA", 1, 0, At(0, 0), /*session=*/1});
  EXPECT_EQ(fusion.Observe({"camA", 1, 100'000'000, At(0.1, 0), /*session=*/1}), old_object);
  // The restarted agent's track 1 is someone else, 2 m away (inside the association gate).
  const uint64_t new_object = fusion.Observe({"camA", 1, 500'000'000, At(2, 0), /*session=*/2});
  EXPECT_NE(new_object, old_object);
  EXPECT_EQ(fusion.Observe({"camA", 1, 600'000'000, At(2.1, 0), /*session=*/2}), new_object);
  // The old object is left to expire; the new one keeps its id.
  fusion.Expire(2'300'000'000);
  ASSERT_EQ(fusion.size(), 1u);
  EXPECT_EQ(fusion.Live(2'300'000'000)[0]->id, new_object);
  EXPECT_EQ(fusion.Observe({"camA", 1, 2'300'000'000, At(2.2, 0), /*session=*/2}), new_object);
}

// The merge step only compares objects closer than the gate along the wider ground axis (a
// sweep): among 400 objects 3 m apart none merge, while two objects of two cameras that walk
// together 50 m away merge, the older id stays, and the newer object's track is re-tied to it.
// Laid out along x and along y.
TEST(ObjectFusion, MergeSweepAmongManyObjectsJoinsOnlyTheClosePair) {
  for (const bool along_y : {false, true}) {
    SCOPED_TRACE(along_y ? "along y" : "along x");
    auto at = [&](double along, double across) { return along_y ? At(across, along) : At(along, across); };
    ObjectFusion fusion;
    for (int i = 0; i < 400; ++i) fusion.Observe({"cam" + std::to_string(i), 1, 0, at(3.0 * ((i * 7919) % 400), 0)});
    const uint64_t a = fusion.Observe({"camA", 1, 0, at(371.5, 50)});
    const uint64_t b = fusion.Observe({"camB", 1, 0, at(381.5, 50)});
    fusion.Expire(0);
    EXPECT_EQ(fusion.size(), 402u);
    EXPECT_NE(a, b);
    int64_t t = 0;
    for (int f = 1; f <= 10; ++f) {  // camB's track walks over to camA's object
      t = f * 10'000'000LL;
      EXPECT_EQ(fusion.Observe({"camA", 1, t, at(371.5, 50)}), a);
      EXPECT_EQ(fusion.Observe({"camB", 1, t, at(371.7, 50)}), b);
    }
    fusion.Expire(t);
    EXPECT_EQ(fusion.size(), 401u);
    EXPECT_EQ(fusion.Observe({"camB", 1, t + 10'000'000, at(371.7, 50)}), a);
    EXPECT_EQ(fusion.Observe({"camA", 1, t + 10'000'000, at(371.5, 50)}), a);
  }
}

TEST(ObjectFusion, LateSecondCameraMergesIntoTheExistingObject) {
  ObjectFusion fusion;
  // Both cameras start separate objects in the same instant (neither saw the other): the merge
  // step joins them and the older id stays.
  const uint64_t a = fusion.Observe({"camA", 1, 0, At(5, 5)});
  fusion.Observe({"camB", 9, 0, At(5.3, 4.9)});
  fusion.Expire(0);
  ASSERT_EQ(fusion.size(), 1u);
  EXPECT_EQ(fusion.Observe({"camB", 9, 100'000'000, At(5.2, 5.0)}), a);
}

}  // namespace
}  // namespace ave

namespace ave {
namespace {

// A frame of camera `c` at capture time t_ns with one box (track `track`) standing on `truth`.
std::shared_ptr<v1::SensorFrame> BoxFrame(const scene::CameraSpec& c, const Eigen::Vector3d& truth, int64_t t_ns,
                                          uint64_t sequence, uint32_t track) {
  const auto b = BoxAbove(c.intrinsics, c.world_from_camera, truth, 8, 20);
  auto frame = std::make_shared<v1::SensorFrame>();
  frame->set_capture_time_ns(t_ns);
  frame->set_sequence(sequence);
  *frame->mutable_pose() = ToProto(c.world_from_camera);
  v1::DetectedBox* box = frame->add_boxes();
  box->set_track_id(track);
  box->set_score(0.9f);
  for (const auto& [u, v] : {std::pair{b[0], b[1]}, {b[2], b[1]}, {b[2], b[3]}, {b[0], b[3]}}) {
    v1::Point2* p = box->add_corners();
    p->set_x(static_cast<float>(u));
    p->set_y(static_cast<float>(v));
  }
  return frame;
}

// The server core end to end: boxes of two cameras on the same walker become one object in the
// scene update, with its model, covariance, path and both camera ids.
TEST(SceneStateObjects, BoxesFromTwoCamerasBecomeOnePlacedObject) {
  SceneState state;
  state.SetStaticModel(scene::BuildStaticMesh(Campus(), 2.0));
  for (const char* id : {"cam1", "cam3"}) {
    const scene::CameraSpec& c = *Campus().FindCamera(id);
    state.UpsertCamera({c.id, c.name, c.intrinsics, c.world_from_camera, "", true});
  }
  const int64_t t0 = 1'000'000'000'000;
  for (int f = 0; f < 20; ++f) {
    const double x = -2 + 0.14 * f, y = -5;  // walking east at 1.4 m/s, 10 fps
    const Eigen::Vector3d truth(x, y, Campus().TerrainHeight(x, y));
    for (const char* id : {"cam1", "cam3"}) {
      const scene::CameraSpec& c = *Campus().FindCamera(id);
      auto frame = BoxFrame(c, truth, t0 + f * 100'000'000LL, f + 1, std::string(id) == "cam1" ? 4 : 11);
      ASSERT_TRUE(state.AcceptFrame(id, frame, frame->capture_time_ns()).ok());
    }
  }
  ViewerCursor cursor;
  const v1::SceneUpdate update = state.BuildUpdate({}, false, t0 + 2'000'000'000LL, cursor);
  ASSERT_EQ(update.objects_size(), 1);
  const v1::DynamicObject& o = update.objects(0);
  EXPECT_NEAR(o.position().x(), -2 + 0.14 * 19, 0.3);
  EXPECT_NEAR(o.position().y(), -5, 0.3);
  EXPECT_EQ(o.camera_ids_size(), 2);
  EXPECT_EQ(o.position_covariance_size(), 3);
  EXPECT_GT(o.position_covariance(0), 0);
  EXPECT_GE(o.path_size(), 5);
  EXPECT_NE(o.model(), v1::OBJECT_MODEL_UNSPECIFIED);
  EXPECT_NEAR(o.heading_rad(), 0.0, 0.3);
  // Long after the last frame the object is gone from updates.
  EXPECT_EQ(state.BuildUpdate({}, false, t0 + 60'000'000'000LL, cursor).objects_size(), 0);
}

// Issue 6: an agent that has not measured its clock offset (0 on the wire) may run on a clock hours
// away from the server's: its objects are timed by the server's receipt, so they neither expire at
// once nor linger; with an offset the capture time on the server clock is used.
TEST(SceneStateObjects, UnknownClockOffsetTimesObjectsByReceipt) {
  SceneState state;
  state.SetStaticModel(scene::BuildStaticMesh(Campus(), 2.0));
  const scene::CameraSpec& c = *Campus().FindCamera("cam1");
  state.UpsertCamera({c.id, c.name, c.intrinsics, c.world_from_camera, "", true});
  const uint64_t session = state.StreamOpened(c.id, c.intrinsics);
  EXPECT_GT(session, 0u);
  const Eigen::Vector3d truth(-2, -5, Campus().TerrainHeight(-2, -5));
  const int64_t server_now = 5'000'000'000'000;
  const int64_t agent_clock = server_now - 3'600'000'000'000;  // an hour behind
  auto unknown = BoxFrame(c, truth, agent_clock, 1, 1);
  ASSERT_TRUE(state.AcceptFrame(c.id, unknown, server_now, session).ok());
  ViewerCursor cursor;
  EXPECT_EQ(state.BuildUpdate({}, false, server_now + 500'000'000, cursor).objects_size(), 1);
  EXPECT_EQ(state.BuildUpdate({}, false, server_now + 10'000'000'000, cursor).objects_size(), 0);
  // With the offset known, the capture time is used: a frame captured 1.5 s before its receipt
  // leaves an object that is gone 1 s after the receipt (forget_s = 2).
  auto known = BoxFrame(c, truth, agent_clock + 20'000'000'000, 2, 1);
  known->set_clock_offset_ns(server_now - agent_clock - 1'500'000'000);
  ASSERT_TRUE(state.AcceptFrame(c.id, known, server_now + 20'000'000'000, session).ok());
  EXPECT_EQ(state.BuildUpdate({}, false, server_now + 20'000'000'000, cursor).objects_size(), 1);
  EXPECT_EQ(state.BuildUpdate({}, false, server_now + 21'000'000'000, cursor).objects_size(), 0);
}

// Issue 6: the stream session reaches the fusion through AcceptFrame: a reconnected agent's track 1
// starts a new object.
TEST(SceneStateObjects, ReconnectedStreamStartsNewObjects) {
  SceneState state;
  state.SetStaticModel(scene::BuildStaticMesh(Campus(), 2.0));
  const scene::CameraSpec& c = *Campus().FindCamera("cam1");
  state.UpsertCamera({c.id, c.name, c.intrinsics, c.world_from_camera, "", true});
  const Eigen::Vector3d truth(-2, -5, Campus().TerrainHeight(-2, -5));
  const int64_t t0 = 1'000'000'000'000;
  const uint64_t first = state.StreamOpened(c.id, c.intrinsics);
  ASSERT_TRUE(state.AcceptFrame(c.id, BoxFrame(c, truth, t0, 1, 1), t0, first).ok());
  state.StreamClosed(c.id);
  const uint64_t second = state.StreamOpened(c.id, c.intrinsics);
  EXPECT_NE(first, second);
  ASSERT_TRUE(state.AcceptFrame(c.id, BoxFrame(c, truth, t0 + 300'000'000, 1, 1), t0 + 300'000'000, second).ok());
  ViewerCursor cursor;
  const v1::SceneUpdate update = state.BuildUpdate({}, false, t0 + 400'000'000, cursor);
  ASSERT_EQ(update.objects_size(), 2);
  EXPECT_NE(update.objects(0).object_id(), update.objects(1).object_id());
}

}  // namespace
}  // namespace ave
