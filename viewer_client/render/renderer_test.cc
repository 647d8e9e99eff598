// Render tests against analytically expected pixels: a flat ground square, one box building and
// one projector looking down at it obliquely. Headless EGL (Mesa llvmpipe); no EGL is a failure.
#include "viewer_client/render/renderer.h"

#include <chrono>
#include <functional>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <optional>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/imgcodecs.hpp>

#include "model_store/geometry/bvh.h"
#include "model_store/geometry/camera.h"
#include "model_store/geometry/raycast.h"
#include "model_store/scene/campus.h"
#include "model_store/scene/scene_file.h"
#include "viewer_client/render/gl_context.h"
#include "viewer_client/render/shader_program.h"

namespace ave::viewer {
namespace {

using ::testing::HasSubstr;

constexpr int kWidth = 640;
constexpr int kHeight = 480;
const Eigen::Vector3f kGroundColor(0.5f, 0.5f, 0.5f);
const Eigen::Vector3f kFrustumColor(1.0f, 0.0f, 1.0f);
const Eigen::Vector3d kProjectorEye(-18, 0, 12);
const Eigen::Vector3d kViewerEye(-5, 35, 35);
constexpr int kTolerance = 10;  // per channel, of 255

// Quadrants of the projected image, top row first: top-left red, top-right green, bottom-left
// blue, bottom-right yellow. A wrong flip or mirror lands on another colour.
Eigen::Vector3i QuadrantColor(double u, double v, int width, int height) {
  const bool left = u < 0.5 * width, top = v < 0.5 * height;
  if (top) return left ? Eigen::Vector3i(255, 0, 0) : Eigen::Vector3i(0, 255, 0);
  return left ? Eigen::Vector3i(0, 0, 255) : Eigen::Vector3i(255, 255, 0);
}

std::vector<uint8_t> QuadrantImage(int width, int height) {
  std::vector<uint8_t> rgba(static_cast<size_t>(width) * height * 4);
  for (int v = 0; v < height; ++v) {
    for (int u = 0; u < width; ++u) {
      const Eigen::Vector3i c = QuadrantColor(u, v, width, height);
      uint8_t* px = &rgba[(static_cast<size_t>(v) * width + u) * 4];
      px[0] = static_cast<uint8_t>(c.x());
      px[1] = static_cast<uint8_t>(c.y());
      px[2] = static_cast<uint8_t>(c.z());
      px[3] = 255;
    }
  }
  return rgba;
}

TriangleMesh GroundAndBox() {
  TriangleMesh mesh;
  const int n = 21;  // 40 x 40 m in 2 m cells
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      mesh.positions.emplace_back(-20.0f + 2.0f * i, -20.0f + 2.0f * j, 0.0f);
      mesh.normals.emplace_back(0.0f, 0.0f, 1.0f);
      mesh.colors.push_back(kGroundColor);
    }
  }
  for (int j = 0; j + 1 < n; ++j) {
    for (int i = 0; i + 1 < n; ++i) {
      const uint32_t a = j * n + i, b = a + 1, c = a + n + 1, d = a + n;
      mesh.indices.insert(mesh.indices.end(), {a, b, c, a, c, d});
      mesh.triangle_material.insert(mesh.triangle_material.end(), 2, SurfaceMaterial::kTerrain);
      mesh.triangle_object.insert(mesh.triangle_object.end(), 2, -1);
    }
  }
  scene::AppendBox(mesh, Eigen::Vector3d::Zero(), 0, Eigen::Vector3d(6, 6, 8), Eigen::Vector3f(0.7f, 0.7f, 0.7f),
                   Eigen::Vector3f(0.6f, 0.6f, 0.6f), 0, SurfaceMaterial::kWall, SurfaceMaterial::kRoof);
  return mesh;
}

struct Camera {
  PinholeIntrinsics intrinsics;
  Rigid3d world_from_camera;

  // OpenCV pixel of a local point, which is also its framebuffer pixel (column, row from the top)
  // when rendered with GlViewFromWorld / GlProjection of this camera.
  std::optional<Eigen::Vector2d> Pixel(const Eigen::Vector3d& p) const {
    return ProjectToPixel(intrinsics, world_from_camera.Inverse() * p);
  }
  bool InImage(const Eigen::Vector2d& uv, double margin) const {
    return uv.x() >= margin && uv.y() >= margin && uv.x() <= intrinsics.width - 1 - margin &&
           uv.y() <= intrinsics.height - 1 - margin;
  }
};

Camera ProjectorCamera() { return {PinholeIntrinsics::FromFov(640, 480, 70), LookAt(kProjectorEye, {2, 0, 0})}; }
Camera ViewerCamera() { return {PinholeIntrinsics::FromFov(kWidth, kHeight, 80), LookAt(kViewerEye, {0, -2, 0})}; }

Projector MakeProjector(const Camera& cam, const std::vector<uint8_t>& image, uint64_t serial) {
  Projector p;
  p.camera_id = "cam-test";
  p.view = GlViewFromWorld(cam.world_from_camera);
  p.near_m = 0.5;
  p.far_m = 200;
  p.projection = GlProjection(cam.intrinsics, p.near_m, p.far_m);
  p.position = cam.world_from_camera.translation;
  p.image_width = cam.intrinsics.width;
  p.image_height = cam.intrinsics.height;
  p.image_rgba = image;
  p.image_serial = serial;
  p.color = kFrustumColor;
  return p;
}

View MakeView(const Camera& cam, Viewport viewport) {
  View v;
  v.viewport = viewport;
  v.view = GlViewFromWorld(cam.world_from_camera);
  v.projection = GlProjection(cam.intrinsics, 0.5, 300);
  return v;
}

Eigen::Vector3i ToRgb255(const Eigen::Vector3f& c) { return (c * 255.0f).array().round().cast<int>(); }

Eigen::Vector3i PixelAt(const std::vector<uint8_t>& rgba, int width, int u, int v) {
  const uint8_t* px = &rgba[(static_cast<size_t>(v) * width + u) * 4];
  return {px[0], px[1], px[2]};
}

