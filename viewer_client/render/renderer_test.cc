// Render tests against analytically expected pixels (render_test_scene.h): projection, shadows,
// frustums, locked views, inputs and their errors, contexts, layout, the campus quad view.
#include "viewer_client/render/passes/projector_geometry.h"
#include "viewer_client/render/render_test_scene.h"

namespace ave::viewer {
namespace {

using namespace ::ave::viewer::render_test;  // NOLINT: the shared scene and helpers of the render tests
using ::testing::HasSubstr;

// (a) Ground the projector sees shows its image's colour there.
TEST_F(SceneTest, Projection_VisibleGroundShowsVideoColor) {
  const std::vector<uint8_t> rgba = RenderViewer();
  WritePng("/tmp/render_test_scene.png", rgba, kWidth, kHeight);
  int checked = 0;
  for (const Eigen::Vector3d& p : {Eigen::Vector3d(-8, 6, 0), Eigen::Vector3d(-6, -6, 0), Eigen::Vector3d(2, -8, 0),
                                  Eigen::Vector3d(8, 9, 0), Eigen::Vector3d(-4, -10, 0), Eigen::Vector3d(12, -12, 0)}) {
    const std::optional<Eigen::Vector2d> uv = projector_.Pixel(p);
    ASSERT_TRUE(uv && projector_.InImage(*uv, 12)) << p.transpose();
    if (std::abs(uv->x() - 319.5) < 12 || std::abs(uv->y() - 239.5) < 12) continue;  // quadrant border
    ASSERT_TRUE(SegmentIsClear(mesh_, kProjectorEye, p)) << "test setup: projector sees " << p.transpose();
    const Eigen::Vector3i expected = QuadrantColor(uv->x(), uv->y(), 640, 480);
    const Eigen::Vector3i got = ViewerPixel(rgba, p);
    EXPECT_TRUE(Near(got, expected)) << p.transpose() << ": got " << Str(got) << " expected " << Str(expected);
    ++checked;
  }
  EXPECT_GE(checked, 4);
}

// (b) Ground hidden from the projector by the box keeps the model's shaded colour.
TEST_F(SceneTest, Projection_ShadowedGroundKeepsModelColor) {
  const std::vector<uint8_t> rgba = RenderViewer();
  for (const Eigen::Vector3d& p : {Eigen::Vector3d(6, 0, 0), Eigen::Vector3d(9, 1.5, 0), Eigen::Vector3d(14, -1, 0)}) {
    const std::optional<Eigen::Vector2d> uv = projector_.Pixel(p);
    ASSERT_TRUE(uv && projector_.InImage(*uv, 12)) << "test setup: inside the frustum " << p.transpose();
    ASSERT_FALSE(SegmentIsClear(mesh_, kProjectorEye, p)) << "test setup: box hides " << p.transpose();
    const Eigen::Vector3i got = ViewerPixel(rgba, p);
    EXPECT_TRUE(Near(got, ShadedGround())) << p.transpose() << ": got " << Str(got) << " expected " << Str(ShadedGround());
  }
}

// (c) Ground outside the projector's frustum keeps the model's shaded colour.
TEST_F(SceneTest, Projection_OutsideFrustumKeepsModelColor) {
  const std::vector<uint8_t> rgba = RenderViewer();
  for (const Eigen::Vector3d& p : {Eigen::Vector3d(-18, 12, 0), Eigen::Vector3d(-17, -8, 0)}) {
    const std::optional<Eigen::Vector2d> uv = projector_.Pixel(p);
    ASSERT_FALSE(uv && projector_.InImage(*uv, -3)) << "test setup: outside the frustum " << p.transpose();
    const Eigen::Vector3i got = ViewerPixel(rgba, p);
    EXPECT_TRUE(Near(got, ShadedGround())) << p.transpose() << ": got " << Str(got) << " expected " << Str(ShadedGround());
  }
}

// (d) Same inputs, same pixels.
TEST_F(SceneTest, Render_IsBitIdenticalTwice) {
  const std::vector<uint8_t> first = RenderViewer(true);
  const std::vector<uint8_t> second = RenderViewer(true);
  ASSERT_EQ(first.size(), second.size());
  EXPECT_TRUE(first == second);
}

// (e) Building feet: ground 0.3 m in front of the lit wall is textured (the wall's depth does not
// leak onto it) and ground just behind the box is not (no peter-panning).
TEST_F(SceneTest, Projection_GroundAtBuildingFootIsTextured) {
  const std::vector<uint8_t> rgba = RenderViewer();
  for (const double y : {-2.0, -1.0, 1.0, 2.0}) {
    const Eigen::Vector3d p(-3.3, y, 0);
    const std::optional<Eigen::Vector2d> uv = projector_.Pixel(p);
    ASSERT_TRUE(uv && projector_.InImage(*uv, 12));
    ASSERT_TRUE(SegmentIsClear(mesh_, kProjectorEye, p));
    if (std::abs(uv->x() - 319.5) < 6 || std::abs(uv->y() - 239.5) < 6) continue;
    const Eigen::Vector3i expected = QuadrantColor(uv->x(), uv->y(), 640, 480);
    const Eigen::Vector3i got = ViewerPixel(rgba, p);
    EXPECT_TRUE(Near(got, expected)) << p.transpose() << ": got " << Str(got) << " expected " << Str(expected);
  }
  // ... and the shadow stays attached on the far side: ground 0.4 m behind the box, seen from the east.
  const Camera east{PinholeIntrinsics::FromFov(kWidth, kHeight, 80), LookAt({25, -10, 30}, {0, 0, 0})};
  const std::vector<uint8_t> from_east = RenderFrom(east);
  for (const double y : {-1.5, 1.5}) {
    const Eigen::Vector3d p(3.4, y, 0);
    ASSERT_FALSE(SegmentIsClear(mesh_, kProjectorEye, p));
    const Eigen::Vector3i got = PixelSeenBy(east, from_east, p);
    EXPECT_TRUE(Near(got, ShadedGround())) << p.transpose() << ": got " << Str(got) << " expected " << Str(ShadedGround());
  }
}

TEST_F(SceneTest, Frustum_LinesAreDrawnInProjectorColor) {
  const std::vector<uint8_t> without = RenderViewer(false);
  const std::vector<uint8_t> with = RenderViewer(true);
  const double depth_m = renderer_->options().frustum_depth_m;
  const PinholeIntrinsics& k = projector_.intrinsics;
  // Midpoints of the four centre-to-corner edges.
  for (const Eigen::Vector2d& corner : {Eigen::Vector2d(-0.5, -0.5), Eigen::Vector2d(k.width - 0.5, -0.5),
                                       Eigen::Vector2d(-0.5, k.height - 0.5), Eigen::Vector2d(k.width - 0.5, k.height - 0.5)}) {
    Eigen::Vector3d ray = PixelRay(k, corner);
    ray *= depth_m / ray.z();
    const Eigen::Vector3d mid = projector_.world_from_camera * (0.5 * ray);
    ASSERT_TRUE(SegmentIsClear(mesh_, kViewerEye, mid));
    const std::optional<Eigen::Vector2d> uv = viewer_.Pixel(mid);
    ASSERT_TRUE(uv && viewer_.InImage(*uv, 4));
    bool found = false, found_before = false;
    for (int dv = -3; dv <= 3; ++dv) {
      for (int du = -3; du <= 3; ++du) {
        const int u = static_cast<int>(std::lround(uv->x())) + du, v = static_cast<int>(std::lround(uv->y())) + dv;
        found |= Near(PixelAt(with, kWidth, u, v), ToRgb255(kFrustumColor));
        found_before |= Near(PixelAt(without, kWidth, u, v), ToRgb255(kFrustumColor));
      }
    }
    EXPECT_TRUE(found) << "no frustum pixel near " << uv->transpose();
    EXPECT_FALSE(found_before);
  }
}

// The camera-locked view (same aspect) shows the camera image wherever the camera sees the model.
TEST_F(SceneTest, LockedView_ShowsTheCameraImage) {
  const Projector projector = MakeProjector(projector_, image_, 1);
  const View view = ViewLockedToProjector(projector, {0, 0, kWidth, kHeight});
  context_->BindFramebuffer();
  ASSERT_TRUE(renderer_->Render({view}, kWidth, kHeight).ok());
  const std::vector<uint8_t> rgba = *context_->ReadPixels();
  int checked = 0;
  for (int v = 20; v < kHeight; v += 40) {
    for (int u = 20; u < kWidth; u += 40) {
      const Eigen::Vector3d ray = projector_.world_from_camera.rotation * PixelRay(projector_.intrinsics, {u, v});
      if (!RaycastMesh(mesh_, kProjectorEye, ray)) continue;  // sky
      const Eigen::Vector3i expected = QuadrantColor(u, v, kWidth, kHeight);
      EXPECT_TRUE(Near(PixelAt(rgba, kWidth, u, v), expected)) << u << ", " << v;
      ++checked;
    }
  }
  EXPECT_GT(checked, 100);
}

TEST_F(SceneTest, DynamicBox_ReceivesVideoAndCastsShadow) {
  // A 1 x 1 x 3 m box on visible ground; the ground just behind it (seen from the projector) loses the video.
  const Eigen::Vector3d base(-8, 6, 0);
  ASSERT_TRUE(renderer_->SetDynamicObjects({DynamicBox{base, 0.0, {1, 1, 3}, {0.2f, 0.8f, 0.2f}}}).ok());
  const std::vector<uint8_t> rgba = RenderViewer();
  const Eigen::Vector3d top(-8, 6, 3);
  const std::optional<Eigen::Vector2d> top_uv = projector_.Pixel(top);
  ASSERT_TRUE(top_uv);
  EXPECT_TRUE(Near(ViewerPixel(rgba, top + Eigen::Vector3d(0, 0, 0.01)), QuadrantColor(top_uv->x(), top_uv->y(), 640, 480)));
  // Ground hit by the projector's ray through the box's mid-height centre, continued.
  const Eigen::Vector3d through = base + Eigen::Vector3d(0, 0, 1.5);
  const Eigen::Vector3d dir = (through - kProjectorEye).normalized();
  const Eigen::Vector3d behind = kProjectorEye + dir * (-kProjectorEye.z() / dir.z());
  EXPECT_TRUE(Near(ViewerPixel(rgba, behind), ShadedGround())) << behind.transpose();
}

TEST_F(SceneTest, Renderer_RedoesWorkOnlyWhenInputsChange) {
  RenderViewer();
  const RenderStats first = renderer_->stats();
  EXPECT_EQ(first.shadow_map_renders, 1u);
  EXPECT_EQ(first.video_uploads, 1u);
  RenderViewer();
  ASSERT_TRUE(renderer_->SetProjectors({MakeProjector(projector_, image_, 1)}).ok());
  RenderViewer();
  EXPECT_EQ(renderer_->stats().shadow_map_renders, 1u);
  EXPECT_EQ(renderer_->stats().video_uploads, 1u);
  ASSERT_TRUE(renderer_->SetProjectors({MakeProjector(projector_, image_, 2)}).ok());
  RenderViewer();
  EXPECT_EQ(renderer_->stats().video_uploads, 2u);
  EXPECT_EQ(renderer_->stats().shadow_map_renders, 1u);
  Camera moved = projector_;
  moved.world_from_camera.translation.x() += 1;
  ASSERT_TRUE(renderer_->SetProjectors({MakeProjector(moved, {}, 2)}).ok());
  RenderViewer();
  EXPECT_EQ(renderer_->stats().shadow_map_renders, 2u);
  EXPECT_EQ(renderer_->stats().video_uploads, 2u);
  const uint64_t dynamic_before = renderer_->stats().dynamic_shadow_updates;
  ASSERT_TRUE(renderer_->SetDynamicObjects({DynamicBox{}}).ok());
  RenderViewer();
  EXPECT_EQ(renderer_->stats().shadow_map_renders, 2u);
  EXPECT_EQ(renderer_->stats().dynamic_shadow_updates, dynamic_before + 1);
}

TEST_F(SceneTest, Renderer_RejectsBadInputsWithReasons) {
  std::vector<Projector> many(kMaxProjectors + 1, MakeProjector(projector_, image_, 1));
  absl::Status s = renderer_->SetProjectors(many);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(s.message()), HasSubstr("at most 64"));

