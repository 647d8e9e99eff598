// The avatar pass (issue 17): an avatar lands on the pixels the pinhole model predicts and faces
// its heading; projected video lands on avatars, and with video_on_people off (the privacy
// export) no video pixel lands on any of them, in the exact and the cached view paths.
#include "model_store/avatar/procedural_avatar.h"
#include "viewer_client/render/render_test_scene.h"

namespace ave::viewer {
namespace {

using namespace ::ave::viewer::render_test;  // NOLINT: the shared scene and helpers of the render tests
using ::testing::HasSubstr;

const Eigen::Vector3i kMagenta(255, 0, 255);

bool IsMagenta(const Eigen::Vector3i& c) { return c.x() > 150 && c.z() > 150 && c.y() < 90; }
bool IsGreen(const Eigen::Vector3i& c) { return c.y() > c.x() + 40 && c.y() > c.z() + 40; }

Eigen::Vector3d OnAvatar(const Eigen::Vector3d& base, double heading_rad, const Eigen::Vector3d& p_in_avatar) {
  const double c = std::cos(heading_rad), s = std::sin(heading_rad);
  return base + Eigen::Vector3d(c * p_in_avatar.x() - s * p_in_avatar.y(), s * p_in_avatar.x() + c * p_in_avatar.y(),
                                p_in_avatar.z());
}

class AvatarTest : public SceneTest {
 protected:
  void SetUp() override {
    SceneTest::SetUp();
    ASSERT_TRUE(renderer_->SetAvatarSequence(avatar::MakeProceduralWalk()).ok());
  }
  void NoVideo() {
    DisplayOptions display = renderer_->options().display;
    display.retention_half_life_s = 0;
    ASSERT_TRUE(renderer_->SetDisplayOptions(display).ok());
    ASSERT_TRUE(renderer_->SetProjectors({}).ok());
  }
  void VideoOnPeople(bool on) {
    DisplayOptions display = renderer_->options().display;
    display.video_on_people = on;
    ASSERT_TRUE(renderer_->SetDisplayOptions(display).ok());
  }
  // Pixels of `camera` whose linear depth is nearer than in `before` (what the avatars cover).
  std::vector<Eigen::Vector2i> NearerThan(const std::vector<float>& before, const std::vector<float>& after) {
    std::vector<Eigen::Vector2i> out;
    for (int v = 0; v < kHeight; ++v)
      for (int u = 0; u < kWidth; ++u)
        if (after[v * kWidth + u] < before[v * kWidth + u] - 0.05f) out.emplace_back(u, v);
    return out;
  }
  std::vector<float> Depth(const Camera& camera) {
    auto depth = renderer_->ReadLinearDepth(MakeView(camera, {0, 0, kWidth, kHeight}));
    EXPECT_TRUE(depth.ok()) << depth.status();
    return depth.ok() ? *depth : std::vector<float>();
  }
};

// From above (steep), the nose (green, on the +x face of the head) is where the pinhole model puts
// the avatar's +x side at its heading, and not on the opposite side; a metre away is ground.
TEST_F(AvatarTest, LandsOnThePinholePixelsFacingItsHeading) {
  NoVideo();
  const Camera above{PinholeIntrinsics::FromFov(kWidth, kHeight, 50), LookAt({8, -11, 14}, {8, -8, 0})};
  const Eigen::Vector3d base(8, -8, 0);
  for (double heading : {0.0, M_PI / 2, 2.5, -2.0}) {
    ASSERT_TRUE(renderer_->SetAvatars({{"procedural-walk", base, heading, 0.3}}).ok());
    const std::vector<uint8_t> rgba = RenderFrom(above);
    const Eigen::Vector3d front = OnAvatar(base, heading, {0.16, 0, 1.66});  // nose top
    const Eigen::Vector3d back = OnAvatar(base, heading, {-0.16, 0, 1.66});
    const Eigen::Vector3i at_front = PixelSeenBy(above, rgba, front);
    const Eigen::Vector3i at_back = PixelSeenBy(above, rgba, back);
    EXPECT_TRUE(IsGreen(at_front)) << "heading " << heading << ": nose pixel " << Str(at_front);
    EXPECT_FALSE(IsGreen(at_back)) << "heading " << heading << ": behind the head " << Str(at_back);
    const Eigen::Vector3i away = PixelSeenBy(above, rgba, OnAvatar(base, heading, {0, 1.0, 0}));
    EXPECT_TRUE(Near(away, ShadedGround())) << "heading " << heading << ": " << Str(away);
  }
}

// Projected video lands on avatars by default; with video_on_people off not one of their pixels
// shows video (the privacy export), frame after frame (the cached view redraws them exactly),
// while the ground around them still gets it.
TEST_F(AvatarTest, PrivacyExport_NoVideoPixelLandsOnAPerson) {
  ReplaceProjector(MakeProjector(projector_, SolidImage(640, 480, kMagenta), 2));
  const Camera close{PinholeIntrinsics::FromFov(kWidth, kHeight, 60), LookAt({0, 16, 7}, {6, 5, 1})};
  viewer_ = close;
  std::vector<AvatarInstance> people;
  for (int k = 0; k < 4; ++k) people.push_back({"procedural-walk", {4.0 + 1.5 * k, 7.0 - k, 0}, -0.6 + 0.5 * k, 0.25 * k});
  RenderViewer();
  const std::vector<float> ground_depth = Depth(viewer_);
  ASSERT_TRUE(renderer_->SetAvatars(people).ok());
  std::vector<uint8_t> rgba = RenderViewer();
  std::vector<Eigen::Vector2i> covered = NearerThan(ground_depth, Depth(viewer_));
  ASSERT_GT(covered.size(), 400u) << "the avatars are in the picture";
  size_t video = 0;
  for (const Eigen::Vector2i& p : covered) video += IsMagenta(PixelAt(rgba, kWidth, p.x(), p.y()));
  EXPECT_GT(video, covered.size() / 5) << "by default video lands on avatars";

  VideoOnPeople(false);
  for (int frame = 0; frame < 3; ++frame) {
    for (AvatarInstance& a : people) a.phase_cycles += 0.1;  // walking in place: frames change
    if (frame == 2) people[0].base.x() += 0.3;
    ASSERT_TRUE(renderer_->SetAvatars(people).ok());
    rgba = RenderViewer();
    covered = NearerThan(ground_depth, Depth(viewer_));
    ASSERT_GT(covered.size(), 400u) << "frame " << frame;
    size_t leaked = 0;
    for (const Eigen::Vector2i& p : covered) leaked += IsMagenta(PixelAt(rgba, kWidth, p.x(), p.y()));
    EXPECT_EQ(leaked, 0u) << "frame " << frame << ": video pixels on people";
    EXPECT_TRUE(IsMagenta(ViewerPixel(rgba, {3, 10, 0}))) << "the ground still gets the video";
    if (const char* dir = std::getenv("AVE_TEST_PNG_DIR"); dir && frame == 2) {
      WritePng(std::string(dir) + "/avatars_privacy.png", rgba, kWidth, kHeight);
    }
  }
  EXPECT_GT(renderer_->stats().view_cache_patches, 0u) << "the cached path with model rectangles was taken";
}

// A crowd over most of a cached view: the view is drawn exactly instead of patched rectangle by
// rectangle, and the pictures and depth are those of a renderer without the view cache.
class AvatarCrowdTest : public AvatarTest {
 protected:
  RendererOptions Options() const override {
    RendererOptions options;
    options.moving_view_scale = 1;
    return options;
  }
  // The reference: the same scene, projector and walk in a renderer without the view cache.
  void MakeExactRenderer(std::unique_ptr<Renderer>* exact) const {
    RendererOptions exact_options = Options();
    exact_options.view_cache = false;
    absl::StatusOr<std::unique_ptr<Renderer>> made = Renderer::Create(exact_options);
    ASSERT_TRUE(made.ok()) << made.status();
    *exact = std::move(*made);
    ASSERT_TRUE((*exact)->SetStaticMesh(mesh_).ok());
    ASSERT_TRUE((*exact)->SetProjectors({MakeProjector(projector_, image_, 1)}).ok());
    ASSERT_TRUE((*exact)->SetAvatarSequence(avatar::MakeProceduralWalk()).ok());
  }
  // `people` in this renderer (the view cache's path) and in `exact`: the same picture within 3
  // levels and the same depth. The cached path's picture and depth go to `rgba` / `depth`.
  void ExpectCachedMatchesExact(std::unique_ptr<Renderer>& exact, const std::vector<AvatarInstance>& people, int frame,
                                std::vector<uint8_t>* rgba = nullptr, std::vector<float>* depth = nullptr) {
    for (Renderer* r : {renderer_.get(), exact.get()}) ASSERT_TRUE(r->SetAvatars(people).ok());
    const std::vector<uint8_t> cached = RenderViewer();
    const std::vector<float> cached_depth = Depth(viewer_);
    std::swap(renderer_, exact);
    const std::vector<uint8_t> reference = RenderViewer();
    const std::vector<float> reference_depth = Depth(viewer_);
    std::swap(renderer_, exact);
    const PictureDifference d = Compare(cached, reference);
    EXPECT_LE(d.max, 3) << "frame " << frame << ": mean " << d.mean;
    EXPECT_EQ(cached_depth, reference_depth) << "frame " << frame;
    if (rgba) *rgba = cached;
    if (depth) *depth = cached_depth;
  }
};

TEST_F(AvatarCrowdTest, CachedViewFallsBackToExactAndMatchesIt) {
  std::unique_ptr<Renderer> exact;
  ASSERT_NO_FATAL_FAILURE(MakeExactRenderer(&exact));
  viewer_ = Camera{PinholeIntrinsics::FromFov(kWidth, kHeight, 60), LookAt({0, 16, 7}, {6, 5, 1})};
  RenderViewer();  // the cache is built without people
  for (int frame = 0; frame < 3; ++frame) {
    std::vector<AvatarInstance> crowd;
    for (int k = 0; k < 40; ++k) {
      crowd.push_back({"procedural-walk", {2.0 + 1.2 * (k % 8) + 0.2 * frame, 3.0 + 1.5 * (k / 8), 0}, 0.3 * k, 0.1 * frame});
    }
    ASSERT_NO_FATAL_FAILURE(ExpectCachedMatchesExact(exact, crowd, frame));
  }
  EXPECT_GE(renderer_->stats().views_exact_for_models, 3u);
  exact.reset();
}

// A crowd seen from farther: its rectangles (squares around each person, not their union) cover
// under a third of the view, so the cached path draws it: one shadow-tested resolve over every
// pixel instead of counting 40 people's shadow volumes, and the patches pass by pass. Pictures
// and depth are those of a renderer without the view cache.
TEST_F(AvatarCrowdTest, CrowdOnTheCachedPathMatchesExact) {
  std::unique_ptr<Renderer> exact;
  ASSERT_NO_FATAL_FAILURE(MakeExactRenderer(&exact));
  viewer_ = Camera{PinholeIntrinsics::FromFov(kWidth, kHeight, 60), LookAt({-6, 30, 16}, {6, 5, 1})};
  RenderViewer();  // the cache is built without people
  const RenderStats built = renderer_->stats();
  for (int frame = 0; frame < 3; ++frame) {
    std::vector<AvatarInstance> crowd;
    for (int k = 0; k < 40; ++k) {
      crowd.push_back({"procedural-walk", {2.0 + 1.2 * (k % 8) + 0.2 * frame, 3.0 + 1.5 * (k / 8), 0}, 0.3 * k, 0.1 * frame});
    }
    ASSERT_NO_FATAL_FAILURE(ExpectCachedMatchesExact(exact, crowd, frame));
  }
  const RenderStats after = renderer_->stats();
  EXPECT_EQ(after.views_exact_for_models, built.views_exact_for_models) << "the crowd took the cached path";
  EXPECT_EQ(after.view_cache_shadowed_all - built.view_cache_shadowed_all, 3u);
  EXPECT_EQ(after.view_cache_entry_marks, built.view_cache_entry_marks) << "no shadow volumes counted";
  EXPECT_GE(after.view_cache_patches, built.view_cache_patches + 3 * 5) << "several runs of squares a frame";
  exact.reset();
}

// A few people (under the crowd's 24) on the cached path (issue 17): their own pixels shaded by
// the projector passes through the G-buffer's stencil, the cached resolve around them kept, their
// shadows on the ground tested inside shadow volumes cut where the static surface behind them
// ends. The people and their shadows on the ground are those of a renderer without the view cache.
TEST_F(AvatarCrowdTest, FewPeopleAndTheirShadowsOnTheCachedPathMatchExact) {
  std::unique_ptr<Renderer> exact;
  ASSERT_NO_FATAL_FAILURE(MakeExactRenderer(&exact));
  viewer_ = Camera{PinholeIntrinsics::FromFov(kWidth, kHeight, 60), LookAt({-6, 30, 16}, {6, 5, 1})};
  const std::vector<uint8_t> empty = RenderViewer();  // the cache is built without people
  const std::vector<float> empty_depth = Depth(viewer_);
  const RenderStats built = renderer_->stats();
  for (int frame = 0; frame < 3; ++frame) {
    std::vector<AvatarInstance> people;
    for (int k = 0; k < 6; ++k) {
      people.push_back({"procedural-walk", {3.0 + 2.5 * (k % 3) + 0.2 * frame, 4.0 + 3.0 * (k / 3), 0}, 0.7 * k, 0.1 * frame});
    }
    std::vector<uint8_t> cached;
    std::vector<float> cached_depth;
    ASSERT_NO_FATAL_FAILURE(ExpectCachedMatchesExact(exact, people, frame, &cached, &cached_depth));
    // The people are there, and so are their shadows: ground pixels (depth as without them) that
    // the video no longer reaches.
    int person = 0, shadow = 0;
    for (int v = 0; v < kHeight; ++v) {
      for (int u = 0; u < kWidth; ++u) {
        const size_t i = static_cast<size_t>(v) * kWidth + u;
        const Eigen::Vector3i with = PixelAt(cached, kWidth, u, v), without = PixelAt(empty, kWidth, u, v);
        const bool changed = (with - without).cwiseAbs().maxCoeff() > 30;
        if (cached_depth[i] < empty_depth[i] - 0.05f) {
          ++person;
        } else if (changed) {
          ++shadow;
        }
      }
    }
    EXPECT_GT(person, 6 * 20) << "frame " << frame;
    EXPECT_GT(shadow, 6 * 20) << "frame " << frame;
  }
  const RenderStats after = renderer_->stats();
  EXPECT_EQ(after.views_exact_for_models, built.views_exact_for_models) << "the people took the cached path";
  EXPECT_EQ(after.view_cache_shadow_tests - built.view_cache_shadow_tests, 3u);
  EXPECT_EQ(after.view_cache_shadowed_all, built.view_cache_shadowed_all) << "shadow volumes, not every pixel";
  exact.reset();
}

TEST_F(AvatarTest, OneFrameSequenceAndBadInputs) {
  NoVideo();
  ASSERT_TRUE(renderer_->SetAvatarSequence(avatar::MakeProceduralWalk({.frame_count = 1}, "statue")).ok());
  ASSERT_TRUE(renderer_->SetAvatars({{"statue", {8, -8, 0}, 0, 0.77}}).ok());
  const std::vector<uint8_t> statue = RenderViewer();
  ASSERT_TRUE(renderer_->SetAvatars({{"statue", {8, -8, 0}, 0, 0.1}}).ok());
  EXPECT_EQ(RenderViewer(), statue) << "one frame: every phase draws it";
  EXPECT_THAT(std::string(renderer_->SetAvatars({{"nobody", {0, 0, 0}, 0, 0}}).message()), HasSubstr("'nobody'"));
  EXPECT_THAT(std::string(renderer_->SetAvatars({{"statue", {0, NAN, 0}, 0, 0}}).message()), HasSubstr("avatar 0"));
  avatar::AvatarSequence bad = avatar::MakeProceduralWalk({}, "bad");
  bad.frames[3].indices.back() = 100000;
  EXPECT_THAT(std::string(renderer_->SetAvatarSequence(bad).message()), HasSubstr("frames[3].indices"));
}

}  // namespace
}  // namespace ave::viewer