bool Near(const Eigen::Vector3i& a, const Eigen::Vector3i& b, int tolerance = kTolerance) {
  return (a - b).cwiseAbs().maxCoeff() <= tolerance;
}

std::string Str(const Eigen::Vector3i& c) {
  return "(" + std::to_string(c.x()) + ", " + std::to_string(c.y()) + ", " + std::to_string(c.z()) + ")";
}

void WritePng(const std::string& path, const std::vector<uint8_t>& rgba, int width, int height) {
  cv::Mat image(height, width, CV_8UC4, const_cast<uint8_t*>(rgba.data()));
  cv::Mat bgr;
  cv::cvtColor(image, bgr, cv::COLOR_RGBA2BGR);
  cv::imwrite(path, bgr);
}

// Context + renderer + the test scene, drawn from ViewerCamera into the whole framebuffer.
class SceneTest : public ::testing::Test {
 protected:
  void SetUp() override {
    absl::StatusOr<std::unique_ptr<HeadlessContext>> context = CreateHeadlessContext(kWidth, kHeight);
    ASSERT_TRUE(context.ok()) << "headless EGL must work here: " << context.status();
    context_ = std::move(*context);
    absl::StatusOr<std::unique_ptr<Renderer>> renderer = Renderer::Create(Options());
    ASSERT_TRUE(renderer.ok()) << renderer.status();
    renderer_ = std::move(*renderer);
    mesh_ = GroundAndBox();
    ASSERT_TRUE(renderer_->SetStaticMesh(mesh_).ok());
    image_ = QuadrantImage(640, 480);
    ASSERT_TRUE(renderer_->SetProjectors({MakeProjector(projector_, image_, 1)}).ok());
  }
  void TearDown() override { renderer_.reset(); }
  virtual RendererOptions Options() const { return {}; }

  std::vector<uint8_t> RenderViewer(bool draw_frustums = false) { return RenderFrom(viewer_, draw_frustums); }

  // Replaces the fixture's projector without leaving its imagery behind as a retained snapshot.
  void ReplaceProjector(const Projector& p) {
    DisplayOptions display = renderer_->options().display;
    display.retention_half_life_s = 0;
    ASSERT_TRUE(renderer_->SetDisplayOptions(display).ok());
    ASSERT_TRUE(renderer_->SetProjectors({p}).ok());
  }

  std::vector<uint8_t> RenderFrom(const Camera& camera, bool draw_frustums = false) {
    View view = MakeView(camera, {0, 0, kWidth, kHeight});
    view.draw_frustums = draw_frustums;
    context_->BindFramebuffer();
    const absl::Status s = renderer_->Render({view}, kWidth, kHeight);
    EXPECT_TRUE(s.ok()) << s;
    absl::StatusOr<std::vector<uint8_t>> pixels = context_->ReadPixels();
    EXPECT_TRUE(pixels.ok()) << pixels.status();
    return pixels.ok() ? *pixels : std::vector<uint8_t>();
  }

  // The rendered colour of a local point seen by `camera` (which must see it unobstructed).
  Eigen::Vector3i ViewerPixel(const std::vector<uint8_t>& rgba, const Eigen::Vector3d& p) {
    return PixelSeenBy(viewer_, rgba, p);
  }
  Eigen::Vector3i PixelSeenBy(const Camera& camera, const std::vector<uint8_t>& rgba, const Eigen::Vector3d& p) {
    const std::optional<Eigen::Vector2d> uv = camera.Pixel(p);
    const bool in_image = uv && camera.InImage(*uv, 2);
    EXPECT_TRUE(in_image) << "test setup: camera does not see " << p.transpose();
    EXPECT_TRUE(SegmentIsClear(mesh_, camera.world_from_camera.translation, p))
        << "test setup: camera's line to " << p.transpose() << " blocked";
    if (!in_image) return {-1, -1, -1};
    return PixelAt(rgba, kWidth, static_cast<int>(std::lround(uv->x())), static_cast<int>(std::lround(uv->y())));
  }

  Eigen::Vector3i ShadedGround() const {
    return ToRgb255(ShadedModelColor(renderer_->options(), kGroundColor, Eigen::Vector3f::UnitZ()));
  }

  Camera projector_ = ProjectorCamera();
  Camera viewer_ = ViewerCamera();
  TriangleMesh mesh_;
  std::vector<uint8_t> image_;
  std::unique_ptr<HeadlessContext> context_;
  std::unique_ptr<Renderer> renderer_;
};

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

// ---------------------------------------------------------------------------------------------
// Issue 7: analytic truth on the `minimal` scenario, hard cases, retention, overlap, models.

std::vector<uint8_t> SolidImage(int width, int height, Eigen::Vector3i rgb);

// A smooth image (red grows to the right, green downwards) so per-pixel comparisons tolerate
// sub-pixel sampling differences.
Eigen::Vector3i GradientColor(double u, double v, int width, int height) {
  return Eigen::Vector3d(255.0 * (u + 0.5) / width, 255.0 * (v + 0.5) / height, 64).array().round().cast<int>();
}

std::vector<uint8_t> GradientImage(int width, int height) {
  std::vector<uint8_t> rgba(static_cast<size_t>(width) * height * 4);
  for (int v = 0; v < height; ++v) {
    for (int u = 0; u < width; ++u) {
      const Eigen::Vector3i c = GradientColor(u, v, width, height);
      uint8_t* px = &rgba[(static_cast<size_t>(v) * width + u) * 4];
      for (int ch = 0; ch < 3; ++ch) px[ch] = static_cast<uint8_t>(std::clamp(c[ch], 0, 255));
      px[3] = 255;
    }
  }
  return rgba;
}

// OpenCV's forward Brown-Conrady model: the distorted pixel of a point in the camera frame.
std::optional<Eigen::Vector2d> DistortedPixel(const PinholeIntrinsics& k, const std::array<double, 5>& d,
                                              const Eigen::Vector3d& p_cam) {
  if (!(p_cam.z() > 1e-6)) return std::nullopt;
  const double x = p_cam.x() / p_cam.z(), y = p_cam.y() / p_cam.z(), r2 = x * x + y * y;
  const double radial = 1 + r2 * (d[0] + r2 * (d[1] + r2 * d[4]));
  const double xd = x * radial + 2 * d[2] * x * y + d[3] * (r2 + 2 * x * x);
  const double yd = y * radial + d[2] * (r2 + 2 * y * y) + 2 * d[3] * x * y;
  return Eigen::Vector2d(k.fx * xd + k.cx, k.fy * yd + k.cy);
}

