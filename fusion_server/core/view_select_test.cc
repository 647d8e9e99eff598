#include "fusion_server/core/view_select.h"

#include <limits>

#include <gtest/gtest.h>

#include "fusion_server/core/scene_state.h"
#include "fusion_server/core/convert.h"

namespace ave {
namespace {

constexpr double kNoFloor = -std::numeric_limits<double>::infinity();

const PinholeIntrinsics kK = PinholeIntrinsics::FromFov(640, 480, 60);

Eigen::Matrix4d Clip(const Rigid3d& pose, double near_m, double far_m, const PinholeIntrinsics& k = kK) {
  return GlProjection(k, near_m, far_m) * GlViewFromWorld(pose);
}

ConvexVolume Camera(const Eigen::Vector3d& eye, const Eigen::Vector3d& target, double far_m = 100,
                    double floor_z = kNoFloor) {
  return CameraVolume(kK, LookAt(eye, target), 0.5, far_m, floor_z);
}

TEST(ViewSelect, CameraVolumeMatchesItsGlFrustum) {
  const Rigid3d pose = LookAt({3, -4, 12}, {40, 10, 0});
  const ConvexVolume from_camera = CameraVolume(kK, pose, 0.5, 80, kNoFloor);
  absl::StatusOr<ConvexVolume> from_clip = FrustumFromClip(Clip(pose, 0.5, 80), 1e9, kNoFloor);
  ASSERT_TRUE(from_clip.ok()) << from_clip.status();
  ASSERT_EQ(from_camera.vertices.size(), 8u);
  ASSERT_EQ(from_clip->vertices.size(), 8u);
  for (size_t i = 0; i < 8; ++i) {
    EXPECT_LT((from_camera.vertices[i] - from_clip->vertices[i]).norm(), 1e-6 * 80) << "corner " << i;
  }
}

TEST(ViewSelect, OverlappingAndDisjointCameras) {
  const ConvexVolume a = Camera({0, 0, 10}, {30, 0, 0});
  EXPECT_TRUE(VolumesIntersect(a, Camera({30, 30, 10}, {30, 0, 0})));    // both see (30, 0, 0)
  EXPECT_FALSE(VolumesIntersect(a, Camera({-5, 0, 10}, {-60, 0, 0})));   // back to back
  EXPECT_FALSE(VolumesIntersect(a, Camera({0, 500, 10}, {0, 600, 0})));  // far apart
  EXPECT_TRUE(VolumesIntersect(a, a));
}

TEST(ViewSelect, SmallVolumeInsideLargeOneIntersects) {
  const ConvexVolume big = Camera({0, 0, 10}, {50, 0, 0}, 300);
  const ConvexVolume small = CameraVolume(kK, LookAt({60, 0, 8}, {70, 0, 8}), 0.1, 1, kNoFloor);
  EXPECT_TRUE(VolumesIntersect(big, small));
  EXPECT_TRUE(VolumesIntersect(small, big));
}

// Axis-aligned boxes of the two overlap, but the volumes do not: only an edge-cross axis or a
// slanted face separates them.
TEST(ViewSelect, DiagonalNeighboursThatOnlyShareBoundingBoxesAreSeparated) {
  const ConvexVolume a = Camera({0, 0, 5}, {40, 40, 5}, 60);
  // Parallel, 75 m to the right: the fans' inner edges would meet 65 m out, beyond the far plane.
  const ConvexVolume b = Camera({53, -53, 5}, {93, -13, 5}, 60);
  EXPECT_FALSE(VolumesIntersect(a, b));
}

TEST(ViewSelect, FloorCutStopsDownwardCamerasSelectingUnderground) {
  // Two cameras 80 m apart, each looking steeply down at its own block: their uncut frusta meet
  // under the ground, their volumes above the floor (z >= 0) do not.
  const Eigen::Vector3d down_a(0, 0, 15), down_b(80, 0, 15);
  EXPECT_TRUE(VolumesIntersect(Camera(down_a, {5, 0, 0}, 600), Camera(down_b, {75, 0, 0}, 600)));
  EXPECT_FALSE(VolumesIntersect(Camera(down_a, {5, 0, 0}, 600, 0.0), Camera(down_b, {75, 0, 0}, 600, 0.0)));
  // A camera entirely below the floor keeps nothing.
  EXPECT_TRUE(Camera({0, 0, -50}, {10, 0, -60}, 20, 0.0).empty());
  EXPECT_FALSE(VolumesIntersect(Camera({0, 0, -50}, {10, 0, -60}, 20, 0.0), Camera(down_a, {5, 0, 0}, 600, 0.0)));
}

TEST(ViewSelect, CameraStraightDownAndViewAtLargeOffsetAreStable) {
  // Straight down (LookAt's degenerate-up case) and a frustum at 1e6 m: no NaN, and the answer holds.
  const ConvexVolume down = Camera({1e6, 1e6, 30}, {1e6, 1e6, 0}, 100, 0.0);
  ASSERT_FALSE(down.empty());
  for (const auto& p : down.vertices) ASSERT_TRUE(p.allFinite());
  EXPECT_TRUE(VolumesIntersect(down, Camera({1e6 + 40, 1e6, 20}, {1e6, 1e6, 0}, 100, 0.0)));
  EXPECT_FALSE(VolumesIntersect(down, Camera({1e6 + 400, 1e6, 20}, {1e6 + 500, 1e6, 0}, 100, 0.0)));
}

TEST(ViewSelect, FarPlaneClampLimitsAHugeViewFrustum) {
  const Rigid3d view = LookAt({0, 0, 10}, {100, 0, 10});
  const ConvexVolume distant = Camera({5000, 0, 10}, {5100, 0, 10}, 50);
  absl::StatusOr<ConvexVolume> wide = FrustumFromClip(Clip(view, 0.5, 1e5), 1e5, kNoFloor);
  absl::StatusOr<ConvexVolume> clamped = FrustumFromClip(Clip(view, 0.5, 1e5), 2000, kNoFloor);
  ASSERT_TRUE(wide.ok() && clamped.ok());
  EXPECT_TRUE(VolumesIntersect(*wide, distant));
  EXPECT_FALSE(VolumesIntersect(*clamped, distant));
}

TEST(ViewSelect, InfiniteFarPlaneIsClamped) {
  // The limit of GlProjection as far -> infinity: row 2 = (0, 0, -1, -2 near).
  Eigen::Matrix4d proj = GlProjection(kK, 0.5, 1000);
  proj(2, 2) = -1;
  proj(2, 3) = -2 * 0.5;
  const Rigid3d view = LookAt({0, 0, 10}, {100, 0, 10});
  absl::StatusOr<ConvexVolume> v = FrustumFromClip(proj * GlViewFromWorld(view), 300, kNoFloor);
  ASSERT_TRUE(v.ok()) << v.status();
  for (const auto& p : v->vertices) {
    ASSERT_TRUE(p.allFinite());
    EXPECT_LT(p.x(), 300.5);
  }
  EXPECT_GT(v->vertices[4].x(), 200);
}

TEST(ViewSelect, BadMatricesAreRejectedWithAReason) {
  Eigen::Matrix4d nan = Eigen::Matrix4d::Identity();
  nan(0, 1) = std::numeric_limits<double>::quiet_NaN();
  EXPECT_NE(FrustumFromClip(nan, 100, kNoFloor).status().message().find("not finite"), std::string::npos);
  Eigen::Matrix4d singular = Eigen::Matrix4d::Identity();
  singular(2, 2) = 0;
  EXPECT_NE(FrustumFromClip(singular, 100, kNoFloor).status().message().find("singular"), std::string::npos);
  EXPECT_FALSE(FrustumFromClip(Eigen::Matrix4d::Identity(), 0, kNoFloor).ok());
}

// SceneState: JPEGs only for cameras in view, poses for all, and no "skipped" frames counted for
// the time a camera was out of view.
TEST(ViewSelect, SceneStateSendsFramesOnlyForCamerasInView) {
  SceneState state;
  auto add = [&](const std::string& id, const Eigen::Vector3d& eye, const Eigen::Vector3d& target) {
    CameraEntry e;
    e.id = id;
    e.name = id;
    e.intrinsics = PinholeIntrinsics::FromFov(64, 48, 60);
    e.mounting_pose = LookAt(eye, target);
    state.UpsertCamera(e);
  };
  add("near", {0, 0, 15}, {10, 0, 0});
  add("far", {400, 0, 15}, {410, 0, 0});
  auto frame = [&](const std::string& id, uint64_t seq) {
    auto f = std::make_shared<v1::SensorFrame>();
    f->set_sequence(seq);
    f->set_capture_time_ns(int64_t(seq) * 1000);
    f->set_jpeg("jpeg-bytes");
    ASSERT_TRUE(state.AcceptFrame(id, f, 1).ok());
  };
  frame("near", 1);
  frame("far", 1);
  ViewerCursor cursor;
  cursor.selection_floor_z = 0;
  absl::StatusOr<ConvexVolume> view = FrustumFromClip(Clip(LookAt({-20, 0, 40}, {10, 0, 0}), 0.5, 2000), 2000, 0);
  ASSERT_TRUE(view.ok());
  cursor.views = {*view};
  v1::SceneUpdate u = state.BuildUpdate({}, true, 10, cursor);
  ASSERT_EQ(u.cameras_size(), 2);
  EXPECT_EQ(cursor.last_selected, 1u);
  for (const auto& cam : u.cameras()) {
    EXPECT_TRUE(cam.has_pose()) << cam.camera_id();
    EXPECT_EQ(!cam.jpeg().empty(), cam.camera_id() == "near") << cam.camera_id();
  }
  // "far" keeps streaming while out of view, then the view turns to it: its newest frame goes out,
  // and none of the frames it sent meanwhile count as skipped for this viewer.
  for (uint64_t s = 2; s < 6; ++s) {
    frame("far", s);
    state.BuildUpdate({}, true, 10, cursor);
  }
  cursor.views = {*FrustumFromClip(Clip(LookAt({380, 0, 40}, {410, 0, 0}), 0.5, 2000), 2000, 0)};
  frame("far", 6);
  u = state.BuildUpdate({}, true, 10, cursor);
  bool far_sent = false;
  for (const auto& cam : u.cameras()) {
    if (cam.camera_id() != "far") continue;
    far_sent = cam.jpeg() == "jpeg-bytes" && cam.frame_sequence() == 6;
    EXPECT_EQ(cam.frames_skipped(), 0u);
  }
  EXPECT_TRUE(far_sent);
  EXPECT_EQ(cursor.last_skipped, 0u);
}

}  // namespace
}  // namespace ave
