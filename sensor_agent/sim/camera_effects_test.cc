#include "sensor_agent/sim/camera_effects.h"

#include <cmath>
#include <cstdlib>
#include <filesystem>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "model_store/geometry/raycast.h"
#include "model_store/scene/scene_file.h"
#include "sensor_agent/sim/scenario.h"

namespace ave::sim {
namespace {

using Eigen::Vector2d;
using Eigen::Vector3d;

Scenario Load(const std::string& name) {
  auto s = LoadScenario(name);
  EXPECT_TRUE(s.ok()) << s.status();
  return s.ok() ? *s : Scenario{};
}

// A scene with no effects renders bit-identically twice, and exactly as the plain renderer does.
TEST(CameraPipeline, NoEffectsRendersBitIdenticalTwice) {
  const Scenario s = Load("minimal");
  ASSERT_TRUE(s.effects.empty());
  const scene::CameraSpec& cam = *s.world.FindCamera("cam1");
  const SimulatedCamera a(s.world, cam, s.EffectsForCamera("cam1"), s.seed), b(s.world, cam, s.EffectsForCamera("cam1"), s.seed);
  const SimImage x = a.Frame(3, 0.3), y = a.Frame(3, 0.3), z = b.Frame(3, 0.3);
  ASSERT_GT(x.width, 0);
  for (const SimImage* other : {&y, &z}) {
    EXPECT_EQ(x.bgr, other->bgr);
    EXPECT_EQ(x.object_id, other->object_id);
    EXPECT_EQ(x.class_id, other->class_id);
  }
  const CampusRenderer plain(s.world);
  EXPECT_EQ(plain.Render(cam.intrinsics, cam.world_from_camera, 0.3).bgr, x.bgr);
  // The walker is in view.
  EXPECT_GT(std::count(x.object_id.begin(), x.object_id.end(), kMoverIdBase + 1), 20);
}

// MISSION standing demand 3: an effect the scenario does not name is never evaluated.
TEST(CameraPipeline, OnlyNamedEffectsAreEvaluated) {
  const Scenario minimal = Load("minimal");
  ResetEvaluations();
  {
    const SimulatedCamera cam(minimal.world, *minimal.world.FindCamera("cam1"), minimal.effects, minimal.seed);
    for (int f = 0; f < 3; ++f) cam.Frame(f, f / 10.0);
  }
  for (int k = 0; k < kEffectCount; ++k) EXPECT_EQ(Evaluations(static_cast<EffectKind>(k)), 0u) << EffectName(static_cast<EffectKind>(k));

  auto some = LoadScenarioText(std::string(*scene::BundledScenarioText("minimal")) +
                                   "\n" R"(trees:
  - {position: [8, 5]}
)",
                               "some.yaml");
  ASSERT_TRUE(some.ok()) << some.status();
  some->effects.Enable(EffectKind::kCameraNoise, {});
  some->effects.Enable(EffectKind::kJpegArtefacts, {});
  ResetEvaluations();
  {
    const SimulatedCamera cam(some->world, *some->world.FindCamera("cam1"), some->effects, some->seed);
    for (int f = 0; f < 3; ++f) cam.Frame(f, f / 10.0);
  }
  EXPECT_EQ(Evaluations(EffectKind::kCameraNoise), 3u);
  EXPECT_EQ(Evaluations(EffectKind::kJpegArtefacts), 3u);
  for (EffectKind k : {EffectKind::kIllumination, EffectKind::kRollingOcclusion, EffectKind::kWavingVegetation, EffectKind::kGpsNoise,
                       EffectKind::kImuNoise, EffectKind::kLidarRangeNoise}) {
    EXPECT_EQ(Evaluations(k), 0u) << EffectName(k);
  }

