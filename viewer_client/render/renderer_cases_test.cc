// Issue 7: sky, hard cases (projector inside a building, looking down, near plane, coplanar wall,
// far world coordinates, NaN poses), retention, overlap policies, model shapes, linear depth.
#include "viewer_client/render/render_test_scene.h"

namespace ave::viewer {
namespace {

using namespace ::ave::viewer::render_test;  // NOLINT: the shared scene and helpers of the render tests

// Sky: imagery above the horizon lands on the dome; with the sky off it is the clear colour.
TEST_F(SceneTest, Sky_ReceivesImageryAboveTheHorizon) {
  const Camera up{PinholeIntrinsics::FromFov(640, 480, 70), LookAt({-18, 0, 3}, {0, 0, 10})};
  ReplaceProjector(MakeProjector(up, image_, 1));
  const Eigen::Vector2d top_left(40, 30), top_right(600, 30);
  for (const Eigen::Vector2d& uv : {top_left, top_right}) {
    ASSERT_FALSE(RaycastMesh(mesh_, up.world_from_camera.translation, up.world_from_camera.rotation * PixelRay(up.intrinsics, uv)))
        << "test setup: sky at " << uv.transpose();
  }
  const std::vector<uint8_t> with_sky = RenderFrom(up);
  EXPECT_TRUE(Near(PixelAt(with_sky, kWidth, 40, 30), QuadrantColor(40, 30, 640, 480)));
  EXPECT_TRUE(Near(PixelAt(with_sky, kWidth, 600, 30), QuadrantColor(600, 30, 640, 480)));
  DisplayOptions display;
  display.sky = false;
  ASSERT_TRUE(renderer_->SetDisplayOptions(display).ok());
  const std::vector<uint8_t> without = RenderFrom(up);
  EXPECT_TRUE(Near(PixelAt(without, kWidth, 40, 30), ToRgb255(View().clear_color)));
}

// Hard case: a projector inside the building lights only the inside of its walls.
TEST_F(SceneTest, HardCase_ProjectorInsideBuildingLeaksNothing) {
  const Camera inside{PinholeIntrinsics::FromFov(640, 480, 100), LookAt({0, 0, 4}, {10, 0, 0})};
  ReplaceProjector(MakeProjector(inside, image_, 1));
  const std::vector<uint8_t> rgba = RenderViewer();
  for (const Eigen::Vector3d& p : {Eigen::Vector3d(6, 0, 0), Eigen::Vector3d(9, 3, 0), Eigen::Vector3d(12, -2, 0)}) {
    ASSERT_TRUE(inside.Pixel(p) && inside.InImage(*inside.Pixel(p), 2)) << "test setup: in the frustum " << p.transpose();
    EXPECT_TRUE(Near(ViewerPixel(rgba, p), ShadedGround())) << p.transpose() << ": " << Str(ViewerPixel(rgba, p));
  }
  // The outside of the wall it looks through keeps the wall's colour.
  const Eigen::Vector3d wall(3.0, 0.5, 2.5);
  const Camera east{PinholeIntrinsics::FromFov(kWidth, kHeight, 70), LookAt({20, 4, 6}, {3, 0, 2})};
  const std::vector<uint8_t> from_east = RenderFrom(east);
  const Eigen::Vector3i expected = ToRgb255(ShadedModelColor(renderer_->options(), {0.7f, 0.7f, 0.7f}, Eigen::Vector3f::UnitX()));
  EXPECT_TRUE(Near(PixelSeenBy(east, from_east, wall + Eigen::Vector3d(0.01, 0, 0)), expected));
}

// Hard case: looking straight down (LookAt's degenerate up); the ground shows the right quadrants.
TEST_F(SceneTest, HardCase_ProjectorLookingStraightDown) {
  const Camera down{PinholeIntrinsics::FromFov(640, 480, 60), LookAt({-10, 8, 15}, {-10, 8, 0})};
  ReplaceProjector(MakeProjector(down, image_, 1));
  const std::vector<uint8_t> rgba = RenderViewer();
  int checked = 0;
  for (const Eigen::Vector3d& p : {Eigen::Vector3d(-14, 11, 0), Eigen::Vector3d(-6, 11, 0), Eigen::Vector3d(-14, 5, 0),
                                  Eigen::Vector3d(-6, 5, 0)}) {
    const std::optional<Eigen::Vector2d> uv = down.Pixel(p);
    ASSERT_TRUE(uv && down.InImage(*uv, 12)) << p.transpose();
    EXPECT_TRUE(Near(ViewerPixel(rgba, p), QuadrantColor(uv->x(), uv->y(), 640, 480))) << p.transpose();
    ++checked;
  }
  EXPECT_EQ(checked, 4);
}

// Hard case: the near plane cuts the terrain (projector 0.3 m above the ground, near 0.5 m; the
// viewer's own near plane also cuts it): ground nearer than the near plane gets no video, ground
// beyond it the right colour.
TEST_F(SceneTest, HardCase_NearPlaneCutsTerrain) {
  const Camera low{PinholeIntrinsics::FromFov(640, 480, 90), LookAt({-15, -15, 0.3}, {-5, -15, -2})};
  ReplaceProjector(MakeProjector(low, image_, 1));
  const std::vector<uint8_t> rgba = RenderViewer();
  const Eigen::Vector3d beyond(-10, -15.5, 0);
  const std::optional<Eigen::Vector2d> uv = low.Pixel(beyond);
  ASSERT_TRUE(uv && low.InImage(*uv, 10));
  EXPECT_TRUE(Near(ViewerPixel(rgba, beyond), QuadrantColor(uv->x(), uv->y(), 640, 480)));
  const Eigen::Vector3d too_near(-14.85, -15, 0);  // 0.15 m ahead: within the near plane
  ASSERT_LT((low.world_from_camera.Inverse() * too_near).z(), 0.5);
  EXPECT_TRUE(Near(ViewerPixel(rgba, too_near), ShadedGround()));
  // A viewer whose near plane (0.5 m) cuts the ground right under it still draws the ground ahead.
  const Camera skimming{PinholeIntrinsics::FromFov(kWidth, kHeight, 90), LookAt({-10, -18, 0.2}, {-10, -10, 0})};
  const std::vector<uint8_t> low_view = RenderFrom(skimming);
  const Eigen::Vector3d ahead(-10, -15.5, 0);
  const Eigen::Vector3i got = PixelSeenBy(skimming, low_view, ahead);
  EXPECT_TRUE(Near(got, QuadrantColor(uv->x(), uv->y(), 640, 480), 2 * kTolerance)) << Str(got);
}

// Hard case: the projector lies exactly in the plane of a wall (grazing): the wall keeps its own
// colour, the ground beside it is textured, and nothing is NaN (the frame is finite and stable).
TEST_F(SceneTest, HardCase_ProjectorCoplanarWithWall) {
  const Camera coplanar{PinholeIntrinsics::FromFov(640, 480, 70), LookAt({-3, -16, 4}, {-3, 0, 4})};
  ReplaceProjector(MakeProjector(coplanar, image_, 1));
  const Camera west{PinholeIntrinsics::FromFov(kWidth, kHeight, 70), LookAt({-20, -4, 8}, {-3, 0, 3})};
  const std::vector<uint8_t> rgba = RenderFrom(west);
  const Eigen::Vector3i wall = ToRgb255(ShadedModelColor(renderer_->options(), {0.7f, 0.7f, 0.7f}, -Eigen::Vector3f::UnitX()));
  for (const Eigen::Vector3d& on_wall : {Eigen::Vector3d(-3.01, -1, 4), Eigen::Vector3d(-3.01, 1.5, 2)}) {
    const Eigen::Vector3i seen = PixelSeenBy(west, rgba, on_wall);
    EXPECT_TRUE(Near(seen, wall)) << "at " << on_wall.transpose() << ": " << Str(seen) << ", the wall " << Str(wall);
  }
  const Eigen::Vector3d ground(-7, -4, 0);
  const std::optional<Eigen::Vector2d> uv = coplanar.Pixel(ground);
  ASSERT_TRUE(uv && coplanar.InImage(*uv, 10));
  EXPECT_TRUE(Near(PixelSeenBy(west, rgba, ground), QuadrantColor(uv->x(), uv->y(), 640, 480)));
  EXPECT_TRUE(rgba == RenderFrom(west));
}

// Hard case: the site at 1e6 m world coordinates. Poses are made local in double (world minus
// origin) before anything becomes float, so the picture matches the one at the origin, and a 1 cm
// camera move still moves the picture (float world coordinates there would snap to 6 cm steps).
TEST_F(SceneTest, HardCase_FarWorldCoordinatesRenderWithoutJitter) {
  const Eigen::Vector3d origin(1.0e6, 2.0e6, 150.0);
  auto local_camera = [&](const Eigen::Vector3d& eye_world, const Eigen::Vector3d& target_world) {
    return Camera{PinholeIntrinsics::FromFov(kWidth, kHeight, 80), LookAt(eye_world - origin, target_world - origin)};
  };
  const std::vector<uint8_t> at_origin = RenderViewer();
  const std::vector<uint8_t> far = RenderFrom(local_camera(origin + kViewerEye, origin + Eigen::Vector3d(0, -2, 0)));
  int differ = 0;
  for (size_t k = 0; k < far.size(); ++k) differ += std::abs(int(far[k]) - int(at_origin[k])) > 2;
  EXPECT_LE(differ, static_cast<int>(far.size() / 1000));
  const std::vector<uint8_t> moved =
      RenderFrom(local_camera(origin + kViewerEye + Eigen::Vector3d(0.01, 0, 0), origin + Eigen::Vector3d(0.01, -2, 0)));
  EXPECT_FALSE(moved == far) << "a 1 cm move must change the picture";
  EXPECT_EQ(static_cast<float>(origin.x() + 0.01), static_cast<float>(origin.x() + 0.03))
      << "float world coordinates cannot tell these apart: the reason for the local frame";
}

// Hard case: a pose with NaNs is ignored; the camera is listed stale and the frame has no NaN
// (it is the frame without that camera).
TEST_F(SceneTest, HardCase_NanPoseIsIgnoredAndMarkedStale) {
  const std::vector<uint8_t> good = RenderViewer(true);
  Projector nan_pose = MakeProjector(ViewerCamera(), image_, 1);
  nan_pose.camera_id = "cam-nan";
  nan_pose.view(0, 3) = std::numeric_limits<double>::quiet_NaN();
  ASSERT_TRUE(renderer_->SetProjectors({MakeProjector(projector_, {}, 1), nan_pose}).ok());
  EXPECT_THAT(renderer_->StaleCameras(), ::testing::ElementsAre("cam-nan"));
  EXPECT_TRUE(RenderViewer(true) == good);
  // cam-test with a NaN pose keeps its last good pose and frame.
  Projector stale_test = MakeProjector(projector_, image_, 2);
  stale_test.position.x() = std::numeric_limits<double>::infinity();
  ASSERT_TRUE(renderer_->SetProjectors({stale_test}).ok());
  EXPECT_THAT(renderer_->StaleCameras(), ::testing::ElementsAre("cam-nan", "cam-test"));
  EXPECT_TRUE(RenderViewer(true) == good);
  ASSERT_TRUE(renderer_->SetProjectors({MakeProjector(projector_, image_, 1)}).ok());
  EXPECT_THAT(renderer_->StaleCameras(), ::testing::ElementsAre("cam-nan"));
}

// Texture retention: after the camera turns away the ground keeps its last imagery, fading with
// the half-life; the age tint changes it; retention off gives the model colour back.
TEST_F(SceneTest, Retention_KeepsImageryAfterTheCameraTurnsAway) {
  renderer_->SetClock(100);
  ASSERT_TRUE(renderer_->SetProjectors({MakeProjector(projector_, image_, 5)}).ok());  // captured at t = 100 s
  const Eigen::Vector3d p(-8, 6, 0);
  const Eigen::Vector2d uv = *projector_.Pixel(p);
  const Eigen::Vector3i video = QuadrantColor(uv.x(), uv.y(), 640, 480);
  ASSERT_TRUE(Near(ViewerPixel(RenderViewer(), p), video));
  Camera turned = projector_;
  turned.world_from_camera = LookAt(kProjectorEye, {-18, -30, 0});
  ASSERT_FALSE(turned.Pixel(p) && turned.InImage(*turned.Pixel(p), -2)) << "test setup: turned away from p";
  ASSERT_TRUE(renderer_->SetProjectors({MakeProjector(turned, image_, 6)}).ok());
  EXPECT_EQ(renderer_->stats().retained_snapshots, 1u);
  EXPECT_TRUE(Near(ViewerPixel(RenderViewer(), p), video)) << "fresh retained imagery";
  renderer_->SetClock(160);  // one half-life (60 s)
  const Eigen::Vector3i half = ((video + ShadedGround()).cast<double>() / 2).array().round().cast<int>();
  EXPECT_TRUE(Near(ViewerPixel(RenderViewer(), p), half)) << Str(ViewerPixel(RenderViewer(), p)) << " vs " << Str(half);
  DisplayOptions display;
  display.tint_by_age = true;
  ASSERT_TRUE(renderer_->SetDisplayOptions(display).ok());
  EXPECT_FALSE(Near(ViewerPixel(RenderViewer(), p), half, 3));
  display.retention_half_life_s = 0;
  ASSERT_TRUE(renderer_->SetDisplayOptions(display).ok());
  EXPECT_TRUE(Near(ViewerPixel(RenderViewer(), p), ShadedGround()));
}


// Overlap policy: two cameras on the same ground, red from near, blue from far.
TEST_F(SceneTest, Overlap_PolicyDecidesWhichCameraPaints) {
  const Camera near_cam{PinholeIntrinsics::FromFov(640, 480, 70), LookAt({-12, 10, 6}, {-10, 6, 0})};
  const Camera far_cam{PinholeIntrinsics::FromFov(640, 480, 70), LookAt({-18, -16, 14}, {-10, 6, 0})};
  const std::vector<uint8_t> red = SolidImage(640, 480, {255, 0, 0}), blue = SolidImage(640, 480, {0, 0, 255});
  Projector a = MakeProjector(near_cam, red, 1), b = MakeProjector(far_cam, blue, 1);
  a.camera_id = "near";
  b.camera_id = "far";
  ASSERT_TRUE(renderer_->SetProjectors({a, b}).ok());
  const Eigen::Vector3d p(-10, 6, 0);
  ASSERT_TRUE(near_cam.InImage(*near_cam.Pixel(p), 20) && far_cam.InImage(*far_cam.Pixel(p), 20));
  DisplayOptions display;
  display.overlap = OverlapPolicy::kLastWins;
  ASSERT_TRUE(renderer_->SetDisplayOptions(display).ok());
  EXPECT_TRUE(Near(ViewerPixel(RenderViewer(), p), {0, 0, 255}));
  display.overlap = OverlapPolicy::kBestView;
  ASSERT_TRUE(renderer_->SetDisplayOptions(display).ok());
  const Eigen::Vector3i best = ViewerPixel(RenderViewer(), p);
  EXPECT_GT(best.x(), 230) << Str(best);
  display.overlap = OverlapPolicy::kBlendBestView;
  ASSERT_TRUE(renderer_->SetDisplayOptions(display).ok());
  const Eigen::Vector3i blend = ViewerPixel(RenderViewer(), p);
  EXPECT_GT(blend.x(), blend.z()) << "the nearer, more head-on camera weighs more: " << Str(blend);
  EXPECT_GT(blend.z(), 10) << "but both contribute: " << Str(blend);
  EXPECT_LT(blend.x(), best.x());
}

// Standing models receive video; paths are drawn.
TEST_F(SceneTest, Models_CylinderAndBillboardReceiveVideoAndPathsAreDrawn) {
  const std::vector<uint8_t> green = SolidImage(640, 480, {0, 255, 0});
  ASSERT_TRUE(renderer_->SetProjectors({MakeProjector(projector_, green, 2)}).ok());
  DynamicModel cylinder{{-9, 6, 0}, 0, {0.8, 0.8, 2}, {0.9f, 0.1f, 0.9f}, ModelShape::kCylinder};
  DynamicModel billboard{{-9, -6, 0}, 0, {0.6, 1.0, 2}, {0.9f, 0.1f, 0.9f}, ModelShape::kBillboard};
  ASSERT_TRUE(renderer_->SetDynamicModels({cylinder, billboard}).ok());
  const Polyline path{{{-16, -14, 0.05}, {-16, -4, 0.05}}, {0, 1, 1}};
  ASSERT_TRUE(renderer_->SetPaths({path}).ok());
  const std::vector<uint8_t> rgba = RenderViewer(false);  // paths are drawn without frustums too
  WritePng("/tmp/render_models.png", rgba, kWidth, kHeight);
  // Points on the cylinder's side and on the billboard's north-facing quad that both the projector
  // (west-north-west of them) and the viewer (north-north-east) see.
  const Eigen::Vector3d on_cylinder(-9 - 0.41 * 0.866, 6 + 0.41 * 0.5, 1), on_billboard(-9.2, -5.99, 1.5);
  EXPECT_TRUE(Near(ViewerPixel(rgba, on_cylinder), {0, 255, 0})) << Str(ViewerPixel(rgba, on_cylinder));
  EXPECT_TRUE(Near(ViewerPixel(rgba, on_billboard), {0, 255, 0})) << Str(ViewerPixel(rgba, on_billboard));
  const std::optional<Eigen::Vector2d> uv = viewer_.Pixel({-16, -9, 0.05});
  ASSERT_TRUE(uv);
  bool found = false;
  for (int dv = -2; dv <= 2; ++dv) {
    for (int du = -2; du <= 2; ++du) {
      found |= Near(PixelAt(rgba, kWidth, int(std::lround(uv->x())) + du, int(std::lround(uv->y())) + dv), {0, 255, 255});
    }
  }
  EXPECT_TRUE(found) << "path not drawn near " << uv->transpose();
}

// --depth: linear depth along the view axis, +inf for the sky, written as OpenEXR.
TEST_F(SceneTest, Depth_IsLinearMetresAndWritesExr) {
  View view = MakeView(viewer_, {0, 0, kWidth, kHeight});
  context_->BindFramebuffer();
  ASSERT_TRUE(renderer_->Render({view}, kWidth, kHeight).ok());
  const absl::StatusOr<std::vector<float>> depth = renderer_->ReadLinearDepth(view);
  ASSERT_TRUE(depth.ok()) << depth.status();
  for (const Eigen::Vector3d& p : {Eigen::Vector3d(-8, 6, 0), Eigen::Vector3d(12, -12, 0), Eigen::Vector3d(0, 0, 8)}) {
    const Eigen::Vector2d uv = *viewer_.Pixel(p);
    const int u = static_cast<int>(std::lround(uv.x())), v = static_cast<int>(std::lround(uv.y()));
    // The depth of the surface under that pixel centre: ray cast, then along the optical axis.
    const Eigen::Vector3d ray = viewer_.world_from_camera.rotation * PixelRay(viewer_.intrinsics, {u, v});
    const std::optional<RayHit> hit = RaycastMesh(mesh_, kViewerEye, ray);
    ASSERT_TRUE(hit);
    const double expected = (viewer_.world_from_camera.Inverse() * (kViewerEye + hit->distance_m * ray)).z();
    EXPECT_NEAR((*depth)[static_cast<size_t>(v) * kWidth + u], expected, 0.01 * expected) << p.transpose();
  }
  EXPECT_TRUE(std::isinf((*depth)[5]));  // top-left corner: sky
  const std::string path = ::testing::TempDir() + "/render_depth.exr";
  ASSERT_TRUE(WriteDepthExr(path, *depth, kWidth, kHeight).ok());
  FILE* f = std::fopen(path.c_str(), "rb");
  ASSERT_NE(f, nullptr);
  unsigned char magic[4] = {0, 0, 0, 0};
  EXPECT_EQ(std::fread(magic, 1, 4, f), 4u);
  std::fclose(f);
  EXPECT_EQ(magic[0], 0x76);
  EXPECT_EQ(magic[1], 0x2f);
  EXPECT_FALSE(WriteDepthExr("/nonexistent-dir/x.exr", *depth, kWidth, kHeight).ok());
  EXPECT_FALSE(WriteDepthExr(path, *depth, kWidth + 1, kHeight).ok());
}

// The headless display is Mesa's surfaceless platform or an EGL device (a GPU server without
// Mesa), as AVE_EGL_PLATFORM says: both draw the test scene alike here (Mesa offers both, llvmpipe
// behind each), and a value that is neither is refused naming the variable.
TEST(HeadlessContextTest, EglPlatformFromTheEnvironmentDrawsTheSameScene) {
  struct Restore {
    ~Restore() { ::unsetenv("AVE_EGL_PLATFORM"); }
  } restore;
  ::setenv("AVE_EGL_PLATFORM", "gbm", 1);
  absl::StatusOr<std::unique_ptr<HeadlessContext>> refused = CreateHeadlessContext(kWidth, kHeight);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(refused.status().message().find("AVE_EGL_PLATFORM='gbm'"), std::string_view::npos) << refused.status();

  std::vector<std::vector<uint8_t>> pictures;
  for (const char* platform : {"surfaceless", "device"}) {
    ::setenv("AVE_EGL_PLATFORM", platform, 1);
    absl::StatusOr<std::unique_ptr<HeadlessContext>> context = CreateHeadlessContext(kWidth, kHeight);
    ASSERT_TRUE(context.ok()) << platform << ": " << context.status();
    std::printf("%s: %s\n", platform, (*context)->Description().c_str());
    absl::StatusOr<std::unique_ptr<Renderer>> renderer = Renderer::Create({});
    ASSERT_TRUE(renderer.ok()) << platform << ": " << renderer.status();
    ASSERT_TRUE((*renderer)->SetStaticMesh(GroundAndBox()).ok());
    ASSERT_TRUE((*renderer)->SetProjectors({MakeProjector(ProjectorCamera(), QuadrantImage(640, 480), 1)}).ok());
    (*context)->BindFramebuffer();
    ASSERT_TRUE((*renderer)->Render({MakeView(ViewerCamera(), {0, 0, kWidth, kHeight})}, kWidth, kHeight).ok()) << platform;
    absl::StatusOr<std::vector<uint8_t>> pixels = (*context)->ReadPixels();
    ASSERT_TRUE(pixels.ok()) << platform << ": " << pixels.status();
    pictures.push_back(*pixels);
    renderer->reset();  // before its context goes
  }
  ASSERT_EQ(pictures[0].size(), pictures[1].size());
  size_t differ = 0;
  for (size_t k = 0; k < pictures[0].size(); ++k) differ += std::abs(int(pictures[0][k]) - int(pictures[1][k])) > 3;
  EXPECT_LE(differ, pictures[0].size() / 1000) << "surfaceless and device pictures differ";
  size_t lit = 0;
  for (uint8_t v : pictures[1]) lit += v > 0;
  EXPECT_GT(lit, pictures[1].size() / 4) << "the device platform drew the scene";
}

// ---------------------------------------------------------------------------------------------
}  // namespace
}  // namespace ave::viewer