  const std::vector<uint8_t> short_image(100);
  s = renderer_->SetProjectors({MakeProjector(projector_, short_image, 7)});
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(s.message()), HasSubstr("cam-test"));

  Projector bad_planes = MakeProjector(projector_, image_, 1);
  bad_planes.far_m = 0.1;
  EXPECT_EQ(renderer_->SetProjectors({bad_planes}).code(), absl::StatusCode::kInvalidArgument);

  TriangleMesh broken = mesh_;
  broken.indices.push_back(100000);
  broken.indices.push_back(0);
  broken.indices.push_back(1);
  s = renderer_->SetStaticMesh(broken);
  EXPECT_THAT(std::string(s.message()), HasSubstr(">= vertex count"));

  View outside = MakeView(viewer_, {0, 0, kWidth + 1, kHeight});
  EXPECT_EQ(renderer_->Render({outside}, kWidth, kHeight).code(), absl::StatusCode::kInvalidArgument);

  RendererOptions options;
  options.shadow_map_size = 10;
  const absl::StatusOr<std::unique_ptr<Renderer>> r = Renderer::Create(options);
  EXPECT_THAT(std::string(r.status().message()), HasSubstr("shadow_map_size"));

  // The good state survived the rejected calls.
  const std::vector<uint8_t> rgba = RenderViewer();
  const Eigen::Vector3d p(-8, 6, 0);
  const Eigen::Vector2d uv = *projector_.Pixel(p);
  EXPECT_TRUE(Near(ViewerPixel(rgba, p), QuadrantColor(uv.x(), uv.y(), 640, 480)));
}