struct Truth {
  Eigen::Vector3i color{-1, -1, -1};
  int kind = 0;  // 0 model, 1 projected, 2 sky, 3 projected sky
  int surface = -1;  // triangle (or -1 for sky)
};

// What the renderer should show through a viewer pixel: ray cast (BVH) to the model or the sky
// dome, then the projector's (distorted) image where it sees that point, else the model's colour.
class TruthCaster {
 public:
  TruthCaster(const TriangleMesh& mesh, const RendererOptions& options, const Camera& projector,
              const std::array<double, 5>& distortion, double sky_radius, Eigen::Vector3f sky_color)
      : mesh_(mesh), bvh_(mesh), options_(options), projector_(projector), distortion_(distortion),
        sky_radius_(sky_radius), sky_color_(sky_color) {
    Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e30), hi = -lo;
    for (const Eigen::Vector3f& p : mesh.positions) {
      lo = lo.cwiseMin(p.cast<double>());
      hi = hi.cwiseMax(p.cast<double>());
    }
    sky_centre_ = Eigen::Vector3d(0.5 * (lo.x() + hi.x()), 0.5 * (lo.y() + hi.y()), lo.z());
  }

  Truth At(const Camera& viewer, double u, double v) const {
    const Eigen::Vector3d ray = viewer.world_from_camera.rotation * PixelRay(viewer.intrinsics, {u, v});
    const Eigen::Vector3d eye = viewer.world_from_camera.translation;
    Truth t;
    Eigen::Vector3d x, n;
    Eigen::Vector3f base;
    if (const std::optional<RayHit> hit = bvh_.Raycast(eye, ray)) {
      x = eye + hit->distance_m * ray;
      const uint32_t first = mesh_.indices[3 * hit->triangle];
      n = mesh_.normals[first].cast<double>().normalized();
      base = ShadedModelColor(options_, mesh_.colors[first], mesh_.normals[first]);
      t.surface = static_cast<int>(hit->triangle);
    } else {
      // Inside the dome: the far root of |eye + s ray - c| = R.
      const Eigen::Vector3d oc = eye - sky_centre_;
      const double b = oc.dot(ray), c = oc.squaredNorm() - sky_radius_ * sky_radius_;
      x = eye + (-b + std::sqrt(b * b - c)) * ray;
      n = (sky_centre_ - x).normalized();
      base = sky_color_;
      t.kind = 2;
    }
    t.color = ToRgb255(base);
    const Eigen::Vector3d c = projector_.world_from_camera.translation;
    const Eigen::Vector3d p_cam = projector_.world_from_camera.Inverse() * x;
    if (n.dot(c - x) <= 0 || p_cam.z() < 0.5 || p_cam.z() > 200) return t;
    const std::optional<Eigen::Vector2d> uv = DistortedPixel(projector_.intrinsics, distortion_, p_cam);
    const PinholeIntrinsics& k = projector_.intrinsics;
    if (!uv || uv->x() < -0.5 || uv->y() < -0.5 || uv->x() > k.width - 0.5 || uv->y() > k.height - 0.5) return t;
    const std::optional<RayHit> block = bvh_.Raycast(c, x - c);
    if (block && block->distance_m < (x - c).norm() - 0.05) return t;
    t.color = GradientColor(uv->x(), uv->y(), k.width, k.height);
    t.kind += 1;
    return t;
  }

 private:
  const TriangleMesh& mesh_;
  MeshBvh bvh_;
  RendererOptions options_;
  Camera projector_;
  std::array<double, 5> distortion_;
  double sky_radius_;
  Eigen::Vector3f sky_color_;
  Eigen::Vector3d sky_centre_;
};

// Every other pixel of the `minimal` scenario seen from a viewer, against the ray-cast truth.
// Pixels whose neighbours a pixel away fall on another surface or visibility class (silhouettes,
// shadow and frustum edges) are left out; everywhere else the colour must match.
class MinimalTruthTest : public ::testing::TestWithParam<bool> {};

