#pragma once
// Shared by the render tests (renderer_test.cc, renderer_truth_test.cc, renderer_cases_test.cc,
// view_cache_test.cc): a flat ground square, one box building and one projector looking down at
// it obliquely, rendered headless (EGL, Mesa llvmpipe; no EGL is a failure), and picture helpers.
#include <algorithm>
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
#ifndef AVE_TEST_NO_IMGCODECS
#include <opencv2/imgcodecs.hpp>
#endif

#include "model_store/geometry/bvh.h"
#include "model_store/geometry/camera.h"
#include "model_store/geometry/raycast.h"
#include "model_store/scene/campus.h"
#include "model_store/scene/scene_file.h"
#include "viewer_client/render/gl_context.h"
#include "viewer_client/render/renderer.h"
#include "viewer_client/render/shader_program.h"

namespace ave::viewer::render_test {


inline constexpr int kWidth = 640;
inline constexpr int kHeight = 480;
const Eigen::Vector3f kGroundColor(0.5f, 0.5f, 0.5f);
const Eigen::Vector3f kFrustumColor(1.0f, 0.0f, 1.0f);
const Eigen::Vector3d kProjectorEye(-18, 0, 12);
const Eigen::Vector3d kViewerEye(-5, 35, 35);
inline constexpr int kTolerance = 10;  // per channel, of 255

// Quadrants of the projected image, top row first: top-left red, top-right green, bottom-left
// blue, bottom-right yellow. A wrong flip or mirror lands on another colour.
inline Eigen::Vector3i QuadrantColor(double u, double v, int width, int height) {
  const bool left = u < 0.5 * width, top = v < 0.5 * height;
  if (top) return left ? Eigen::Vector3i(255, 0, 0) : Eigen::Vector3i(0, 255, 0);
  return left ? Eigen::Vector3i(0, 0, 255) : Eigen::Vector3i(255, 255, 0);
}

// An opaque RGBA image whose pixel (u, v) (column, row from the top) has color(u, v, width, height).
inline std::vector<uint8_t> ImageOf(int width, int height,
                                    const std::function<Eigen::Vector3i(double, double, int, int)>& color) {
  std::vector<uint8_t> rgba(static_cast<size_t>(width) * height * 4);
  for (int v = 0; v < height; ++v) {
    for (int u = 0; u < width; ++u) {
      const Eigen::Vector3i c = color(u, v, width, height);
      uint8_t* px = &rgba[(static_cast<size_t>(v) * width + u) * 4];
      for (int ch = 0; ch < 3; ++ch) px[ch] = static_cast<uint8_t>(std::clamp(c[ch], 0, 255));
      px[3] = 255;
    }
  }
  return rgba;
}

inline std::vector<uint8_t> QuadrantImage(int width, int height) { return ImageOf(width, height, QuadrantColor); }

inline TriangleMesh GroundAndBox() {
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

inline Camera ProjectorCamera() { return {PinholeIntrinsics::FromFov(640, 480, 70), LookAt(kProjectorEye, {2, 0, 0})}; }
inline Camera ViewerCamera() { return {PinholeIntrinsics::FromFov(kWidth, kHeight, 80), LookAt(kViewerEye, {0, -2, 0})}; }

inline Projector MakeProjector(const Camera& cam, const std::vector<uint8_t>& image, uint64_t serial) {
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

inline View MakeView(const Camera& cam, Viewport viewport) {
  View v;
  v.viewport = viewport;
  v.view = GlViewFromWorld(cam.world_from_camera);
  v.projection = GlProjection(cam.intrinsics, 0.5, 300);
  return v;
}

inline Eigen::Vector3i ToRgb255(const Eigen::Vector3f& c) { return (c * 255.0f).array().round().cast<int>(); }

inline Eigen::Vector3i PixelAt(const std::vector<uint8_t>& rgba, int width, int u, int v) {
  const uint8_t* px = &rgba[(static_cast<size_t>(v) * width + u) * 4];
  return {px[0], px[1], px[2]};
}

inline bool Near(const Eigen::Vector3i& a, const Eigen::Vector3i& b, int tolerance = kTolerance) {
  return (a - b).cwiseAbs().maxCoeff() <= tolerance;
}

inline std::string Str(const Eigen::Vector3i& c) {
  std::string s = "(";
  s += std::to_string(c.x()) + ", " + std::to_string(c.y()) + ", " + std::to_string(c.z()) + ")";
  return s;
}

// ave-render-test-gpu (the GPU machine's build, no image codecs: they pull GDAL) writes none.
inline void WritePng(const std::string& path, const std::vector<uint8_t>& rgba, int width, int height) {
#ifdef AVE_TEST_NO_IMGCODECS
  (void)rgba, (void)width, (void)height;
  std::fprintf(stderr, "built without PNG output: '%s' not written\n", path.c_str());
#else
  cv::Mat image(height, width, CV_8UC4, const_cast<uint8_t*>(rgba.data()));
  cv::Mat bgr;
  cv::cvtColor(image, bgr, cv::COLOR_RGBA2BGR);
  cv::imwrite(path, bgr);
#endif
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

// A uniform image.
inline std::vector<uint8_t> SolidImage(int width, int height, Eigen::Vector3i rgb) {
  std::vector<uint8_t> rgba(static_cast<size_t>(width) * height * 4, 255);
  for (size_t k = 0; k < rgba.size(); k += 4) {
    for (int ch = 0; ch < 3; ++ch) rgba[k + ch] = static_cast<uint8_t>(rgb[ch]);
  }
  return rgba;
}

// A smooth image (red grows to the right, green downwards) so per-pixel comparisons tolerate
// sub-pixel sampling differences.
inline Eigen::Vector3i GradientColor(double u, double v, int width, int height) {
  return Eigen::Vector3d(255.0 * (u + 0.5) / width, 255.0 * (v + 0.5) / height, 64).array().round().cast<int>();
}

inline std::vector<uint8_t> GradientImage(int width, int height) { return ImageOf(width, height, GradientColor); }

// Per-channel absolute differences of two RGBA pictures.
struct PictureDifference {
  double mean = 0;
  int max = 0;
  double share_over_2 = 0;  // share of pixels with some channel more than 2 levels apart
};

inline PictureDifference Compare(const std::vector<uint8_t>& a, const std::vector<uint8_t>& b) {
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


}  // namespace ave::viewer::render_test