TEST_F(SceneTest, Shader_CompileErrorNamesTheFile) {
  const absl::StatusOr<unsigned int> program = internal::BuildProgram(
      "shaders/ok.vert.glsl", internal::EmbeddedShader("shaders/shadow.vert.glsl"), "shaders/broken.frag.glsl",
      "#version 330 core\nvoid main() { undefined_call(); }\n");
  ASSERT_FALSE(program.ok());
  EXPECT_THAT(std::string(program.status().message()), HasSubstr("shaders/broken.frag.glsl"));
  EXPECT_THAT(std::string(program.status().message()), HasSubstr("compile"));
}

TEST(HeadlessContext, ReadPixelsIsTopRowFirstAndQuadLayoutIsGlOriented) {
  absl::StatusOr<std::unique_ptr<HeadlessContext>> context = CreateHeadlessContext(64, 48);
  ASSERT_TRUE(context.ok()) << "headless EGL must work here: " << context.status();
  std::printf("GL: %s\n", (*context)->Description().c_str());
  absl::StatusOr<std::unique_ptr<Renderer>> renderer = Renderer::Create();
  ASSERT_TRUE(renderer.ok()) << renderer.status();
  const std::array<Viewport, 4> quads = QuadLayout(64, 48);
  const Eigen::Vector3f colors[4] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {1, 1, 1}};
  std::vector<View> views(4);
  for (int k = 0; k < 4; ++k) {
    views[k].viewport = quads[k];
    views[k].clear_color = colors[k];
  }
  ASSERT_TRUE((*renderer)->Render(views, 64, 48).ok());
  const std::vector<uint8_t> rgba = *(*context)->ReadPixels();
  EXPECT_EQ(PixelAt(rgba, 64, 2, 2), Eigen::Vector3i(255, 0, 0));      // top-left: browse view
  EXPECT_EQ(PixelAt(rgba, 64, 61, 2), Eigen::Vector3i(0, 255, 0));     // top-right
  EXPECT_EQ(PixelAt(rgba, 64, 2, 45), Eigen::Vector3i(0, 0, 255));     // bottom-left
  EXPECT_EQ(PixelAt(rgba, 64, 61, 45), Eigen::Vector3i(255, 255, 255));  // bottom-right
}

