#include "model_store/scene/campus.h"

#include <cmath>

#include <gtest/gtest.h>

#include "model_store/geometry/raycast.h"

namespace ave::scene {
namespace {

TEST(Campus, StaticMeshIsConsistent) {
  const SyntheticCampus campus = BuiltinCampus();
  const TriangleMesh mesh = BuildStaticMesh(campus, 4.0);
  ASSERT_EQ(mesh.positions.size(), mesh.normals.size());
  ASSERT_EQ(mesh.positions.size(), mesh.colors.size());
  ASSERT_EQ(mesh.indices.size() % 3, 0u);
  ASSERT_EQ(mesh.triangle_material.size(), mesh.TriangleCount());
  ASSERT_EQ(mesh.triangle_object.size(), mesh.TriangleCount());
  for (uint32_t i : mesh.indices) ASSERT_LT(i, mesh.positions.size());
  for (const auto& n : mesh.normals) ASSERT_NEAR(n.norm(), 1.0f, 1e-4f);
  EXPECT_EQ(mesh.origin, campus.origin);
}

// A vertical ray onto a building hits its roof at BuildingTop; onto open ground, the terrain.
TEST(Campus, RaysHitRoofsAndTerrainWhereExpected) {
  const SyntheticCampus campus = BuiltinCampus();
  const TriangleMesh mesh = BuildStaticMesh(campus, 2.0);
  const BoxBuilding& b = campus.buildings[0];
  const auto roof = RaycastMesh(mesh, {b.center_m.x(), b.center_m.y(), 200}, {0, 0, -1});
  ASSERT_TRUE(roof.has_value());
  EXPECT_NEAR(200 - roof->distance_m, campus.BuildingTop(b), 1e-3);
  EXPECT_EQ(mesh.triangle_material[roof->triangle], SurfaceMaterial::kRoof);
  // Open ground: the 2 m grid is a linear interpolation of the analytic terrain, within 2 cm.
  ASSERT_EQ(campus.BuildingAt(-107, -110.3), -1);
  const auto ground = RaycastMesh(mesh, {-107, -110.3, 200}, {0, 0, -1});
  ASSERT_TRUE(ground.has_value());
  EXPECT_NEAR(200 - ground->distance_m, campus.TerrainHeight(-107, -110.3), 0.02);
}

TEST(Campus, MoversFollowTheirLoopsAtTheirSpeed) {
  const SyntheticCampus campus = BuiltinCampus();
  const Mover& m = campus.movers[0];
  const MoverState a = MoverAt(campus, m, 0.0), b = MoverAt(campus, m, 1.0);
  EXPECT_NEAR((b.position_m.head<2>() - a.position_m.head<2>()).norm(), m.speed_mps, 1e-9);
  EXPECT_NEAR(a.position_m.z(), campus.TerrainHeight(a.position_m.x(), a.position_m.y()), 1e-12);
  // Negative and very large times stay finite and on the loop.
  for (double t : {-1e3, 1e7}) {
    const MoverState s = MoverAt(campus, m, t);
    EXPECT_TRUE(s.position_m.allFinite());
    EXPECT_NEAR(s.position_m.x(), -6, 1e-6);
  }
}

TEST(Campus, EveryCameraLooksAtGroundInsideTheSite) {
  const SyntheticCampus campus = BuiltinCampus();
  const TriangleMesh mesh = BuildStaticMesh(campus, 4.0);
  ASSERT_EQ(campus.cameras.size(), 3u);
  for (const auto& cam : campus.cameras) {
    EXPECT_EQ(cam.intrinsics.Check(), "") << cam.id;
    const Eigen::Vector3d axis = cam.world_from_camera.rotation * Eigen::Vector3d::UnitZ();
    const auto hit = RaycastMesh(mesh, cam.world_from_camera.translation, axis);
    ASSERT_TRUE(hit.has_value()) << cam.id;
    EXPECT_LT(hit->distance_m, 120) << cam.id;
  }
}

// A walker's heading turns at the path's mean turn rate, smoothly, through each bend and back at each end, centred
// on the bend, while its position stays on the polyline; the first walk starts looking along it.
TEST(Campus, AWalkingCameraTurnsAtItsTurnRateThroughBendsAndEnds) {
  const SyntheticCampus campus = BuiltinCampus();
  CameraSpec cam;
  CameraPath path;
  path.waypoints_m = {{0, 0}, {0, 10}, {10, 10}};  // a left turn of 90 deg, then 180 deg at the end
  path.speed_mps = 1.0;
  path.pitch_deg = 0;
  path.turn_rate_deg_s = 90;
  cam.path = path;
  auto yaw_at = [&](double t) {
    const Eigen::Vector3d f = CameraPoseAt(campus, cam, t).rotation * Eigen::Vector3d::UnitZ();
    return std::atan2(f.y(), f.x());
  };
  EXPECT_NEAR(yaw_at(0), M_PI / 2, 1e-12);   // along the first leg from the start
  EXPECT_NEAR(yaw_at(9.4), M_PI / 2, 1e-12);  // before the bend's turn (half of 1 s)
  EXPECT_NEAR(yaw_at(10), M_PI / 4, 1e-12);   // half turned at the bend
  EXPECT_NEAR(yaw_at(10.6), 0, 1e-12);        // along the second leg after it
  EXPECT_NEAR(yaw_at(20), M_PI / 2, 1e-12);   // the 180 deg turn back, half done at the end (left)
  EXPECT_NEAR(std::abs(yaw_at(21.1)), M_PI, 1e-12);  // walking back
  const double rate = 90 * M_PI / 180, dt = 1e-3;
  double most = 0;
  Eigen::Quaterniond before = CameraPoseAt(campus, cam, 0).rotation;
  for (double t = dt; t < 45; t += dt) {  // past the start of the second walk (a turn now)
    const Rigid3d pose = CameraPoseAt(campus, cam, t);
    most = std::max(most, before.angularDistance(pose.rotation) / dt);
    before = pose.rotation;
    // The position is on the polyline, walked at the speed.
    const double s = std::fmod(t, 40.0), along = s < 20 ? s : 40 - s;
    const Eigen::Vector2d expected = along < 10 ? Eigen::Vector2d(0, along) : Eigen::Vector2d(along - 10, 10);
    ASSERT_LT((pose.translation.head<2>() - expected).norm(), 1e-9) << "t " << t;
  }
  EXPECT_LT(most, 1.5 * rate * 1.001);  // a smoothstep's peak: 1.5 times the mean rate
  EXPECT_GT(most, 1.5 * rate * 0.95);
  EXPECT_NEAR(yaw_at(40), 0, 1e-9);  // half way through turning back (left, from south to north) at the start
  // Hard cases: far and negative times, a repeated waypoint (a zero-length leg), a U-turn in the
  // middle of the path, a tiny and a huge turn rate: every pose finite and unit.
  for (double t : {-1e3, 1e7, 1e12}) {
    const Rigid3d pose = CameraPoseAt(campus, cam, t);
    EXPECT_TRUE(pose.translation.allFinite() && pose.rotation.coeffs().allFinite()) << t;
    EXPECT_NEAR(pose.rotation.norm(), 1, 1e-9) << t;
  }
  for (const std::vector<Eigen::Vector2d>& waypoints : std::vector<std::vector<Eigen::Vector2d>>{
           {{0, 0}, {0, 10}, {0, 10}, {10, 10}}, {{0, 0}, {0, 10}, {0, 2}}, {{0, 0}, {0, 1e-9}, {5, 5}}}) {
    for (double rate : {1e-3, 90.0, 36000.0}) {
      CameraSpec odd = cam;
      odd.path->waypoints_m = waypoints;
      odd.path->turn_rate_deg_s = rate;
      for (double t = 0; t < 60; t += 0.05) {
        const Rigid3d pose = CameraPoseAt(campus, odd, t);
        ASSERT_TRUE(pose.translation.allFinite() && pose.rotation.coeffs().allFinite()) << t << " rate " << rate;
        ASSERT_NEAR(pose.rotation.norm(), 1, 1e-9) << t;
      }
    }
  }
}

}  // namespace
}  // namespace ave::scene
