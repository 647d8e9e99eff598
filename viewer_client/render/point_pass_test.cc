// The point pass (issue 16): a point cloud lands on the pinhole pixels of its points in their
// colours, the static model hides points behind it, an empty cloud draws nothing, and the cached
// view path agrees with the exact one while points are drawn.
#include "viewer_client/render/render_test_scene.h"

namespace ave::viewer {
namespace {

using namespace ::ave::viewer::render_test;  // NOLINT: the shared scene and helpers of the render tests
using ::testing::HasSubstr;

constexpr float kPointSizePx = 5;

Eigen::Vector3f IdColorForTest(int k) { return k == 0 ? Eigen::Vector3f(1, 0.4f, 0) : Eigen::Vector3f(0, 0.6f, 1); }

PointCloud CloudOf(const std::vector<Eigen::Vector3d>& points, const std::vector<Eigen::Vector3f>& colors) {
  PointCloud cloud;
  for (const Eigen::Vector3d& p : points) cloud.positions_local_m.push_back(p.cast<float>());
  cloud.colors = colors;
  cloud.point_size_px = kPointSizePx;
  return cloud;
}

TEST_F(SceneTest, Points_LandOnTheirPinholePixelsInTheirColours) {
  // On the ground, in the projector's video and off it, and one in the air beside the building:
  // points receive no video, so each pixel is the point's own colour.
  const std::vector<Eigen::Vector3d> points = {{-8, 4, 0.2}, {10, 10, 1.0}, {-12, -6, 0.5}, {6, 12, 4.0}};
  const std::vector<Eigen::Vector3f> colors = {
      {0.0f, 1.0f, 1.0f}, {1.0f, 0.5f, 0.0f}, {0.5f, 0.0f, 1.0f}, {0.2f, 0.9f, 0.3f}};
  const std::vector<uint8_t> before = RenderViewer();
  ASSERT_TRUE(renderer_->SetPointCloud(CloudOf(points, colors)).ok());
  const std::vector<uint8_t> after = RenderViewer();
  for (size_t k = 0; k < points.size(); ++k) {
    const Eigen::Vector3i expected = ToRgb255(colors[k]);
    EXPECT_TRUE(Near(ViewerPixel(after, points[k]), expected))
        << "point " << k << " at " << points[k].transpose() << ": " << Str(ViewerPixel(after, points[k])) << " want "
        << Str(expected);
    // The square is kPointSizePx wide around that pixel: 5 pixels away the scene shows again.
    const Eigen::Vector2d uv = *viewer_.Pixel(points[k]);
    for (const Eigen::Vector2i& step : {Eigen::Vector2i(5, 0), Eigen::Vector2i(0, 5), Eigen::Vector2i(-5, 0)}) {
      const int u = static_cast<int>(std::lround(uv.x())) + step.x(), v = static_cast<int>(std::lround(uv.y())) + step.y();
      EXPECT_EQ(PixelAt(after, kWidth, u, v), PixelAt(before, kWidth, u, v)) << "point " << k << " is too large";
    }
  }
  // Nothing else changed: only the points' squares differ.
  size_t changed = 0;
  for (size_t i = 0; i < after.size(); i += 4) changed += !std::equal(&after[i], &after[i] + 3, &before[i]);
  EXPECT_GT(changed, points.size() * 9);
  EXPECT_LE(changed, points.size() * (kPointSizePx + 1) * (kPointSizePx + 1));
}

TEST_F(SceneTest, Points_BehindTheBuildingAreHidden) {
  // The box spans x, y in [-3, 3] and z in [0, 8]; from the viewer at (-5, 35, 35) its wall at
  // y = 3 lies between the eye and this point.
  const Eigen::Vector3d hidden(0, -5, 1);
  ASSERT_FALSE(SegmentIsClear(mesh_, viewer_.world_from_camera.translation, hidden)) << "test setup";
  const std::optional<Eigen::Vector2d> uv = viewer_.Pixel(hidden);
  ASSERT_TRUE(uv && viewer_.InImage(*uv, 10)) << "test setup: the point's pixel is in the picture";
  const Eigen::Vector3d seen(0, 6, 1);  // in front of the same wall
  ASSERT_TRUE(SegmentIsClear(mesh_, viewer_.world_from_camera.translation, seen)) << "test setup";
  const std::vector<uint8_t> before = RenderViewer();
  ASSERT_TRUE(renderer_->SetPointCloud(CloudOf({hidden, seen}, {{1, 0, 1}, {1, 0, 1}})).ok());
  const std::vector<uint8_t> after = RenderViewer();
  const int u = static_cast<int>(std::lround(uv->x())), v = static_cast<int>(std::lround(uv->y()));
  EXPECT_EQ(PixelAt(after, kWidth, u, v), PixelAt(before, kWidth, u, v)) << "the wall hides the point";
  EXPECT_FALSE(Near(PixelAt(after, kWidth, u, v), {255, 0, 255}));
  EXPECT_TRUE(Near(ViewerPixel(after, seen), {255, 0, 255})) << "the point in front of the wall shows";
}

TEST_F(SceneTest, Points_EmptyCloudDrawsNothingAndBadCloudsAreRefused) {
  const std::vector<uint8_t> none = RenderViewer();
  ASSERT_TRUE(renderer_->SetPointCloud(CloudOf({{-8, 4, 0.2}}, {{0, 1, 1}})).ok());
  EXPECT_NE(RenderViewer(), none);
  ASSERT_TRUE(renderer_->SetPointCloud({}).ok());
  EXPECT_EQ(RenderViewer(), none) << "an empty cloud removes the points";
  // View::draw_points off: not drawn in that view.
  ASSERT_TRUE(renderer_->SetPointCloud(CloudOf({{-8, 4, 0.2}}, {{0, 1, 1}})).ok());
  View view = MakeView(viewer_, {0, 0, kWidth, kHeight});
  view.draw_frustums = false;
  view.draw_points = false;
  context_->BindFramebuffer();
  ASSERT_TRUE(renderer_->Render({view}, kWidth, kHeight).ok());
  EXPECT_EQ(*context_->ReadPixels(), none);

  PointCloud mismatched = CloudOf({{0, 0, 0}, {1, 1, 1}}, {{1, 1, 1}});
  EXPECT_THAT(std::string(renderer_->SetPointCloud(mismatched).message()), HasSubstr("2 positions but 1 colours"));
  PointCloud nan = CloudOf({{0, 0, 0}, {1, 1, 1}}, {{1, 1, 1}, {1, 1, 1}});
  nan.positions_local_m[1].y() = std::numeric_limits<float>::quiet_NaN();
  EXPECT_THAT(std::string(renderer_->SetPointCloud(nan).message()), HasSubstr("point 1 is not finite"));
  PointCloud tiny = CloudOf({{0, 0, 0}}, {{1, 1, 1}});
  tiny.point_size_px = 0;
  EXPECT_THAT(std::string(renderer_->SetPointCloud(tiny).message()), HasSubstr("point_size_px"));
}

// Points are drawn after the resolve, over the cached and the exact path alike: a cached renderer
// and one without the cache give the same pictures frame after frame while the cloud moves and a
// model is patched over the cached view.
class PointCacheTest : public SceneTest {
 protected:
  RendererOptions Options() const override {
    RendererOptions options;
    options.moving_view_scale = 1;
    return options;
  }
};

TEST_F(PointCacheTest, CachedViewsAgreeWithExactOnesWithPoints) {
  RendererOptions exact_options;
  exact_options.view_cache = false;
  absl::StatusOr<std::unique_ptr<Renderer>> made = Renderer::Create(exact_options);
  ASSERT_TRUE(made.ok()) << made.status();
  std::unique_ptr<Renderer> exact = std::move(*made);
  ASSERT_TRUE(exact->SetStaticMesh(mesh_).ok());
  ASSERT_TRUE(exact->SetProjectors({MakeProjector(projector_, image_, 1)}).ok());
  for (int frame = 0; frame < 5; ++frame) {
    // A person's worth of points walking past the building, and a box beside them.
    std::vector<Eigen::Vector3d> points;
    std::vector<Eigen::Vector3f> colors;
    for (int k = 0; k < 40; ++k) {
      points.emplace_back(-10 + frame + 0.05 * (k % 5), 6 + 0.05 * (k / 5 % 4), 0.1 + 0.04 * k);
      colors.emplace_back(IdColorForTest(k / 20));
    }
    const PointCloud cloud = CloudOf(points, colors);
    const DynamicBox box{{-6.0 + frame, 8, 0}, 0.3, {1, 1, 2}, {0.2f, 0.8f, 0.2f}};
    for (Renderer* r : {renderer_.get(), exact.get()}) {
      ASSERT_TRUE(r->SetPointCloud(cloud).ok());
      ASSERT_TRUE(r->SetDynamicObjects({box}).ok());
    }
    const std::vector<uint8_t> cached = RenderViewer(true);
    std::swap(renderer_, exact);
    const std::vector<uint8_t> reference = RenderViewer(true);
    std::swap(renderer_, exact);
    const PictureDifference d = Compare(cached, reference);
    EXPECT_LE(d.max, 3) << "frame " << frame << ": mean " << d.mean;
    EXPECT_LE(d.share_over_2, 0.001) << "frame " << frame;
    EXPECT_TRUE(Near(ViewerPixel(cached, points[0]), ToRgb255(colors[0]))) << "frame " << frame;
  }
  EXPECT_GE(renderer_->stats().view_cache_hits, 3u) << "the cached path was taken";
  EXPECT_GT(renderer_->stats().view_cache_patches, 0u);
  exact.reset();
}

}  // namespace
}  // namespace ave::viewer