// Without a display the window context says so; with one (e.g. Xvfb) it draws like the headless one.
TEST(WindowContext, OpensOnlyWithADisplay) {
  const char* display = std::getenv("DISPLAY");
  WindowOptions options;
  options.visible = false;
  options.width = 64;
  options.height = 48;
  absl::StatusOr<std::unique_ptr<WindowContext>> window = CreateWindowContext(options);
  if (display == nullptr || *display == '\0') {
    ASSERT_FALSE(window.ok());
    EXPECT_THAT(std::string(window.status().message()), HasSubstr("DISPLAY"));
    return;
  }
  ASSERT_TRUE(window.ok()) << window.status();
  std::printf("GL: %s\n", (*window)->Description().c_str());
  absl::StatusOr<std::unique_ptr<Renderer>> renderer = Renderer::Create();
  ASSERT_TRUE(renderer.ok()) << renderer.status();
  const int w = (*window)->framebuffer_width(), h = (*window)->framebuffer_height();
  std::vector<View> views(4);
  const std::array<Viewport, 4> quads = QuadLayout(w, h);
  for (int k = 0; k < 4; ++k) {
    views[k].viewport = quads[k];
    views[k].clear_color = k == 0 ? Eigen::Vector3f(1, 0, 0) : Eigen::Vector3f(0, 0, 1);
  }
  (*window)->BindFramebuffer();
  ASSERT_TRUE((*renderer)->Render(views, w, h).ok());
  const std::vector<uint8_t> rgba = *(*window)->ReadPixels();
  EXPECT_EQ(PixelAt(rgba, w, 1, 1), Eigen::Vector3i(255, 0, 0));
  EXPECT_EQ(PixelAt(rgba, w, w - 2, h - 2), Eigen::Vector3i(0, 0, 255));
  (*window)->SwapBuffers();
  (*window)->PollEvents();
  const WindowInput input = (*window)->TakeInput();
  EXPECT_EQ(input.scroll, 0.0);
  EXPECT_FALSE((*window)->ShouldClose());
  renderer->reset();
}