TEST_P(MinimalTruthTest, Snapshot_MatchesRayCastProjection) {
  const bool distorted = GetParam();
  constexpr int kW = 400, kH = 300;
  const std::optional<std::string_view> text = scene::BundledScenarioText("minimal");
  ASSERT_TRUE(text);
  const absl::StatusOr<scene::SyntheticCampus> campus = scene::LoadSceneText(std::string(*text), "minimal.yaml");
  ASSERT_TRUE(campus.ok()) << campus.status();
  const TriangleMesh mesh = scene::BuildStaticMesh(*campus);
  ASSERT_FALSE(campus->cameras.empty());
  const scene::CameraSpec& cam = campus->cameras[0];
  const Camera projector{cam.intrinsics, cam.world_from_camera};
  const std::array<double, 5> distortion =
      distorted ? std::array<double, 5>{-0.18, 0.03, 0.002, -0.001, 0.0} : std::array<double, 5>{};

  absl::StatusOr<std::unique_ptr<HeadlessContext>> context = CreateHeadlessContext(kW, kH);
  ASSERT_TRUE(context.ok()) << context.status();
  RendererOptions options;
  options.sky_radius_m = 100;
  absl::StatusOr<std::unique_ptr<Renderer>> renderer = Renderer::Create(options);
  ASSERT_TRUE(renderer.ok()) << renderer.status();
  ASSERT_TRUE((*renderer)->SetStaticMesh(mesh).ok());
  // The first frame (which builds the view cache) shows other content; the second, drawn from the
  // cache with new video, is the one checked: the mapping is reused, the colours are not.
  const std::vector<uint8_t> first_image = SolidImage(cam.intrinsics.width, cam.intrinsics.height, {0, 0, 255});
  Projector p = MakeProjector(projector, first_image, 1);
  p.distortion = distortion;
  ASSERT_TRUE((*renderer)->SetProjectors({p}).ok());

  const Camera viewer{PinholeIntrinsics::FromFov(kW, kH, 80), LookAt({-22, -32, 14}, {2, 6, 3})};
  View view = MakeView(viewer, {0, 0, kW, kH});
  view.draw_frustums = false;
  (*context)->BindFramebuffer();
  ASSERT_TRUE((*renderer)->Render({view}, kW, kH).ok());
  const std::vector<uint8_t> image = GradientImage(cam.intrinsics.width, cam.intrinsics.height);
  p.image_rgba = image;
  p.image_serial = 2;
  ASSERT_TRUE((*renderer)->SetProjectors({p}).ok());
  ASSERT_TRUE((*renderer)->Render({view}, kW, kH).ok());
  EXPECT_EQ((*renderer)->stats().view_cache_builds, 1u);
  EXPECT_EQ((*renderer)->stats().view_cache_hits, 1u);
  const std::vector<uint8_t> rgba = *(*context)->ReadPixels();
  WritePng(distorted ? "/tmp/render_minimal_distorted.png" : "/tmp/render_minimal.png", rgba, kW, kH);

  const TruthCaster truth(mesh, options, projector, distortion, 100, view.clear_color);
  int compared = 0, wrong = 0;
  int by_kind[4] = {0, 0, 0, 0};
  for (int v = 1; v < kH - 1; v += 2) {
    for (int u = 1; u < kW - 1; u += 2) {
      const Truth t = truth.At(viewer, u, v);
      bool edge = false;
      for (const auto& [du, dv] : {std::pair{-1, 0}, {1, 0}, {0, -1}, {0, 1}}) {
        const Truth o = truth.At(viewer, u + du, v + dv);
        edge |= o.kind != t.kind || (o.surface < 0) != (t.surface < 0) ||
                (t.kind % 2 == 0 && !Near(o.color, t.color, 3));
      }
      if (edge) continue;
      ++compared;
      ++by_kind[t.kind];
      const Eigen::Vector3i got = PixelAt(rgba, kW, u, v);
      if (!Near(got, t.color, 12)) {
        if (wrong < 5) ADD_FAILURE() << "pixel (" << u << ", " << v << ") kind " << t.kind << ": got " << Str(got) << " expected " << Str(t.color);
        ++wrong;
      }
    }
  }
  std::printf("minimal%s: %d pixels compared (model %d, projected %d, sky %d, projected sky %d), %d differ\n",
              distorted ? " (distorted lens)" : "", compared, by_kind[0], by_kind[1], by_kind[2], by_kind[3], wrong);
  EXPECT_GT(by_kind[1] + by_kind[3], compared / 5) << "the projection must cover a good part of the view";
  EXPECT_GT(by_kind[3], compared / 20) << "imagery above the horizon lands on the sky";
  EXPECT_GT(by_kind[0], compared / 20);
  EXPECT_LE(wrong, compared / 200) << "more than 0.5 % of pixels differ from the ray-cast truth";
}

INSTANTIATE_TEST_SUITE_P(Lens, MinimalTruthTest, ::testing::Values(false, true),
                         [](const auto& info) { return info.param ? "Distorted" : "Pinhole"; });

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
  EXPECT_TRUE(Near(PixelSeenBy(west, rgba, {-3.01, -1, 4}), wall));
  EXPECT_TRUE(Near(PixelSeenBy(west, rgba, {-3.01, 1.5, 2}), wall));
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

