// View cache (issue 7 performance): still views reuse their G-buffer and projector mapping; cached
// frames equal exact ones; moving views are drawn reduced; pose jitter keeps caches.
#include "viewer_client/render/render_test_scene.h"

namespace ave::viewer {
namespace {

using namespace ::ave::viewer::render_test;  // NOLINT: the shared scene and helpers of the render tests
using ::testing::HasSubstr;

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