TEST(QuadLayout, TilesTheFramebufferExactly) {
  const std::array<Viewport, 4> q = QuadLayout(1281, 721);
  EXPECT_EQ(q[0].x, 0);
  EXPECT_EQ(q[0].y + q[0].height, 721);  // top-left touches the top
  EXPECT_EQ(q[1].x + q[1].width, 1281);
  EXPECT_EQ(q[2].y, 0);
  EXPECT_EQ(q[0].width + q[1].width, 1281);
  EXPECT_EQ(q[2].height + q[0].height, 721);
  int area = 0;
  for (const Viewport& v : q) area += v.width * v.height;
  EXPECT_EQ(area, 1281 * 721);
}

TEST(ViewLockedToProjector, KeepsTheImageAspectCentred) {
  const Camera cam = ProjectorCamera();
  const std::vector<uint8_t> image = QuadrantImage(640, 480);
  const Projector p = MakeProjector(cam, image, 1);
  // A 2:1 viewport: the 4:3 image spans the middle 2/3 of its width and its full height.
  const View wide = ViewLockedToProjector(p, {0, 0, 800, 400});
  const Eigen::Vector3d in_eye = cam.world_from_camera * (PixelRay(cam.intrinsics, {-0.5, -0.5}) * 10.0);
  Eigen::Vector4d clip = wide.projection * wide.view * in_eye.homogeneous();
  EXPECT_NEAR(clip.x() / clip.w(), -(4.0 / 3.0) / 2.0, 1e-9);
  EXPECT_NEAR(clip.y() / clip.w(), 1.0, 1e-9);
  const View tall = ViewLockedToProjector(p, {0, 0, 300, 400});
  clip = tall.projection * tall.view * in_eye.homogeneous();
  EXPECT_NEAR(clip.x() / clip.w(), -1.0, 1e-9);
  EXPECT_NEAR(clip.y() / clip.w(), (0.75 / (4.0 / 3.0)), 1e-9);
  EXPECT_EQ(tall.highlight_camera_id, "cam-test");
}

