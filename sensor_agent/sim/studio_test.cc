#include "sensor_agent/sim/studio.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "model_store/geometry/bvh.h"

namespace ave::sim {
namespace {

TEST(Studio, CamerasAreCalibratedAroundTheActor) {
  const StudioSpec spec;
  const std::vector<StudioCamera> cams = StudioCameras(spec);
  ASSERT_EQ(cams.size(), 14u);
  EXPECT_EQ(cams.back().id, "overhead");
  for (const StudioCamera& cam : cams) {
    EXPECT_EQ(cam.intrinsics.Check(), "");
    const Eigen::Vector3d c = cam.world_from_camera.translation;
    if (cam.id != "overhead") {
      EXPECT_NEAR(c.head<2>().norm(), spec.radius_m, 1e-9);
    }
    // The actor's centre projects near the image centre in every view, the overhead one included.
    const auto uv = ProjectToPixel(cam.intrinsics, cam.world_from_camera.Inverse() * Eigen::Vector3d(0, 0, cam.id == "overhead" ? 0 : 0.9));
    ASSERT_TRUE(uv.has_value()) << cam.id;
    EXPECT_NEAR(uv->x(), cam.intrinsics.cx, 1e-6) << cam.id;
    EXPECT_NEAR(uv->y(), cam.intrinsics.cy, 1e-6) << cam.id;
  }
  StudioSpec bad;
  bad.cameras = 0;
  EXPECT_THAT(bad.Check(), ::testing::HasSubstr("cameras"));
  bad = StudioSpec();
  bad.fps = 0;
  EXPECT_THAT(bad.Check(), ::testing::HasSubstr("fps"));
}

TEST(Studio, ActorWalksWithSwingingLimbs) {
  const StudioActorState a = StudioActorAt(0), b = StudioActorAt(1);
  EXPECT_NEAR(a.ground_m.head<2>().norm(), 0.6, 1e-12);
  // 0.7 m of arc in 1 s on the 0.6 m circle: the chord is 2 r sin(arc / 2r).
  EXPECT_NEAR((b.ground_m - a.ground_m).norm(), 2 * 0.6 * std::sin(0.7 / 1.2), 1e-9);
  const TriangleMesh m0 = StudioActorMesh(0), m1 = StudioActorMesh(0.3);
  ASSERT_EQ(m0.TriangleCount(), m1.TriangleCount());
  Eigen::Vector3f lo = Eigen::Vector3f::Constant(1e9), hi = -lo;
  for (const auto& p : m0.positions) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  EXPECT_GT(lo.z(), -1e-6);          // above the floor
  EXPECT_LT(lo.z(), 0.1);            // feet near it
  EXPECT_NEAR(hi.z(), 1.8, 0.1);     // a person's height
}

// The body (default) and the boxes share the skeleton and the walk: over a whole cycle both stand
// on the floor at a person's height, and the body's rounded parts hold about the boxes' volume
// (cross-sections of the boxes' area, rounded ends, limbs reaching a little past their joints).
TEST(Studio, BodyAndBoxesShareTheSkeletonAndTheWalk) {
  auto volume = [](const TriangleMesh& m) {
    double v = 0;
    for (size_t t = 0; t < m.TriangleCount(); ++t) {
      v += m.positions[m.indices[3 * t]].cast<double>().dot(
               m.positions[m.indices[3 * t + 1]].cast<double>().cross(m.positions[m.indices[3 * t + 2]].cast<double>())) / 6;
    }
    return v;
  };
  for (double t_s = 0; t_s < 1.2; t_s += 0.1) {
    const TriangleMesh body = StudioActorMesh(t_s), boxes = StudioActorMesh(t_s, StudioActor::kBoxes);
    EXPECT_EQ(boxes.TriangleCount(), 13u * 12u);
    EXPECT_GT(body.TriangleCount(), 13u * 20u * 4u);  // 20-sided rings, rounded ends
    Eigen::Vector3f lo[2], hi[2];
    for (int k = 0; k < 2; ++k) {
      lo[k] = Eigen::Vector3f::Constant(1e9), hi[k] = -lo[k];
      for (const auto& p : (k ? boxes : body).positions) lo[k] = lo[k].cwiseMin(p), hi[k] = hi[k].cwiseMax(p);
      EXPECT_GT(lo[k].z(), 0.005) << k << " at " << t_s << " s";  // shoes on the floor, nothing through it
      EXPECT_LT(lo[k].z(), 0.1) << k << " at " << t_s << " s";
      EXPECT_NEAR(hi[k].z(), 1.8, 0.1) << k << " at " << t_s << " s";
    }
    EXPECT_LT((lo[0] - lo[1]).norm() + (hi[0] - hi[1]).norm(), 0.15) << t_s;  // the same figure's extent
    const double ratio = volume(body) / volume(boxes);  // sums over parts: overlaps counted twice in both
    EXPECT_GT(ratio, 0.8) << t_s;
    EXPECT_LT(ratio, 1.1) << t_s;
  }
  EXPECT_STREQ(StudioActorName(StudioActor::kBoxes), "boxes");
  EXPECT_EQ(ParseStudioActor("body"), StudioActor::kBody);
  EXPECT_FALSE(ParseStudioActor("Body").has_value());
}

// Every pixel centre whose ray hits the actor is in the silhouette, and no other pixel is.
TEST(Studio, SilhouettesAreTheActorsProjectionAndTheShadowIsOutsideThem) {
  StudioSpec spec;
  spec.width = 320;
  spec.height = 240;
  const std::vector<StudioCamera> cams = StudioCameras(spec);
  ResetEvaluations();
  int cameras_with_shadow = 0;
  for (double t_s : {0.0, 0.75}) {
    const TriangleMesh actor = StudioActorMesh(t_s);
    const MeshBvh bvh(actor);
    for (const StudioCamera& cam : cams) {
      const StudioView view = RenderStudioView(cam, EffectSet{}, 1, 0, t_s);
      ASSERT_EQ(view.width, 320);
      size_t silhouette = 0, mismatches = 0, shadow = 0;
      double shadow_grey = 0, floor_grey = 0;
      size_t floor_n = 0;
      for (int v = 0; v < view.height; ++v) {
        for (int u = 0; u < view.width; ++u) {
          const size_t i = static_cast<size_t>(v) * view.width + u;
          const Eigen::Vector3d d = cam.world_from_camera.rotation * PixelRay(cam.intrinsics, Eigen::Vector2d(u, v));
          const bool hit = bvh.Raycast(cam.world_from_camera.translation, d).has_value();
          silhouette += view.silhouette[i] != 0;
          mismatches += hit != (view.silhouette[i] != 0);
          EXPECT_FALSE(view.shadow[i] && view.silhouette[i]) << cam.id << " pixel " << u << "," << v;
          const double grey = (view.bgr[3 * i] + view.bgr[3 * i + 1] + view.bgr[3 * i + 2]) / 3.0;
          if (view.shadow[i]) {
            ++shadow;
            shadow_grey += grey;
            // The shadowed floor point sees the actor towards the light.
            const double s = -cam.world_from_camera.translation.z() / d.z();
            const Eigen::Vector3d p = cam.world_from_camera.translation + s * d;
            EXPECT_NEAR(p.z(), 0, 1e-9);
            EXPECT_TRUE(bvh.Raycast(p, StudioLightDirection()).has_value());
          } else if (!view.silhouette[i] && d.z() < 0) {
            floor_grey += grey;
            ++floor_n;
          }
        }
      }
      EXPECT_GT(silhouette, 300u) << cam.id;
      // Edge pixels whose centre lies exactly on a triangle edge may go either way.
      EXPECT_LE(mismatches, silhouette / 200 + 2) << cam.id;
      if (shadow > 50) {
        ++cameras_with_shadow;
        EXPECT_LT(shadow_grey / shadow, 0.7 * floor_grey / floor_n) << cam.id;
      }
    }
  }
  EXPECT_GE(cameras_with_shadow, 20);  // of 28 views, the shadow shows in most
  EXPECT_EQ(Evaluations(EffectKind::kCameraNoise), 0u);
  EXPECT_EQ(Evaluations(EffectKind::kIllumination), 0u);
}

TEST(Studio, DeterministicAndNoiseOnlyWhenNamed) {
  StudioSpec spec;
  spec.width = 160;
  spec.height = 120;
  const StudioCamera cam = StudioCameras(spec)[3];
  const StudioView a = RenderStudioView(cam, EffectSet{}, 1, 4, 0.4);
  const StudioView b = RenderStudioView(cam, EffectSet{}, 1, 4, 0.4);
  EXPECT_EQ(a.bgr, b.bgr);
  EffectSet noise;
  noise.Enable(EffectKind::kCameraNoise, {{{"sigma", 4.0}}});
  ResetEvaluations();
  const StudioView n1 = RenderStudioView(cam, noise, 1, 4, 0.4), n2 = RenderStudioView(cam, noise, 1, 4, 0.4);
  EXPECT_EQ(n1.bgr, n2.bgr);
  EXPECT_NE(n1.bgr, a.bgr);
  EXPECT_EQ(n1.silhouette, a.silhouette);  // truth is not noisy
  EXPECT_EQ(Evaluations(EffectKind::kCameraNoise), 2u);
}

TEST(Studio, BackgroundPlateIsTheStudioWithoutActorOrShadow) {
  StudioSpec spec;
  spec.width = 160;
  spec.height = 120;
  const StudioCamera cam = StudioCameras(spec)[2];
  const StudioView view = RenderStudioView(cam, EffectSet{}, 1, 3, 0.3);
  const StudioView plate = RenderStudioBackground(cam, EffectSet{}, 1);
  ASSERT_EQ(plate.bgr.size(), view.bgr.size());
  EXPECT_EQ(std::count(plate.silhouette.begin(), plate.silhouette.end(), 255), 0);
  EXPECT_EQ(std::count(plate.shadow.begin(), plate.shadow.end(), 255), 0);
  int differ = 0, covered = 0;
  for (size_t i = 0; i < view.silhouette.size(); ++i) {
    const bool actor = view.silhouette[i] || view.shadow[i];
    covered += actor;
    const bool same = view.bgr[3 * i] == plate.bgr[3 * i] && view.bgr[3 * i + 1] == plate.bgr[3 * i + 1] && view.bgr[3 * i + 2] == plate.bgr[3 * i + 2];
    if (!actor) EXPECT_TRUE(same) << "pixel " << i;  // away from the actor and its shadow: the same studio
    differ += actor && !same;
  }
  EXPECT_GT(covered, 100);
  EXPECT_GT(differ, covered / 2);
}

TEST(Studio, WritesImagesMasksAndCalibration) {
  StudioSpec spec;
  spec.cameras = 3;
  spec.width = 160;
  spec.height = 120;
  spec.duration_s = 0.2;
  const std::string dir = (std::filesystem::temp_directory_path() / ("ave_studio_" + std::to_string(::getpid()))).string();
  const auto t0 = std::chrono::steady_clock::now();
  ASSERT_TRUE(SimulateStudio(spec, EffectSet{}, 1, dir).ok());
  std::printf("studio 4 cameras x 2 frames at 160x120: %.0f ms\n",
              std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  for (const char* cam : {"ring00", "ring01", "ring02", "overhead"}) {
    for (const char* f : {"0000", "0001"}) {
      const cv::Mat image = cv::imread(dir + "/" + cam + "/image_" + f + ".png", cv::IMREAD_COLOR);
      const cv::Mat mask = cv::imread(dir + "/" + cam + "/mask_" + f + ".png", cv::IMREAD_GRAYSCALE);
      ASSERT_FALSE(image.empty()) << cam << " " << f;
      ASSERT_EQ(mask.size(), image.size());
      EXPECT_GT(cv::countNonZero(mask), 50);
    }
    const cv::Mat plate = cv::imread(dir + "/" + cam + "/background.png", cv::IMREAD_COLOR);
    ASSERT_FALSE(plate.empty()) << cam;
  }
  std::ifstream json(dir + "/calibration.json");
  std::stringstream ss;
  ss << json.rdbuf();
  EXPECT_THAT(ss.str(), ::testing::HasSubstr("\"id\": \"overhead\""));
  EXPECT_THAT(ss.str(), ::testing::HasSubstr("\"world_from_camera\""));
  std::filesystem::remove_all(dir);
  spec.fps = -1;
  EXPECT_EQ(SimulateStudio(spec, EffectSet{}, 1, dir).code(), absl::StatusCode::kInvalidArgument);
  EXPECT_FALSE(std::filesystem::exists(dir));
}

TEST(Studio, FullSizeFrameTimingAndPng) {
  const StudioSpec spec;
  const std::vector<StudioCamera> cams = StudioCameras(spec);
  const auto t0 = std::chrono::steady_clock::now();
  const StudioView view = RenderStudioView(cams[2], EffectSet{}, 1, 0, 0.5);
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  std::printf("studio view 640x480: %.1f ms\n", ms);  // printed only: timed assertions fail under load
  EXPECT_EQ(view.width, 640);
  EXPECT_EQ(view.bgr.size(), static_cast<size_t>(view.width) * view.height * 3);
  const char* dir = std::getenv("AVE_SIM_PNG_DIR");
  if (dir == nullptr) return;
  cv::Mat image(view.height, view.width, CV_8UC3, const_cast<uint8_t*>(view.bgr.data()));
  cv::Mat mask(view.height, view.width, CV_8UC1, const_cast<uint8_t*>(view.silhouette.data()));
  cv::Mat shadow(view.height, view.width, CV_8UC1, const_cast<uint8_t*>(view.shadow.data()));
  cv::Mat side_by_side, mask_bgr(view.height, view.width, CV_8UC3, cv::Scalar(0, 0, 0));
  mask_bgr.setTo(cv::Scalar(255, 255, 255), mask);
  mask_bgr.setTo(cv::Scalar(0, 0, 160), shadow);  // shadow in dark red: NOT part of the silhouette
  cv::hconcat(image, mask_bgr, side_by_side);
  EXPECT_TRUE(cv::imwrite(std::string(dir) + "/studio_view.png", side_by_side));
}

}  // namespace
}  // namespace ave::sim
