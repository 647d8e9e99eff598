#include "sensor_agent/sim/sim_camera.h"

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <stdexcept>
#include <string>

#include <filesystem>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "model_store/geometry/raycast.h"

namespace ave::sim {
namespace {

using Eigen::Vector2d;
using Eigen::Vector3d;

CampusRenderer::Options StaticOnly() {
  CampusRenderer::Options options;
  options.draw_movers = false;
  return options;
}

uint32_t IdFromHit(const TriangleMesh& mesh, const std::optional<RayHit>& hit) {
  if (!hit) return kSkyId;
  const int32_t object = mesh.triangle_object[hit->triangle];
  if (object >= 0) return kBuildingIdBase + static_cast<uint32_t>(object);
  switch (mesh.triangle_material[hit->triangle]) {
    case SurfaceMaterial::kVegetation: return kVegetationId;
    case SurfaceMaterial::kObject: return kStaticObjectId;
    default: return kGroundId;
  }
}

// True when the 3x3 neighbourhood of (u, v) carries one id: away from silhouettes and seams.
bool InsideRegion(const SimImage& image, int u, int v) {
  const uint32_t id = image.object_id[image.Index(u, v)];
  for (int dv = -1; dv <= 1; ++dv)
    for (int du = -1; du <= 1; ++du) {
      const int x = std::clamp(u + du, 0, image.width - 1), y = std::clamp(v + dv, 0, image.height - 1);
      if (image.object_id[image.Index(x, y)] != id) return false;
    }
  return true;
}

struct Agreement {
  int checked = 0, same_class = 0, hits = 0, depth_checked = 0, depth_bad = 0;
  double worst_depth_error_m = 0;
};

// Compares the rendered mask and depth with ray casts through pixel centres on a grid.
Agreement CompareWithRaycast(const SimImage& image, const TriangleMesh& mesh, const PinholeIntrinsics& k,
                             const Rigid3d& world_from_camera, int step_px) {
  Agreement a;
  for (int v = step_px / 2; v < k.height; v += step_px) {
    for (int u = step_px / 2; u < k.width; u += step_px) {
      const Vector3d ray_in_camera = PixelRay(k, Vector2d(u, v));
      const auto hit = RaycastMesh(mesh, world_from_camera.translation, world_from_camera.rotation * ray_in_camera);
      const uint32_t truth = IdFromHit(mesh, hit);
      const size_t i = image.Index(u, v);
      ++a.checked;
      if (image.object_id[i] == truth) ++a.same_class;
      if (hit) ++a.hits;
      if (hit && image.object_id[i] == truth && InsideRegion(image, u, v)) {
        const double error = std::abs(image.depth_m[i] - hit->distance_m * ray_in_camera.z());
        ++a.depth_checked;
        if (error > 0.02) ++a.depth_bad;
        a.worst_depth_error_m = std::max(a.worst_depth_error_m, error);
      }
    }
  }
  return a;
}

TEST(CampusRenderer, OptionsCheckNamesTheBadField) {
  CampusRenderer::Options options;
  EXPECT_EQ(options.Check(), "");
  options.terrain_resolution_m = 0;
  EXPECT_NE(options.Check().find("terrain_resolution_m"), std::string::npos);
  EXPECT_THROW(CampusRenderer(scene::BuiltinCampus(), options), std::invalid_argument);
  options = {};
  options.sun_direction = Vector3d::Zero();
  EXPECT_NE(options.Check().find("sun_direction"), std::string::npos);
  options = {};
  options.near_m = -1;
  EXPECT_NE(options.Check().find("near_m"), std::string::npos);
}

TEST(CampusRenderer, InvalidIntrinsicsGiveAnEmptyImage) {
  const scene::SyntheticCampus campus = scene::BuiltinCampus();
  const CampusRenderer renderer(campus);
  PinholeIntrinsics k = campus.cameras[0].intrinsics;
  k.fx = 0;
  const SimImage image = renderer.Render(k, campus.cameras[0].world_from_camera, 0);
  EXPECT_EQ(image.width, 0);
  EXPECT_TRUE(image.bgr.empty());
}

// (a) The id mask and depth agree with ray casting against the same static mesh.
TEST(CampusRenderer, MaskAndDepthMatchRaycastForCampusCameras) {
  const scene::SyntheticCampus campus = scene::BuiltinCampus();
  const CampusRenderer renderer(campus, StaticOnly());
  const TriangleMesh mesh = scene::BuildStaticMesh(campus, renderer.options().terrain_resolution_m);
  for (const scene::CameraSpec& camera : campus.cameras) {
    const SimImage image = renderer.Render(camera.intrinsics, camera.world_from_camera, 5.0);
    ASSERT_EQ(image.width, camera.intrinsics.width);
    const Agreement a = CompareWithRaycast(image, mesh, camera.intrinsics, camera.world_from_camera, 40);
    EXPECT_GE(a.checked, 180) << camera.id;
    EXPECT_GE(a.same_class, 0.98 * a.checked) << camera.id << ": " << a.same_class << " of " << a.checked;
    EXPECT_GE(a.hits, 0.5 * a.checked) << camera.id;
    EXPECT_GE(a.depth_checked, 0.8 * a.hits) << camera.id;
    EXPECT_EQ(a.depth_bad, 0) << camera.id << ": worst depth error " << a.worst_depth_error_m << " m";
  }
}

// (b) Same inputs, same bits; also from a second renderer instance.
TEST(CampusRenderer, RendersAreBitIdentical) {
  const scene::SyntheticCampus campus = scene::BuiltinCampus();
  const CampusRenderer first(campus), second(campus);
  const scene::CameraSpec& camera = campus.cameras[1];
  const SimImage a = first.Render(camera.intrinsics, camera.world_from_camera, 12.25);
  const SimImage b = first.Render(camera.intrinsics, camera.world_from_camera, 12.25);
  const SimImage c = second.Render(camera.intrinsics, camera.world_from_camera, 12.25);
  for (const SimImage* other : {&b, &c}) {
    EXPECT_EQ(a.bgr, other->bgr);
    EXPECT_EQ(a.object_id, other->object_id);
    ASSERT_EQ(a.depth_m.size(), other->depth_m.size());
    EXPECT_EQ(std::memcmp(a.depth_m.data(), other->depth_m.data(), a.depth_m.size() * sizeof(float)), 0);
  }
  // And time matters: the movers have moved 3 s later.
  const SimImage later = first.Render(camera.intrinsics, camera.world_from_camera, 15.25);
  EXPECT_NE(a.object_id, later.object_id);
}

// (c) Every mover whose centre is in view and not hidden by a building shows there in the mask.
TEST(CampusRenderer, MoversAppearWhereTheyProject) {
  const scene::SyntheticCampus campus = scene::BuiltinCampus();
  const CampusRenderer renderer(campus);
  const TriangleMesh mesh = scene::BuildStaticMesh(campus, renderer.options().terrain_resolution_m);
  int checked = 0;
  for (const double t_s : {0.0, 5.0, 11.0, 23.5, 47.0}) {
    for (const scene::CameraSpec& camera : campus.cameras) {
      const SimImage image = renderer.Render(camera.intrinsics, camera.world_from_camera, t_s);
      const Rigid3d camera_from_world = camera.world_from_camera.Inverse();
      for (const scene::Mover& mover : campus.movers) {
        const scene::MoverState state = scene::MoverAt(campus, mover, t_s);
        const Vector3d center = state.position_m + Vector3d(0, 0, 0.5 * mover.size_m.z());
        const Vector3d p_in_camera = camera_from_world * center;
        const auto uv = ProjectToPixel(camera.intrinsics, p_in_camera);
        if (!uv || uv->x() < 2 || uv->y() < 2 || uv->x() > camera.intrinsics.width - 3 ||
            uv->y() > camera.intrinsics.height - 3) {
          continue;
        }
        if (!SegmentIsClear(mesh, camera.world_from_camera.translation, center, 0.5)) continue;
        const int u = static_cast<int>(std::lround(uv->x())), v = static_cast<int>(std::lround(uv->y()));
        const uint32_t want = kMoverIdBase + mover.id;
        // The centre pixel itself when the mover is a few pixels wide, else its 3x3 neighbourhood.
        const double half_width_px = 0.5 * std::min(mover.size_m.x(), mover.size_m.y()) * camera.intrinsics.fx / p_in_camera.z();
        bool found = image.object_id[image.Index(u, v)] == want;
        if (half_width_px < 1.5) {
          for (int dv = -1; dv <= 1; ++dv)
            for (int du = -1; du <= 1; ++du) found = found || image.object_id[image.Index(u + du, v + dv)] == want;
        }
        EXPECT_TRUE(found) << camera.id << " t=" << t_s << " mover " << mover.id << " at pixel " << u << "," << v
                           << " shows id " << image.object_id[image.Index(u, v)];
        ++checked;
      }
    }
  }
  EXPECT_GE(checked, 10) << "too few movers in view to test anything";
}

TEST(CampusRenderer, MoversCanBeSwitchedOff) {
  const scene::SyntheticCampus campus = scene::BuiltinCampus();
  const CampusRenderer renderer(campus, StaticOnly());
  for (const scene::CameraSpec& camera : campus.cameras) {
    const SimImage image = renderer.Render(camera.intrinsics, camera.world_from_camera, 5.0);
    EXPECT_EQ(std::count_if(image.object_id.begin(), image.object_id.end(), IsMoverId), 0) << camera.id;
  }
}

// Issue 19 (the demo's cameras at their rate): a fixed camera's renders after the first reuse the
// fixed static scene's raster and shading (reuse_static_layer) and stay bit-identical to rendering
// everything, while trees sway and movers move (pixels they uncover are shaded afresh); a second
// view interleaved with the first does not mix their layers.
TEST(CampusRenderer, ReusedStaticLayerIsBitIdenticalToAFullRender) {
  const scene::SyntheticCampus campus = scene::BuiltinCampus();
  EffectParams sway;
  sway.values["amplitude_m"] = 0.3;
  sway.values["frequency_hz"] = 0.4;
  CampusRenderer::Options reuse, full;
  reuse.waving_vegetation = sway;
  full.waving_vegetation = sway;
  full.reuse_static_layer = false;
  ASSERT_TRUE(reuse.reuse_static_layer);
  const CampusRenderer reusing(campus, reuse), rendering(campus, full);
  const scene::CameraSpec& a = campus.cameras[0];
  const scene::CameraSpec& b = campus.cameras[2];
  int compared = 0, movers_seen = 0;
  // a five times (full, layer built, layer reused x3), b five times, then a once more (b's layer
  // must not be used for it).
  for (const scene::CameraSpec* camera : {&a, &b, &a}) {
    for (double t : {3.0, 3.5, 9.0, 20.25, 41.0}) {
      if (camera == &a && compared >= 10 && t > 3.0) break;
      const SimImage got = reusing.Render(camera->intrinsics, camera->world_from_camera, t);
      const SimImage want = rendering.Render(camera->intrinsics, camera->world_from_camera, t);
      ASSERT_EQ(got.bgr, want.bgr) << camera->id << " at " << t;
      ASSERT_EQ(got.object_id, want.object_id) << camera->id << " at " << t;
      ASSERT_EQ(got.class_id, want.class_id) << camera->id << " at " << t;
      ASSERT_EQ(std::memcmp(got.depth_m.data(), want.depth_m.data(), got.depth_m.size() * sizeof(float)), 0);
      movers_seen += static_cast<int>(std::count_if(got.object_id.begin(), got.object_id.end(), IsMoverId) > 0);
      ++compared;
    }
  }
  EXPECT_EQ(compared, 11);
  EXPECT_GE(movers_seen, 5) << "movers must cover (and uncover) layer pixels for the test to mean anything";
}

// (d) Looking straight up: only sky.
TEST(CampusRenderer, LookingStraightUpSeesOnlySky) {
  const scene::SyntheticCampus campus = scene::BuiltinCampus();
  const CampusRenderer renderer(campus);
  const Vector3d eye(0, 0, campus.TerrainHeight(0, 0) + 2);
  const SimImage image = renderer.Render(PinholeIntrinsics::FromFov(160, 120, 70), LookAt(eye, eye + Vector3d::UnitZ()), 0);
  for (size_t i = 0; i < image.object_id.size(); ++i) {
    ASSERT_EQ(image.object_id[i], kSkyId) << "pixel " << i;
    ASSERT_TRUE(std::isinf(image.depth_m[i]));
  }
}

// (d) Looking straight down onto the gym's flat roof: every pixel is that roof at the analytic depth.
TEST(CampusRenderer, LookingStraightDownOntoARoofSeesOnlyThatRoof) {
  const scene::SyntheticCampus campus = scene::BuiltinCampus();
  const CampusRenderer renderer(campus);
  const size_t gym = 4;
  ASSERT_EQ(campus.buildings[gym].id, "gym");
  const scene::BoxBuilding& b = campus.buildings[gym];
  const Vector3d eye(b.center_m.x(), b.center_m.y(), campus.BuildingTop(b) + 15);
  const SimImage image = renderer.Render(PinholeIntrinsics::FromFov(160, 120, 70), LookAt(eye, eye - Vector3d::UnitZ()), 0);
  for (size_t i = 0; i < image.object_id.size(); ++i) {
    ASSERT_EQ(image.object_id[i], kBuildingIdBase + gym) << "pixel " << i;
    ASSERT_NEAR(image.depth_m[i], 15.0, 2e-3) << "pixel " << i;
  }
}

// (d) Looking straight down onto the road crossing: only ground, in asphalt grey.
TEST(CampusRenderer, LookingStraightDownOntoTheCrossingSeesOnlyGrey) {
  const scene::SyntheticCampus campus = scene::BuiltinCampus();
  const CampusRenderer renderer(campus, StaticOnly());
  const Vector3d eye(0, 0, campus.TerrainHeight(0, 0) + 4);
  const SimImage image = renderer.Render(PinholeIntrinsics::FromFov(160, 120, 70), LookAt(eye, eye - Vector3d::UnitZ()), 0);
  for (size_t i = 0; i < image.object_id.size(); ++i) {
    ASSERT_EQ(image.object_id[i], kGroundId) << "pixel " << i;
    const int b = image.bgr[3 * i], g = image.bgr[3 * i + 1], r = image.bgr[3 * i + 2];
    ASSERT_LE(std::max({r, g, b}) - std::min({r, g, b}), 12) << "asphalt should be grey at pixel " << i;
  }
}

TEST(CampusRenderer, GrassIsGreenAndWallsHaveWindows) {
  const scene::SyntheticCampus campus = scene::BuiltinCampus();
  const CampusRenderer renderer(campus, StaticOnly());
  const PinholeIntrinsics k = PinholeIntrinsics::FromFov(160, 120, 60);
  // Grass between the roads and buildings, seen from 5 m above.
  const Vector3d lawn(-12, -60, campus.TerrainHeight(-12, -60) + 5);
  const SimImage grass = renderer.Render(k, LookAt(lawn, lawn - Vector3d::UnitZ()), 0);
  int green = 0;
  for (size_t i = 0; i < grass.object_id.size(); ++i) {
    if (grass.bgr[3 * i + 1] > grass.bgr[3 * i] + 20 && grass.bgr[3 * i + 1] > grass.bgr[3 * i + 2]) ++green;
  }
  EXPECT_GE(green, 0.95 * grass.object_id.size());
  // hall-a's south wall (y = -35) from 20 m south, level: some pixels are dark blue glass.
  const Vector3d eye(-30, -55, campus.TerrainHeight(-30, -55) + 6);
  const SimImage wall = renderer.Render(k, LookAt(eye, Vector3d(-30, -35, eye.z())), 0);
  int glass = 0, building = 0;
  for (size_t i = 0; i < wall.object_id.size(); ++i) {
    if (wall.object_id[i] != kBuildingIdBase + 0) continue;
    ++building;
    if (wall.bgr[3 * i] > wall.bgr[3 * i + 2] + 10) ++glass;  // blue over red
  }
  EXPECT_GT(building, 0.3 * wall.object_id.size());
  EXPECT_GT(glass, 0.1 * building);
  EXPECT_LT(glass, 0.7 * building);
}

// (d) At the terrain's edge looking outwards and down: the terrain under and behind the camera
// crosses the near plane and must be clipped, never folded into view; nothing behind shows.
TEST(CampusRenderer, TrianglesBehindTheCameraNeverShow) {
  const scene::SyntheticCampus campus = scene::BuiltinCampus();
  const CampusRenderer renderer(campus, StaticOnly());
  const TriangleMesh mesh = scene::BuildStaticMesh(campus, renderer.options().terrain_resolution_m);
  const double x = campus.half_extent_m - 0.5;
  const Vector3d eye(x, 3, campus.TerrainHeight(x, 3) + 0.3);
  const Rigid3d world_from_camera = LookAt(eye, eye + Vector3d(1, 0, -std::tan(30 * M_PI / 180)));
  const PinholeIntrinsics k = PinholeIntrinsics::FromFov(320, 240, 100);
  const SimImage image = renderer.Render(k, world_from_camera, 0);
  int sky = 0, ground = 0, building = 0;
  for (size_t i = 0; i < image.object_id.size(); ++i) {
    const uint32_t id = image.object_id[i];
    sky += id == kSkyId;
    ground += id == kGroundId;
    building += IsBuildingId(id);
    if (id != kSkyId) {
      ASSERT_GE(image.depth_m[i], renderer.options().near_m * 0.999) << "pixel " << i;
    }
  }
  EXPECT_EQ(building, 0);
  EXPECT_GT(sky, 0.3 * image.object_id.size());
  EXPECT_GT(ground, 0.05 * image.object_id.size());
  const Agreement a = CompareWithRaycast(image, mesh, k, world_from_camera, 8);
  EXPECT_GE(a.same_class, 0.98 * a.checked) << a.same_class << " of " << a.checked;
  EXPECT_EQ(a.depth_bad, 0) << "worst depth error " << a.worst_depth_error_m << " m";
}

// (e) Huge and non-finite times still give a complete, consistent image.
TEST(CampusRenderer, HugeTimesGiveFiniteOutput) {
  const scene::SyntheticCampus campus = scene::BuiltinCampus();
  const CampusRenderer renderer(campus);
  const scene::CameraSpec& camera = campus.cameras[0];
  for (const double t_s : {1e7, -1e7, 1e15, std::nan("")}) {
    const SimImage image = renderer.Render(camera.intrinsics, camera.world_from_camera, t_s);
    ASSERT_EQ(image.bgr.size(), 3u * camera.intrinsics.width * camera.intrinsics.height);
    int ground = 0;
    for (size_t i = 0; i < image.object_id.size(); ++i) {
      const bool sky = image.object_id[i] == kSkyId;
      ASSERT_EQ(sky, std::isinf(image.depth_m[i])) << "t=" << t_s << " pixel " << i;
      if (!sky) {
        ASSERT_TRUE(std::isfinite(image.depth_m[i]) && image.depth_m[i] > 0) << "t=" << t_s;
      }
      ground += image.object_id[i] == kGroundId;
    }
    EXPECT_GT(ground, image.object_id.size() / 4) << "t=" << t_s;
  }
}

// Example renders go to AVE_SIM_PNG_DIR (default: the temp dir) and must read back as the same
// pixels, so the pictures a person looks at are exactly what the agents stream.
TEST(CampusRenderer, WritesExampleRendersThatReadBackExactly) {
  const char* env = std::getenv("AVE_SIM_PNG_DIR");
  const std::string dir = env ? env : std::filesystem::temp_directory_path().string();
  const scene::SyntheticCampus campus = scene::BuiltinCampus();
  const CampusRenderer renderer(campus);
  for (const scene::CameraSpec& camera : campus.cameras) {
    SimImage image = renderer.Render(camera.intrinsics, camera.world_from_camera, 5.0);
    const cv::Mat bgr(image.height, image.width, CV_8UC3, image.bgr.data());
    const std::string path = dir + "/sim_" + camera.id + ".png";
    ASSERT_TRUE(cv::imwrite(path, bgr)) << path;
    const cv::Mat back = cv::imread(path, cv::IMREAD_COLOR);
    ASSERT_EQ(back.size(), bgr.size()) << path;
    EXPECT_EQ(cv::norm(back, bgr, cv::NORM_INF), 0) << path;
  }
}

}  // namespace
}  // namespace ave::sim