// The built-in campus in the quad layout at 1280x720 with its three cameras projecting; prints
// the frame time and writes /tmp/render_example.png.
TEST(Campus, RendersQuadLayoutWithThreeProjectors) {
  constexpr int kW = 1280, kH = 720;
  absl::StatusOr<std::unique_ptr<HeadlessContext>> context = CreateHeadlessContext(kW, kH);
  ASSERT_TRUE(context.ok()) << context.status();
  absl::StatusOr<std::unique_ptr<Renderer>> created = Renderer::Create();
  ASSERT_TRUE(created.ok()) << created.status();
  Renderer& renderer = **created;
  const scene::SyntheticCampus campus = scene::BuiltinCampus();
  ASSERT_TRUE(renderer.SetStaticMesh(scene::BuildStaticMesh(campus)).ok());

  const Eigen::Vector3f frustum_colors[3] = {{1, 0.3f, 0.1f}, {0.1f, 0.9f, 0.2f}, {0.2f, 0.4f, 1}};
  std::vector<std::vector<uint8_t>> images;
  std::vector<Projector> projectors;
  for (size_t c = 0; c < campus.cameras.size(); ++c) {
    const scene::CameraSpec& cam = campus.cameras[c];
    const int w = cam.intrinsics.width, h = cam.intrinsics.height;
    std::vector<uint8_t> rgba(static_cast<size_t>(w) * h * 4);
    for (int v = 0; v < h; ++v) {
      for (int u = 0; u < w; ++u) {
        uint8_t* px = &rgba[(static_cast<size_t>(v) * w + u) * 4];
        const bool grid = (u % 64) < 3 || (v % 64) < 3;
        px[0] = grid ? 255 : static_cast<uint8_t>(255 * u / w);
        px[1] = grid ? 255 : static_cast<uint8_t>(255 * v / h);
        px[2] = grid ? 255 : static_cast<uint8_t>(80 * c);
        px[3] = 255;
      }
    }
    images.push_back(std::move(rgba));
  }
  for (size_t c = 0; c < campus.cameras.size(); ++c) {
    const scene::CameraSpec& cam = campus.cameras[c];
    Projector p;
    p.camera_id = cam.id;
    p.view = GlViewFromWorld(cam.world_from_camera);
    p.projection = GlProjection(cam.intrinsics, p.near_m, p.far_m);
    p.position = cam.world_from_camera.translation;
    p.image_width = cam.intrinsics.width;
    p.image_height = cam.intrinsics.height;
    p.image_rgba = images[c];
    p.image_serial = 1;
    p.color = frustum_colors[c];
    projectors.push_back(p);
  }
  ASSERT_TRUE(renderer.SetProjectors(projectors).ok());

  const std::array<Viewport, 4> quads = QuadLayout(kW, kH);
  const Camera browse{PinholeIntrinsics::FromFov(quads[0].width, quads[0].height, 70),
                      LookAt({-70, -90, 70}, {0, 0, 0})};
  std::vector<View> views = {MakeView(browse, quads[0])};
  views[0].highlight_camera_id = "cam1";
  for (int k = 0; k < 3; ++k) views.push_back(ViewLockedToProjector(projectors[k], quads[k + 1]));

  auto boxes_at = [&](double t_s) {
    std::vector<DynamicBox> boxes;
    for (const scene::Mover& m : campus.movers) {
      const scene::MoverState s = scene::MoverAt(campus, m, t_s);
      boxes.push_back(DynamicBox{s.position_m, s.heading_rad, {m.size_m.y(), m.size_m.x(), m.size_m.z()}, m.color});
    }
    return boxes;
  };
  ASSERT_TRUE(renderer.SetDynamicObjects(boxes_at(0)).ok());
  (*context)->BindFramebuffer();
  ASSERT_TRUE(renderer.Render(views, kW, kH).ok());
  auto time_frames = [&](bool moving) {
    constexpr int kFrames = 2;  // figures: ave-bench render
    const auto start = std::chrono::steady_clock::now();
    for (int f = 0; f < kFrames; ++f) {
      if (moving) {
        ASSERT_TRUE(renderer.SetDynamicObjects(boxes_at(0.1 * (f + 1))).ok());
      }
      ASSERT_TRUE(renderer.Render(views, kW, kH).ok());
      ASSERT_TRUE((*context)->ReadPixels().ok());  // waits for the frame
    }
    const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    std::printf("1280x720 quad layout, 3 projectors, %zu movers%s: %.1f ms/frame (incl. readback)\n",
                campus.movers.size(), moving ? " moving" : " still", ms / kFrames);
  };
  time_frames(false);
  time_frames(true);
  const std::vector<uint8_t> rgba = *(*context)->ReadPixels();
  WritePng("/tmp/render_example.png", rgba, kW, kH);
  // The browse view is not all sky: the model is drawn.
  int non_sky = 0;
  for (int v = 0; v < kH / 2; v += 8) {
    for (int u = 0; u < kW / 2; u += 8) {
      non_sky += !Near(PixelAt(rgba, kW, u, v), ToRgb255(views[0].clear_color), 2);
    }
  }
  EXPECT_GT(non_sky, 1000);
}