  // The campus backpack camera gets every camera effect the campus names.
  const Scenario campus = Load("campus");
  ResetEvaluations();
  {
    const SimulatedCamera cam(campus.world, *campus.world.FindCamera("backpack"), campus.EffectsForCamera("backpack"), campus.seed);
    cam.Frame(0, 0.5);
  }
  for (EffectKind k : {EffectKind::kCameraNoise, EffectKind::kIllumination, EffectKind::kJpegArtefacts, EffectKind::kRollingOcclusion,
                       EffectKind::kWavingVegetation}) {
    EXPECT_EQ(Evaluations(k), 1u) << EffectName(k);
  }
  EXPECT_EQ(Evaluations(EffectKind::kGpsNoise), 0u) << "no GPS is simulated by a camera";
}

TEST(CameraPipeline, DeterministicForASeedAndDifferentAcrossSeeds) {
  const Scenario campus = Load("campus");
  const scene::CameraSpec& cam = *campus.world.FindCamera("cam1");
  const EffectSet effects = campus.EffectsForCamera("cam1");
  const SimulatedCamera a(campus.world, cam, effects, campus.seed), b(campus.world, cam, effects, campus.seed + 1);
  const SimImage x = a.Frame(7, 7 / 15.0), y = a.Frame(7, 7 / 15.0), z = b.Frame(7, 7 / 15.0);
  EXPECT_EQ(x.bgr, y.bgr);
  EXPECT_NE(x.bgr, z.bgr);
  EXPECT_EQ(x.object_id, z.object_id) << "effects never change the truth of a fixed camera without occlusion";
}

// Truth consistency: a pedestrian's true foot point projects inside its own mask wherever the
// straight line from the camera to it is clear of the static model (and no other mover covers it).
TEST(CameraPipeline, PedestrianFootPointProjectsInsideItsMask) {
  const Scenario campus = Load("campus");
  const TriangleMesh mesh = scene::BuildStaticMesh(campus.world, 1.0);
  int checked = 0, found = 0;
  for (const char* id : {"cam1", "cam2", "cam3", "backpack"}) {
    const scene::CameraSpec& spec = *campus.world.FindCamera(id);
    scene::CameraSpec ideal = spec;
    ideal.intrinsics.distortion = {};  // the truth test uses the pinhole model
    const SimulatedCamera cam(campus.world, ideal, EffectSet{}, campus.seed);
    for (const double t_s : {0.0, 4.0, 9.5, 21.0, 33.0}) {
      const SimImage image = cam.Frame(0, t_s);
      const Rigid3d world_from_camera = cam.PoseAt(t_s);
      const Rigid3d camera_from_world = world_from_camera.Inverse();
      for (const scene::Mover& mover : campus.world.movers) {
        if (mover.kind != scene::MoverKind::kPerson) continue;
        const Vector3d foot = scene::MoverAt(campus.world, mover, t_s).position_m + Vector3d(0, 0, 0.05);
        const Vector3d p = camera_from_world * foot;
        const auto uv = ProjectToPixel(ideal.intrinsics, p);
        if (!uv || p.z() > 80 || uv->x() < 1 || uv->y() < 1 || uv->x() > image.width - 2 || uv->y() > image.height - 2) continue;
        if (!SegmentIsClear(mesh, world_from_camera.translation, foot, 0.3)) continue;
        const int u = static_cast<int>(std::lround(uv->x())), v = static_cast<int>(std::lround(uv->y()));
        const uint32_t shown = image.object_id[image.Index(u, v)];
        if (IsMoverId(shown) && shown != kMoverIdBase + mover.id && image.depth_m[image.Index(u, v)] < p.z()) continue;  // another mover in front
        bool hit = false;
        for (int dv = -1; dv <= 1; ++dv)
          for (int du = -1; du <= 1; ++du) hit |= image.object_id[image.Index(u + du, v + dv)] == kMoverIdBase + mover.id;
        ++checked;
        found += hit;
        EXPECT_TRUE(hit) << id << " t=" << t_s << " person " << mover.id << " foot at pixel " << u << "," << v << " shows " << shown;
        EXPECT_EQ(image.class_id[image.Index(u, v)] == static_cast<uint8_t>(PixelClass::kPerson), hit && shown == kMoverIdBase + mover.id)
            << id << " person " << mover.id;
      }
    }
  }
  EXPECT_GE(checked, 20) << "too few visible pedestrians to test anything";
}

TEST(CameraEffects, NoiseHasTheNamedSigma) {
  SimImage image;
  image.width = 200;
  image.height = 100;
  image.bgr.assign(3 * 200 * 100, 128);
  EffectParams p;
  p.values["sigma"] = 3.0;
  ApplyCameraNoise(p, 42, image);
  double sum = 0, sum2 = 0;
  for (uint8_t v : image.bgr) {
    sum += v - 128.0;
    sum2 += (v - 128.0) * (v - 128.0);
  }
  const double n = image.bgr.size(), mean = sum / n, sd = std::sqrt(sum2 / n - mean * mean);
  EXPECT_NEAR(mean, 0, 0.05);
  EXPECT_NEAR(sd, 3.0, 0.15);  // rounding to integers adds 1/12 of variance
}

TEST(CameraEffects, IlluminationScalesBrightnessByItsGain) {
  EffectParams p;
  p.values["amplitude"] = 0.3;
  p.values["period_s"] = 10;
  double lo = 10, hi = 0;
  for (double t = 0; t < 60; t += 0.25) {
    const double g = IlluminationGain(p, 5, t);
    lo = std::min(lo, g);
    hi = std::max(hi, g);
    ASSERT_GE(g, 0.7 - 1e-12);
    ASSERT_LE(g, 1.3 + 1e-12);
  }
  EXPECT_GT(hi - lo, 0.2) << "the light changes over a minute";
  EXPECT_NEAR(IlluminationGain(p, 5, 1e12), IlluminationGain(p, 5, 1e12), 0) << "finite at huge times";
  SimImage image;
  image.width = 10;
  image.height = 10;
  image.bgr.assign(300, 100);
  ApplyIllumination(p, 5, 3.0, image);
  EXPECT_EQ(image.bgr[0], static_cast<uint8_t>(std::lround(100 * IlluminationGain(p, 5, 3.0))));
}

TEST(CameraEffects, RollingOcclusionSweepsAndIsInTheMask) {
  const Scenario campus = Load("campus");
  const scene::CameraSpec& cam = *campus.world.FindCamera("cam1");
  EffectSet effects;
  EffectParams p;
  p.values = {{"period_s", 10}, {"duration_s", 2}, {"width_frac", 0.2}};
  effects.Enable(EffectKind::kRollingOcclusion, p);
  const SimulatedCamera sim(campus.world, cam, effects, 1);
  auto occluded_columns = [&](double t) {
    const SimImage im = sim.Frame(0, t);
    int first = -1, count = 0;
    for (int u = 0; u < im.width; ++u) {
      if (im.object_id[im.Index(u, im.height / 2)] == kOccluderId) {
        if (first < 0) first = u;
        ++count;
      }
    }
    return std::pair<int, int>(first, count);
  };
  const auto early = occluded_columns(0.5), late = occluded_columns(1.5), off = occluded_columns(5.0);
  EXPECT_GT(early.second, 50);
  EXPECT_GT(late.first, early.first) << "the occluder moves left to right";
  EXPECT_EQ(off.second, 0);
}

TEST(CameraEffects, JpegArtefactsStayCloseToTheImage) {
  const Scenario campus = Load("campus");
  const scene::CameraSpec& cam = *campus.world.FindCamera("cam2");
  EffectSet effects;
  effects.Enable(EffectKind::kJpegArtefacts, EffectParams{{{"quality", 30}}});
  const SimImage clean = SimulatedCamera(campus.world, cam, {}, 1).Frame(0, 1.0);
  const SimImage jpeg = SimulatedCamera(campus.world, cam, effects, 1).Frame(0, 1.0);
  ASSERT_EQ(clean.bgr.size(), jpeg.bgr.size());
  double se = 0;
  for (size_t i = 0; i < clean.bgr.size(); ++i) se += (clean.bgr[i] - jpeg.bgr[i]) * (clean.bgr[i] - jpeg.bgr[i]);
  const double psnr = 10 * std::log10(255.0 * 255.0 / (se / clean.bgr.size()));
  EXPECT_GT(psnr, 25);
  EXPECT_LT(psnr, 60) << "quality 30 must leave visible artefacts";
}

TEST(CameraEffects, WavingVegetationMovesCrownsNotTrunksOrBuildings) {
  const Scenario campus = Load("campus");
  const scene::Tree& tree = campus.world.trees.front();
  const double ground = campus.world.TerrainHeight(tree.position_m.x(), tree.position_m.y());
  // Look at the first tree from 12 m away, level with its crown.
  const Vector3d target(tree.position_m.x(), tree.position_m.y(), ground + tree.trunk_height_m + tree.crown_radius_m);
  scene::CameraSpec cam;
  cam.id = "treecam";
  cam.intrinsics = PinholeIntrinsics::FromFov(240, 180, 50);
  cam.world_from_camera = LookAt(target + Vector3d(0, -12, 0), target);
  EffectSet effects;
  effects.Enable(EffectKind::kWavingVegetation, EffectParams{{{"amplitude_m", 0.8}, {"frequency_hz", 0.5}}});
  RendererOptions no_movers;
  no_movers.draw_movers = false;
  const SimulatedCamera still(campus.world, cam, {}, 1, no_movers), waving(campus.world, cam, effects, 1, no_movers);
  const SimImage s0 = still.Frame(0, 0.5), w0 = waving.Frame(0, 0.5), w1 = waving.Frame(1, 1.5);
  EXPECT_EQ(s0.object_id, still.Frame(1, 1.5).object_id) << "without the effect the tree stands still";
  int changed = 0, changed_not_tree = 0;
  for (size_t i = 0; i < w0.object_id.size(); ++i) {
    if (w0.object_id[i] != w1.object_id[i]) {
      ++changed;
      if (w0.object_id[i] != kVegetationId && w1.object_id[i] != kVegetationId) ++changed_not_tree;
    }
  }
  EXPECT_GT(changed, 100) << "the crown sways between frames";
  EXPECT_EQ(changed_not_tree, 0) << "only the tree moves";
}

TEST(CameraEffects, LensDistortionBendsTheImageButNotTheCentre) {
  const Scenario campus = Load("campus");
  const scene::CameraSpec& backpack = *campus.world.FindCamera("backpack");
  ASSERT_NE(backpack.intrinsics.distortion[0], 0.0);
  scene::CameraSpec ideal = backpack;
  ideal.intrinsics.distortion = {};
  const SimImage d = SimulatedCamera(campus.world, backpack, {}, 1).Frame(0, 2.0);
  const SimImage p = SimulatedCamera(campus.world, ideal, {}, 1).Frame(0, 2.0);
  ASSERT_EQ(d.width, p.width);
  // The principal point does not move; far from it (barrel, k1 < 0) the content is pulled inwards.
  const int cu = static_cast<int>(backpack.intrinsics.cx), cv = static_cast<int>(backpack.intrinsics.cy);
  EXPECT_EQ(d.object_id[d.Index(cu, cv)], p.object_id[p.Index(cu, cv)]);
  size_t differ = 0;
  for (size_t i = 0; i < d.object_id.size(); ++i) differ += d.object_id[i] != p.object_id[i];
  EXPECT_GT(differ, d.object_id.size() / 200);
  for (uint32_t id : d.object_id) ASSERT_TRUE(id <= kOccluderId || IsBuildingId(id) || IsMoverId(id));
}

// Issue 19 (the pose's NEES, by cause): the moving camera's frame at time t is rendered from
// exactly scene::CameraPoseAt(t), the truth ave-bench pose scores against, and not from a
// neighbouring frame's pose.
TEST(CameraPipeline, MovingCameraFramesAreRenderedAtCameraPoseAtTheirTime) {
  const Scenario campus = Load("campus");
  scene::CameraSpec ideal = *campus.world.FindCamera("backpack");
  ideal.intrinsics.distortion = {};
  const SimulatedCamera cam(campus.world, ideal, {}, 1);
  const CampusRenderer plain(campus.world);
  for (int f : {0, 45, 150}) {
    const double t = f / 30.0;
    EXPECT_EQ(cam.PoseAt(t).translation, scene::CameraPoseAt(campus.world, ideal, t).translation);
    const SimImage frame = cam.Frame(f, t);
    const SimImage at_truth = plain.Render(ideal.intrinsics, scene::CameraPoseAt(campus.world, ideal, t), t);
    const SimImage next = plain.Render(ideal.intrinsics, scene::CameraPoseAt(campus.world, ideal, t + 1 / 30.0), t);
    ASSERT_GT(frame.width, 0);
    EXPECT_EQ(frame.bgr, at_truth.bgr) << "frame " << f;
    EXPECT_NE(frame.bgr, next.bgr) << "frame " << f;  // one frame's walk changes the image
  }
}

// Issue 19 (the backpack at its full rate): shading only the ideal pixels the lens's resampling
// reads changes no output bit, with every campus effect on.
TEST(CameraPipeline, ShadingOnlyThePixelsTheLensReadsIsBitIdentical) {
  const Scenario campus = Load("campus");
  const scene::CameraSpec& backpack = *campus.world.FindCamera("backpack");
  RendererOptions all;
  all.shade_only_read_pixels = false;
  const SimulatedCamera fast(campus.world, backpack, campus.EffectsForCamera("backpack"), campus.seed);
  const SimulatedCamera full(campus.world, backpack, campus.EffectsForCamera("backpack"), campus.seed, all);
  for (int f : {0, 100, 290}) {
    const SimImage a = fast.Frame(f, f / 30.0), b = full.Frame(f, f / 30.0);
    ASSERT_GT(a.width, 0);
    EXPECT_EQ(a.bgr, b.bgr) << "frame " << f;
    EXPECT_EQ(a.object_id, b.object_id) << "frame " << f;
    EXPECT_EQ(a.class_id, b.class_id) << "frame " << f;
    EXPECT_EQ(a.depth_m, b.depth_m) << "frame " << f;
  }
}

// Issue 19: pixel_area. Each pixel is the mean of its 3 x 3 fine samples: the truth layers are
// the centre sample's, which is the one-sample render's pixel centre (so, with a pinhole lens,
// they agree but for ties on an exact edge), and every pixel's colour is a blend of what its area
// shows: within the range of the one-sample render's 3 x 3 neighbourhood. With the backpack's
// lens the fine grid is bent too, and shading only the fine pixels it reads changes no bit.
TEST(CameraPipeline, PixelAreaBlendsEdgesAndKeepsTheCentreTruth) {
  const Scenario campus = Load("campus");
  const scene::CameraSpec& backpack = *campus.world.FindCamera("backpack");
  scene::CameraSpec pinhole = backpack;
  pinhole.intrinsics.distortion = {};
  EffectSet area;
  area.Enable(EffectKind::kPixelArea, EffectParams{{{"samples", 3}}});
  RendererOptions all;
  all.shade_only_read_pixels = false;
  {
    const SimulatedCamera lens(campus.world, backpack, area, campus.seed), lens_full(campus.world, backpack, area, campus.seed, all);
    const SimImage x = lens.Frame(15, 0.5), y = lens_full.Frame(15, 0.5);
    ASSERT_EQ(x.width, backpack.intrinsics.width);
    EXPECT_EQ(x.bgr, y.bgr);
    EXPECT_EQ(x.object_id, y.object_id);
    EXPECT_EQ(x.depth_m, y.depth_m);
  }
  const SimulatedCamera one(campus.world, pinhole, EffectSet{}, campus.seed), three(campus.world, pinhole, area, campus.seed);
  ResetEvaluations();
  const SimImage a = one.Frame(15, 0.5), b = three.Frame(15, 0.5);
  EXPECT_EQ(Evaluations(EffectKind::kPixelArea), 1u);
  ASSERT_EQ(a.width, b.width);
  ASSERT_EQ(a.height, b.height);
  const int w = a.width, h = a.height;
  size_t same_id = 0, edges = 0, blended = 0, inside = 0, checked = 0;
  for (int v = 1; v + 1 < h; ++v) {
    for (int u = 1; u + 1 < w; ++u) {
      const size_t i = a.Index(u, v);
      same_id += a.object_id[i] == b.object_id[i] && a.class_id[i] == b.class_id[i];
      bool edge = false;
      for (int dv = -1; dv <= 1; ++dv)
        for (int du = -1; du <= 1; ++du) edge |= a.object_id[a.Index(u + du, v + dv)] != a.object_id[i];
      if (!edge) continue;
      ++edges;
      bool in_range = true, differs = false;
      for (int ch = 0; ch < 3; ++ch) {
        int lo = 255, hi = 0;
        for (int dv = -1; dv <= 1; ++dv)
          for (int du = -1; du <= 1; ++du) {
            lo = std::min<int>(lo, a.bgr[3 * a.Index(u + du, v + dv) + ch]);
            hi = std::max<int>(hi, a.bgr[3 * a.Index(u + du, v + dv) + ch]);
          }
        const int x = b.bgr[3 * i + ch];
        in_range &= x >= lo - 12 && x <= hi + 12;  // the fine samples' own texture and shading
        differs |= std::abs(x - a.bgr[3 * i + ch]) > 8;
      }
      ++checked;
      inside += in_range;
      blended += differs;
    }
  }
  const size_t n = static_cast<size_t>(w - 2) * (h - 2);
  EXPECT_GT(same_id, n * 9995 / 10000) << "the truth layers are the pixel centre's";
  ASSERT_GT(edges, 1000u);
  EXPECT_GT(inside, checked * 97 / 100) << "an edge pixel blends what its neighbourhood shows";
  EXPECT_GT(blended, edges / 5) << "edge pixels are not the one-sample render's";
}

// Example frames with every campus effect, for people to look at (AVE_SIM_PNG_DIR).
TEST(CameraPipeline, WritesExampleFrames) {
  const char* env = std::getenv("AVE_SIM_PNG_DIR");
  const std::string dir = env ? env : std::filesystem::temp_directory_path().string();
  const Scenario campus = Load("campus");
  for (const char* id : {"cam1", "backpack"}) {
    const SimulatedCamera cam(campus.world, *campus.world.FindCamera(id), campus.EffectsForCamera(id), campus.seed);
    SimImage image = cam.Frame(15, 1.0);
    const cv::Mat bgr(image.height, image.width, CV_8UC3, image.bgr.data());
    ASSERT_TRUE(cv::imwrite(dir + "/sim_effects_" + id + ".png", bgr));
    cv::Mat cls(image.height, image.width, CV_8UC1, image.class_id.data());
    ASSERT_TRUE(cv::imwrite(dir + "/sim_class_" + id + ".png", cls * 25));
  }
}

}  // namespace
}  // namespace ave::sim
