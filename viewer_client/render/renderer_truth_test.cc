// Issue 7: the renderer against a ray-cast truth on the `minimal` scenario, pinhole and distorted.
#include "viewer_client/render/render_test_scene.h"

namespace ave::viewer {
namespace {

using namespace ::ave::viewer::render_test;  // NOLINT: the shared scene and helpers of the render tests

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
}  // namespace
}  // namespace ave::viewer