// The patches of a cached view (issue 17): squares cover every pixel of the model rectangles once,
// stay inside the viewport, and two rectangles far apart do not grow into their union.
TEST(CoveringTilesTest, CoversEachPixelOnceInsideTheViewport) {
  const Viewport viewport{10, 20, 100, 50};
  const std::vector<Viewport> rects = {{12, 22, 5, 5}, {14, 24, 20, 3}, {100, 60, 30, 30}, {0, 0, 5, 5}, {80, 21, 2, 2}};
  const std::vector<Viewport> tiles = internal::CoveringTiles(rects, viewport, 8);
  std::vector<int> count(static_cast<size_t>(viewport.width) * viewport.height, 0);
  int64_t area = 0;
  for (const Viewport& t : tiles) {
    ASSERT_GE(t.x, viewport.x);
    ASSERT_GE(t.y, viewport.y);
    ASSERT_LE(t.x + t.width, viewport.x + viewport.width);
    ASSERT_LE(t.y + t.height, viewport.y + viewport.height);
    area += static_cast<int64_t>(t.width) * t.height;
    for (int y = t.y; y < t.y + t.height; ++y)
      for (int x = t.x; x < t.x + t.width; ++x) ++count[(y - viewport.y) * viewport.width + (x - viewport.x)];
  }
  for (int c : count) ASSERT_LE(c, 1) << "tiles overlap";
  for (const Viewport& r : rects) {
    for (int y = std::max(r.y, viewport.y); y < std::min(r.y + r.height, viewport.y + viewport.height); ++y)
      for (int x = std::max(r.x, viewport.x); x < std::min(r.x + r.width, viewport.x + viewport.width); ++x)
        ASSERT_EQ(count[(y - viewport.y) * viewport.width + (x - viewport.x)], 1) << x << ", " << y;
  }
  // x 12..33 of row 0 needs its columns 0..2 (24 x 8); (80, 21) one square; x 100..109, y 60..69
  // the squares from column 11 and row 5 to the viewport's edge (12 x 10). Their union: 100 x 50.
  EXPECT_EQ(area, 24 * 8 + 8 * 8 + 12 * 10);
  EXPECT_TRUE(internal::CoveringTiles({}, viewport, 8).empty());
}

// The models' shadow volumes end where the static surface behind them ends (issue 17): the
// deepest static depth around a rectangle of the shadow map, as a distance along the projector's
// axis, padded as the volumes' rectangles are; unknown (sky there, or nothing read back): infinity.
TEST(StaticDeepestTest, DeepestSurfaceAroundTheRectangle) {
  const Eigen::Matrix4d projection = GlProjection(PinholeIntrinsics::FromFov(64, 64, 60), 0.5, 200);
  auto window_depth = [&](double distance_m) {
    const Eigen::Vector4d clip = projection * Eigen::Vector4d(0, 0, -distance_m, 1);
    return static_cast<float>(0.5 * clip.z() / clip.w() + 0.5);
  };
  const int size = 64;
  std::vector<float> depth(static_cast<size_t>(size) * size, window_depth(10));
  for (int y = 40; y < 48; ++y)
    for (int x = 40; x < 48; ++x) depth[y * size + x] = window_depth(30);  // a far patch
  for (int x = 0; x < 16; ++x) depth[60 * size + x] = 1.0f;                 // sky in the top-left tile
  internal::ShadowSlot slot;
  EXPECT_TRUE(std::isinf(internal::StaticDeepestM(slot, {2, 2, 4, 4}, projection))) << "nothing read back";
  internal::SetDeepestTiles(depth, size, slot);
  ASSERT_EQ(slot.deepest_tiles_side, 4);
  EXPECT_NEAR(internal::StaticDeepestM(slot, {2, 2, 4, 4}, projection), 10, 1e-3);
  EXPECT_NEAR(internal::StaticDeepestM(slot, {20, 20, 10, 10}, projection), 30, 1e-2) << "its tiles reach the far patch";
  EXPECT_NEAR(internal::StaticDeepestM(slot, {18, 2, 8, 8}, projection), 10, 1e-3);
  EXPECT_TRUE(std::isinf(internal::StaticDeepestM(slot, {1, 50, 4, 4}, projection))) << "sky behind it";
}

}  // namespace
}  // namespace ave::viewer