std::vector<uint8_t> SolidImage(int width, int height, Eigen::Vector3i rgb) {
  std::vector<uint8_t> rgba(static_cast<size_t>(width) * height * 4, 255);
  for (size_t k = 0; k < rgba.size(); k += 4) {
    for (int ch = 0; ch < 3; ++ch) rgba[k + ch] = static_cast<uint8_t>(rgb[ch]);
  }
  return rgba;
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

// ---------------------------------------------------------------------------------------------
// View cache (issue 7 performance): still views reuse their G-buffer and projector mapping.

// Per-channel absolute differences of two RGBA pictures.
struct PictureDifference {
  double mean = 0;
  int max = 0;
  double share_over_2 = 0;  // share of pixels with some channel more than 2 levels apart
};

PictureDifference Compare(const std::vector<uint8_t>& a, const std::vector<uint8_t>& b) {
  PictureDifference d;
  EXPECT_EQ(a.size(), b.size());
  const size_t pixels = std::min(a.size(), b.size()) / 4;
  size_t over = 0;
  for (size_t k = 0; k < pixels; ++k) {
    int worst = 0;
    for (int ch = 0; ch < 3; ++ch) {
      const int diff = std::abs(int(a[4 * k + ch]) - int(b[4 * k + ch]));
      d.mean += diff;
      worst = std::max(worst, diff);
    }
    d.max = std::max(d.max, worst);
    over += worst > 2;
  }
  d.mean /= std::max<size_t>(1, 3 * pixels);
  d.share_over_2 = static_cast<double>(over) / std::max<size_t>(1, pixels);
  return d;
}

// The same inputs into a cached and an uncached renderer, frame after frame.
class ViewCacheTest : public SceneTest {
 protected:
  void SetUp() override {
    SceneTest::SetUp();
    RendererOptions options;
    options.view_cache = false;
    // The reference draws one pass per projector; the cached renderer draws its uncached frames
    // and model rectangles with the combined live passes: both must give the same picture.
    options.combined_live_passes = false;
    absl::StatusOr<std::unique_ptr<Renderer>> exact = Renderer::Create(options);
    ASSERT_TRUE(exact.ok()) << exact.status();
    exact_ = std::move(*exact);
    ASSERT_TRUE(exact_->SetStaticMesh(mesh_).ok());
    ASSERT_TRUE(exact_->SetProjectors({MakeProjector(projector_, image_, 1)}).ok());
  }
  void TearDown() override {
    exact_.reset();
    SceneTest::TearDown();
  }

  // Frames whose inputs changed are compared too: drawn at full resolution here.
  RendererOptions Options() const override {
    RendererOptions options;
    options.moving_view_scale = 1;
    return options;
  }

  // Applies `step` to both renderers, renders both, and checks the cached picture against the
  // exact one. Returns the cached picture.
  std::vector<uint8_t> Step(const std::function<absl::Status(Renderer&)>& step, const std::string& what) {
    EXPECT_TRUE(step(*renderer_).ok()) << what;
    EXPECT_TRUE(step(*exact_).ok()) << what;
    const std::vector<uint8_t> cached = RenderViewer(true);
    std::swap(renderer_, exact_);
    const std::vector<uint8_t> exact = RenderViewer(true);
    std::swap(renderer_, exact_);
    const PictureDifference d = Compare(cached, exact);
    EXPECT_LE(d.max, 3) << what << ": mean " << d.mean;
    EXPECT_LE(d.share_over_2, 0.001) << what;
    return cached;
  }

  std::unique_ptr<Renderer> exact_;
};

TEST_F(ViewCacheTest, CachedFramesEqualExactOnesAcrossPoliciesLensesRetentionAndMovers) {
  const Camera near_cam{PinholeIntrinsics::FromFov(640, 480, 70), LookAt({-12, 10, 6}, {-10, 6, 0})};
  const std::vector<uint8_t> gradient = GradientImage(640, 480), green = SolidImage(640, 480, {20, 200, 90});
  Projector a = MakeProjector(near_cam, gradient, 1), b = MakeProjector(projector_, image_, 1);
  a.camera_id = "near";
  auto set = [](std::vector<Projector> ps) { return [ps](Renderer& r) { return r.SetProjectors(ps); }; };
  // New content in both cameras (as live video does): swaps their images.
  uint64_t serial = 1;
  auto new_video = [&] {
    ++serial;
    a.image_serial = b.image_serial = serial;
    a.image_rgba = serial % 2 ? std::span<const uint8_t>(gradient) : std::span<const uint8_t>(image_);
    b.image_rgba = serial % 2 ? std::span<const uint8_t>(image_) : std::span<const uint8_t>(green);
    Step(set({a, b}), "new video " + std::to_string(serial));
  };
  auto clock = [](double t) {
    return [t](Renderer& r) {
      r.SetClock(t);
      return absl::OkStatus();
    };
  };
  auto display = [](OverlapPolicy overlap, bool tint) {
    return [=](Renderer& r) {
      DisplayOptions d;
      d.overlap = overlap;
      d.tint_by_age = tint;
      return r.SetDisplayOptions(d);
    };
  };
  Step(clock(10), "start");
  Step(set({a, b}), "two projectors, blend");  // changed: drawn in full
  new_video();                                  // still: the cache is built
  const RenderStats built = renderer_->stats();
  new_video();
  // A mover casting a shadow over the projected ground: the cache is reused, patched around it.
  for (double x : {-9.0, -8.0, -7.0}) {
    Step([x](Renderer& r) { return r.SetDynamicObjects({DynamicBox{{x, 6, 0}, 0.3, {1, 1, 3}, {0.2f, 0.8f, 0.2f}}}); },
         "box moving");
  }
  EXPECT_EQ(renderer_->stats().view_cache_builds, built.view_cache_builds) << "nothing but video and movers changed";
  EXPECT_EQ(renderer_->stats().view_cache_hits, built.view_cache_hits + 4);
  EXPECT_GT(renderer_->stats().view_cache_patches, built.view_cache_patches);
  for (OverlapPolicy policy : {OverlapPolicy::kBestView, OverlapPolicy::kLastWins, OverlapPolicy::kBlendBestView}) {
    Step(display(policy, false), "policy " + std::to_string(static_cast<int>(policy)));
    new_video();
  }
  a.distortion = {-0.18, 0.03, 0.002, -0.001, 0.0};
  Step(set({a, b}), "distorted lens");
  new_video();
  // Retention: b turns away, leaving a snapshot; then time passes (the fade scales in the resolve).
  Camera turned = projector_;
  turned.world_from_camera = LookAt(kProjectorEye, {-18, -30, 0});
  b = MakeProjector(turned, image_, ++serial);
  Step(set({a, b}), "turned away");
  EXPECT_EQ(renderer_->stats().retained_snapshots, 1u);
  new_video();
  const uint64_t builds = renderer_->stats().view_cache_builds;
  Step(clock(40), "half a half-life later");
  Step(clock(70), "a half-life later");
  Step(display(OverlapPolicy::kBlendBestView, true), "age tint");
  EXPECT_EQ(renderer_->stats().view_cache_builds, builds) << "fading and tint reuse the cache";
  Step([](Renderer& r) { return r.SetDynamicObjects({}); }, "movers gone");
}

// A camera turning while the view stays: the view is drawn in full each frame, its static
// G-buffer copied from its cache instead of drawn; with a box moving too, each frame must equal
// the exact renderer's (moving views at full resolution here, so the copy is one to one).
TEST_F(ViewCacheTest, TurningCameraReusesTheViewsStaticGbuffer) {
  const Camera near_cam{PinholeIntrinsics::FromFov(640, 480, 70), LookAt({-12, 10, 6}, {-10, 6, 0})};
  const std::vector<uint8_t> gradient = GradientImage(640, 480);
  Projector a = MakeProjector(near_cam, gradient, 1);
  a.camera_id = "near";
  auto set = [&](double yaw_deg) {
    Camera turned = projector_;
    turned.world_from_camera.rotation =
        Eigen::Quaterniond(Eigen::AngleAxisd(yaw_deg * M_PI / 180, Eigen::Vector3d::UnitZ())) *
        projector_.world_from_camera.rotation;
    const std::vector<Projector> ps = {a, MakeProjector(turned, image_, 1)};
    return [ps](Renderer& r) { return r.SetProjectors(ps); };
  };
  Step(set(0), "two projectors");
  Step(set(0), "still: built");
  const RenderStats built = renderer_->stats();
  for (int f = 1; f <= 3; ++f) {
    const double x = -10.0 + f;
    auto turn = set(-2.0 * f);
    Step(
        [x, turn](Renderer& r) {
          if (absl::Status s = r.SetDynamicObjects({DynamicBox{{x, 6, 0}, 0.3, {1, 1, 3}, {0.2f, 0.8f, 0.2f}}});
              !s.ok()) {
            return s;
          }
          return turn(r);
        },
        "turning with a box moving, frame " + std::to_string(f));
  }
  const RenderStats after = renderer_->stats();
  EXPECT_GE(after.views_static_from_cache, built.views_static_from_cache + 3);
  EXPECT_EQ(after.view_cache_builds, built.view_cache_builds) << "the turn rebuilds nothing";
}

// Hard case for the shadow volumes: a model around a camera's eye (the person carrying the
// backpack camera), its corners behind the camera, so its shadow-map rectangle is the whole map and
// its volume starts at the near plane; and a model far off to the side of every frustum. Cached
// frames must still equal exact ones.
TEST_F(ViewCacheTest, ModelAroundACameraEyeMatchesExact) {
  const Camera near_cam{PinholeIntrinsics::FromFov(640, 480, 70), LookAt({-12, 10, 6}, {-10, 6, 0})};
  const std::vector<uint8_t> gradient = GradientImage(640, 480);  // outlives the projectors' spans
  Projector a = MakeProjector(near_cam, gradient, 1);
  a.camera_id = "near";
  const std::vector<Projector> ps = {a, MakeProjector(projector_, image_, 1)};
  auto set = [ps](Renderer& r) { return r.SetProjectors(ps); };
  Step(set, "two projectors");
  Step(set, "still: built");
  const RenderStats built = renderer_->stats();
  for (double dz : {-0.5, 0.0, 0.5}) {
    Step(
        [dz](Renderer& r) {
          return r.SetDynamicObjects({DynamicBox{{-12, 10, 5 + dz}, 0.0, {1.2, 1.2, 2}, {0.8f, 0.2f, 0.2f}},
                                      DynamicBox{{-9, 6, 0}, 0.3, {1, 1, 3}, {0.2f, 0.8f, 0.2f}},
                                      DynamicBox{{500, -500, 0}, 0.3, {1, 1, 2}, {0.2f, 0.2f, 0.8f}}});
        },
        "box around the near camera's eye, z offset " + std::to_string(dz));
  }
  // The far model grows the scene box the projector volumes are cut to: one rebuild, then hits.
  EXPECT_LE(renderer_->stats().view_cache_builds, built.view_cache_builds + 1);
  EXPECT_GT(renderer_->stats().view_cache_shadow_tests, built.view_cache_shadow_tests);
}

// More live cameras in the view than a pixel keeps entries (5 > 4): the models' shadow test first
// keeps the pixels with an entry the box may hide (the entries pass), then tests them. No pixel
// sees more than 3 of the cameras, so the cached picture must still equal the exact one.
TEST_F(ViewCacheTest, MoverShadowsMatchExactWithMoreCamerasThanEntries) {
  const std::vector<uint8_t> gradient = GradientImage(640, 480), green = SolidImage(640, 480, {20, 200, 90});
  std::vector<Projector> projectors = {
      MakeProjector({PinholeIntrinsics::FromFov(640, 480, 70), LookAt({-12, 10, 6}, {-10, 6, 0})}, gradient, 1),
      MakeProjector(projector_, image_, 1)};
  const std::array<std::pair<Eigen::Vector3d, Eigen::Vector3d>, 3> narrow = {
      std::pair{Eigen::Vector3d(10, 12, 8), Eigen::Vector3d(12, 14, 0)},
      std::pair{Eigen::Vector3d(12, -12, 8), Eigen::Vector3d(14, -14, 0)},
      std::pair{Eigen::Vector3d(-14, -14, 8), Eigen::Vector3d(-15, -16, 0)}};
  for (const auto& [eye, at] : narrow) {
    projectors.push_back(MakeProjector({PinholeIntrinsics::FromFov(640, 480, 20), LookAt(eye, at)}, green, 1));
  }
  for (size_t k = 0; k < projectors.size(); ++k) projectors[k].camera_id = "cam" + std::to_string(k);
  uint64_t serial = 1;
  auto set = [&](Renderer& r) {
    for (Projector& p : projectors) p.image_serial = serial;
    return r.SetProjectors(projectors);
  };
  Step(set, "five projectors");
  ++serial;
  Step(set, "still: the cache is built");
  const RenderStats built = renderer_->stats();
  for (double x : {-9.0, -8.0, -7.0}) {
    ++serial;
    Step(set, "new video");
    Step([x](Renderer& r) { return r.SetDynamicObjects({DynamicBox{{x, 6, 0}, 0.3, {1, 1, 3}, {0.2f, 0.8f, 0.2f}}}); },
         "box at x " + std::to_string(x));
  }
  const RenderStats after = renderer_->stats();
  EXPECT_EQ(after.view_cache_builds, built.view_cache_builds) << "nothing but video and the mover changed";
  EXPECT_GT(after.view_cache_entry_marks, built.view_cache_entry_marks) << "the entries pass ran";
  EXPECT_GT(after.view_cache_shadow_tests, built.view_cache_shadow_tests);
}

// A moving view that sees more live cameras than moving_view_cameras is reduced further: the
// linear depth read back shows it (one value per block of scale x scale pixels on the ground: equal
// vertical neighbours 1/2 of the time at half resolution, 3/4 at a quarter).
TEST_F(SceneTest, MovingView_ReducedFurtherWhenItSeesManyCameras) {
  auto equal_neighbours = [&](int moving_view_cameras) {
    RendererOptions options;
    options.moving_view_cameras = moving_view_cameras;
    absl::StatusOr<std::unique_ptr<Renderer>> r = Renderer::Create(options);
    EXPECT_TRUE(r.ok()) << r.status();
    EXPECT_TRUE((*r)->SetStaticMesh(mesh_).ok());
    std::vector<Projector> projectors;
    for (int k = 0; k < 4; ++k) {
      projectors.push_back(MakeProjector(projector_, image_, 1));
      projectors.back().camera_id = "cam" + std::to_string(k);
    }
    EXPECT_TRUE((*r)->SetProjectors(projectors).ok());
    Camera moving = viewer_;
    std::vector<float> depth;
    for (int step = 0; step < 3; ++step) {
      moving.world_from_camera.translation += Eigen::Vector3d(0.2, 0.1, 0);
      const View view = MakeView(moving, {0, 0, kWidth, kHeight});
      context_->BindFramebuffer();
      EXPECT_TRUE((*r)->Render({view}, kWidth, kHeight).ok());
      depth = *(*r)->ReadLinearDepth(view);
    }
    EXPECT_EQ((*r)->stats().views_reduced, 2u);
    size_t equal = 0, pairs = 0;
    for (int y = 0; y + 1 < kHeight; ++y) {  // vertical pairs (a level camera: depth is constant along rows)
      for (int x = 0; x < kWidth; ++x) {
        const float a = depth[y * kWidth + x], b = depth[(y + 1) * kWidth + x];
        if (!std::isfinite(a) || !std::isfinite(b)) continue;
        ++pairs;
        equal += a == b;
      }
    }
    return static_cast<double>(equal) / std::max<size_t>(1, pairs);
  };
  const double few = equal_neighbours(8), many = equal_neighbours(1);
  EXPECT_GT(few, 0.4) << "half resolution";
  std::printf("equal vertical neighbours: %.3f (threshold 8), %.3f (threshold 1)\n", few, many);
  EXPECT_LT(few, 0.6) << "4 cameras, threshold 8: half resolution";
  EXPECT_GT(many, 0.7) << "4 cameras, threshold 1: a quarter";
  RendererOptions bad;
  bad.moving_view_cameras = 0;
  EXPECT_NE(bad.Check().find("moving_view_cameras"), std::string::npos);
}

// A view that moves every frame is drawn at half resolution (moving_view_scale 2) and scaled up;
// the first frame it stays still is drawn in full (the cache build), as the exact renderer does.
TEST_F(SceneTest, MovingView_DrawnAtReducedResolutionThenInFullWhenStill) {
  RendererOptions exact_options;
  exact_options.view_cache = false;
  absl::StatusOr<std::unique_ptr<Renderer>> exact = Renderer::Create(exact_options);
  ASSERT_TRUE(exact.ok()) << exact.status();
  ASSERT_TRUE((*exact)->SetStaticMesh(mesh_).ok());
  ASSERT_TRUE((*exact)->SetProjectors({MakeProjector(projector_, image_, 1)}).ok());
  auto render = [&](Renderer& r, const Camera& camera, std::vector<float>* depth) {
    const View view = MakeView(camera, {0, 0, kWidth, kHeight});
    context_->BindFramebuffer();
    EXPECT_TRUE(r.Render({view}, kWidth, kHeight).ok());
    absl::StatusOr<std::vector<uint8_t>> pixels = context_->ReadPixels();
    EXPECT_TRUE(pixels.ok());
    if (depth) *depth = *r.ReadLinearDepth(view);
    return pixels.ok() ? *pixels : std::vector<uint8_t>();
  };
  Camera moving = viewer_;
  render(*renderer_, moving, nullptr);  // first frame: counts as still, full resolution
  EXPECT_EQ(renderer_->stats().views_reduced, 0u);
  for (int step = 1; step <= 3; ++step) {
    moving.world_from_camera.translation += Eigen::Vector3d(0.2, 0.1, 0);
    std::vector<float> depth, exact_depth;
    const std::vector<uint8_t> fast = render(*renderer_, moving, &depth);
    const std::vector<uint8_t> full = render(**exact, moving, &exact_depth);
    EXPECT_EQ(renderer_->stats().views_reduced, static_cast<uint64_t>(step));
    const PictureDifference d = Compare(fast, full);
    // Nearest upscaling: edges move by up to a pixel, flat areas agree.
    EXPECT_GT(d.max, 3) << "step " << step << ": drawn in full, not reduced";
    EXPECT_LT(d.mean, 3.0) << "step " << step;
    EXPECT_LT(d.share_over_2, 0.1) << "step " << step;
    ASSERT_EQ(depth.size(), exact_depth.size());
    size_t far_off = 0;
    for (size_t k = 0; k < depth.size(); ++k) {
      const bool both_inf = std::isinf(depth[k]) && std::isinf(exact_depth[k]);
      far_off += !both_inf && !(std::abs(depth[k] - exact_depth[k]) < 0.05f * exact_depth[k] + 0.05f);
    }
    EXPECT_LT(static_cast<double>(far_off) / depth.size(), 0.02) << "step " << step << ": linear depth";
  }
  const std::vector<uint8_t> still = render(*renderer_, moving, nullptr);  // still: full resolution
  EXPECT_EQ(renderer_->stats().views_reduced, 3u);
  const PictureDifference d = Compare(still, render(**exact, moving, nullptr));
  EXPECT_LE(d.max, 3);
}

TEST_F(SceneTest, ViewCache_RebuildsExactlyWhenItsInputsChange) {
  RenderStats last;
  // A change: that frame is drawn in full, the next (inputs as before) builds the cache; no
  // change: a hit.
  auto expect = [&](bool changed, const std::string& what) {
    RenderViewer(true);
    RenderStats s = renderer_->stats();
    if (changed) {
      EXPECT_EQ(s.views_uncached, last.views_uncached + 1) << what;
      EXPECT_EQ(s.view_cache_builds, last.view_cache_builds) << what;
      RenderViewer(true);
      s = renderer_->stats();
      EXPECT_EQ(s.view_cache_builds, last.view_cache_builds + 1) << what << ": built once still";
    } else {
      EXPECT_EQ(s.view_cache_hits, last.view_cache_hits + 1) << what;
      EXPECT_EQ(s.view_cache_builds, last.view_cache_builds) << what;
    }
    last = s;
  };
  RenderViewer(true);
  EXPECT_EQ(renderer_->stats().view_cache_builds, 1u) << "the first frame builds";
  last = renderer_->stats();
  expect(false, "still");
  ASSERT_TRUE(renderer_->SetProjectors({MakeProjector(projector_, image_, 2)}).ok());
  expect(false, "new video content");
  ASSERT_TRUE(renderer_->SetDynamicObjects({DynamicBox{{-8, 6, 0}, 0, {1, 1, 2}, {0.2f, 0.8f, 0.2f}}}).ok());
  expect(false, "a mover");
  EXPECT_GT(renderer_->stats().view_cache_patches, 0u);
  DisplayOptions display;
  display.tint_by_age = true;
  ASSERT_TRUE(renderer_->SetDisplayOptions(display).ok());
  expect(false, "age tint (resolve only)");
  display.seam_feather = 0.2;
  ASSERT_TRUE(renderer_->SetDisplayOptions(display).ok());
  expect(true, "seam feather");
  Camera moved = projector_;
  moved.world_from_camera.translation.x() += 0.5;
  ReplaceProjector(MakeProjector(moved, {}, 2));
  expect(true, "projector moved (and retention off)");
  Projector disabled = MakeProjector(moved, {}, 2);
  disabled.enabled = false;
  ASSERT_TRUE(renderer_->SetProjectors({disabled}).ok());
  expect(true, "projector disabled");
  ASSERT_TRUE(renderer_->SetProjectors({MakeProjector(moved, {}, 2)}).ok());
  expect(true, "projector enabled");
  ASSERT_TRUE(renderer_->SetProjectors({}).ok());
  expect(true, "projector removed");
  EXPECT_TRUE(Near(ViewerPixel(RenderViewer(true), {-8, 0, 0}), ShadedGround())) << "no video once it is gone";
  last = renderer_->stats();
  viewer_.world_from_camera.translation.z() += 0.1;
  expect(true, "view moved");
  ASSERT_TRUE(renderer_->SetStaticMesh(mesh_).ok());
  expect(true, "static model replaced");
  // A view moving every frame is drawn in full and never builds.
  for (int f = 0; f < 3; ++f) {
    viewer_.world_from_camera.translation.z() += 0.1;
    RenderViewer(true);
  }
  EXPECT_EQ(renderer_->stats().view_cache_builds, last.view_cache_builds);
  EXPECT_EQ(renderer_->stats().views_uncached, last.views_uncached + 3);
}

TEST_F(SceneTest, ViewCache_OffOrOverlappingViewsDrawInFull) {
  RendererOptions options;
  options.view_cache = false;
  absl::StatusOr<std::unique_ptr<Renderer>> uncached = Renderer::Create(options);
  ASSERT_TRUE(uncached.ok());
  ASSERT_TRUE((*uncached)->SetStaticMesh(mesh_).ok());
  ASSERT_TRUE((*uncached)->SetProjectors({MakeProjector(projector_, image_, 1)}).ok());
  std::swap(renderer_, *uncached);
  RenderViewer();
  RenderViewer();
  EXPECT_EQ(renderer_->stats().view_cache_builds + renderer_->stats().view_cache_hits, 0u);
  EXPECT_EQ(renderer_->stats().views_uncached, 2u);
  std::swap(renderer_, *uncached);
  const View whole = MakeView(viewer_, {0, 0, kWidth, kHeight});
  const View inset = MakeView(projector_, {10, 10, 200, 150});
  context_->BindFramebuffer();
  ASSERT_TRUE(renderer_->Render({whole, inset}, kWidth, kHeight).ok());
  EXPECT_EQ(renderer_->stats().views_uncached, 2u);
  EXPECT_EQ(renderer_->stats().view_cache_builds, 0u);
}

// Fused poses wobble: a still camera whose pose moves its image by far less than a pixel keeps its
// shadow map and the view caches; a real move (or any change with the tolerance off) does not.
TEST_F(SceneTest, PoseJitter_StillCameraKeepsShadowMapAndViewCache) {
  auto jitter_frames = [&](Renderer& r, int frames) {
    Camera jittered = projector_;
    for (int f = 0; f < frames; ++f) {
      const double sign = f % 2 ? 1 : -1;
      jittered.world_from_camera.translation = projector_.world_from_camera.translation + sign * Eigen::Vector3d(1e-4, -1e-4, 5e-5);
      jittered.world_from_camera.rotation =
          Eigen::Quaterniond(Eigen::AngleAxisd(sign * 2e-5, Eigen::Vector3d::UnitZ())) * projector_.world_from_camera.rotation;
      ASSERT_TRUE(r.SetProjectors({MakeProjector(jittered, image_, 10 + f)}).ok());
      RenderViewer();
    }
  };
  RenderViewer();
  const RenderStats still = renderer_->stats();
  jitter_frames(*renderer_, 4);
  EXPECT_EQ(renderer_->stats().shadow_map_renders, still.shadow_map_renders);
  EXPECT_EQ(renderer_->stats().view_cache_builds, still.view_cache_builds);
  EXPECT_EQ(renderer_->stats().view_cache_hits, still.view_cache_hits + 4);
  Camera moved = projector_;
  moved.world_from_camera.translation.x() += 0.05;  // ~2 px at 12 m
  ASSERT_TRUE(renderer_->SetProjectors({MakeProjector(moved, image_, 20)}).ok());
  RenderViewer();
  EXPECT_EQ(renderer_->stats().shadow_map_renders, still.shadow_map_renders + 1);

  RendererOptions options;
  options.still_pose_tolerance_px = 0;
  absl::StatusOr<std::unique_ptr<Renderer>> strict = Renderer::Create(options);
  ASSERT_TRUE(strict.ok());
  ASSERT_TRUE((*strict)->SetStaticMesh(mesh_).ok());
  std::swap(renderer_, *strict);
  jitter_frames(*renderer_, 3);
  EXPECT_EQ(renderer_->stats().shadow_map_renders, 3u) << "tolerance 0: every wobble redraws";
  std::swap(renderer_, *strict);
  options.still_pose_tolerance_px = -1;
  EXPECT_THAT(std::string(Renderer::Create(options).status().message()), HasSubstr("still_pose_tolerance_px"));
}

}  // namespace
}  // namespace ave::viewer
