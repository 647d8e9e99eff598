// Steps of the studio on made-up scenes with exact answers (a sphere seen by a ring of ideal
// cameras); the simulated studio scored against its truth is tests/truth/studio_truth_test.cc.
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <utility>

#include <gtest/gtest.h>

#include "model_store/studio/raster.h"
#include "model_store/studio/reconstruct.h"
#include "model_store/studio/segmentation.h"
#include "model_store/studio/studio_io.h"
#include "model_store/studio/surface.h"
#include "model_store/studio/texture.h"
#include "model_store/studio/visual_hull.h"

namespace ave::studio {
namespace {

constexpr double kPi = 3.14159265358979323846;
const Eigen::Vector3d kCentre(0.1, -0.05, 0.8);
constexpr double kRadius = 0.4;

std::vector<StudioCameraModel> Ring(int n, double radius = 3.0) {
  std::vector<StudioCameraModel> cams;
  for (int i = 0; i < n; ++i) {
    const double a = 2 * kPi * i / n;
    StudioCameraModel c;
    c.id = "cam" + std::to_string(i);
    c.intrinsics = PinholeIntrinsics::FromFov(320, 240, 60);
    c.world_from_camera = LookAt(Eigen::Vector3d(radius * std::cos(a), radius * std::sin(a), 1.5 + 0.3 * (i % 2)), Eigen::Vector3d(0, 0, 0.8));
    cams.push_back(c);
  }
  return cams;
}

// The sphere's exact silhouette: pixels whose ray passes within kRadius of the centre.
Mask SphereMask(const StudioCameraModel& c) {
  const PinholeIntrinsics& k = c.intrinsics;
  Mask m{k.width, k.height, std::vector<uint8_t>(static_cast<size_t>(k.width) * k.height, 0)};
  const Eigen::Vector3d eye = c.world_from_camera.translation;
  for (int v = 0; v < k.height; ++v)
    for (int u = 0; u < k.width; ++u) {
      const Eigen::Vector3d d = c.world_from_camera.rotation * PixelRay(k, Eigen::Vector2d(u, v));
      const Eigen::Vector3d to = kCentre - eye;
      if ((to - to.dot(d) * d).norm() < kRadius) m.data[static_cast<size_t>(v) * k.width + u] = 255;
    }
  return m;
}

std::vector<Mask> SphereMasks(const std::vector<StudioCameraModel>& cams) {
  std::vector<Mask> masks;
  for (const auto& c : cams) masks.push_back(SphereMask(c));
  return masks;
}

double VolumeM3(const VoxelGrid& g) { return static_cast<double>(g.Count()) * std::pow(g.voxel_m, 3); }

HullOptions SphereHull(double voxel_m) {
  HullOptions o;
  o.voxel_m = voxel_m;
  o.bounds_m = Eigen::AlignedBox3d(Eigen::Vector3d(-1, -1, 0), Eigen::Vector3d(1, 1, 2));
  return o;
}

// Every undirected edge of a closed, consistently oriented mesh is used once each way.
void ExpectWatertight(const SurfaceMesh& mesh) {
  std::map<std::pair<uint32_t, uint32_t>, int> directed;
  for (size_t t = 0; t < mesh.TriangleCount(); ++t)
    for (int i = 0; i < 3; ++i) ++directed[{mesh.indices[3 * t + i], mesh.indices[3 * t + (i + 1) % 3]}];
  int bad = 0;
  for (const auto& [edge, count] : directed) {
    const auto back = directed.find({edge.second, edge.first});
    if (count != 1 || back == directed.end() || back->second != 1) ++bad;
  }
  EXPECT_EQ(bad, 0) << "of " << directed.size() << " directed edges";
}

TEST(Segmentation, ShadowIsRemovedAndDarkClothesStay) {
  Image background{4, 1, {200, 202, 204, 200, 202, 204, 200, 202, 204, 200, 202, 204}};
  // pixel 0: background + noise; 1: shadow (45 % brightness); 2: dark trousers (different hue);
  // 3: blue shirt.
  Image image{4, 1, {203, 200, 205, 90, 91, 92, 77, 56, 64, 204, 115, 51}};
  SegmentationOptions o;
  o.open_radius_px = o.close_radius_px = 0;
  Mask shadow;
  absl::StatusOr<Mask> m = SegmentForeground(image, background, o, "camX", &shadow);
  ASSERT_TRUE(m.ok()) << m.status();
  EXPECT_EQ(m->data, (std::vector<uint8_t>{0, 0, 255, 255}));
  EXPECT_EQ(shadow.data, (std::vector<uint8_t>{0, 255, 0, 0}));
  o.remove_shadows = false;
  m = SegmentForeground(image, background, o, "camX");
  ASSERT_TRUE(m.ok());
  EXPECT_EQ(m->data, (std::vector<uint8_t>{0, 255, 255, 255}));
}

TEST(Segmentation, SizeMismatchNamesTheCamera) {
  Image a{4, 1, std::vector<uint8_t>(12, 0)}, b{2, 2, std::vector<uint8_t>(12, 0)};
  absl::StatusOr<Mask> m = SegmentForeground(a, b, {}, "ring07");
  ASSERT_FALSE(m.ok());
  EXPECT_NE(m.status().message().find("ring07"), std::string::npos) << m.status();
}

TEST(Segmentation, MedianBackgroundIgnoresAPassingActor) {
  std::vector<Image> frames(5, Image{2, 1, {10, 20, 30, 10, 20, 30}});
  frames[1].bgr[0] = 250;  // the actor passes pixel 0 in two frames
  frames[3].bgr[0] = 240;
  absl::StatusOr<Image> bg = MedianBackground(frames, "cam0");
  ASSERT_TRUE(bg.ok());
  EXPECT_EQ(bg->bgr, (std::vector<uint8_t>{10, 20, 30, 10, 20, 30}));
}

TEST(VisualHull, SphereVolumeConvergesAndHierarchyMatchesFlat) {
  const auto cams = Ring(12);
  const auto masks = SphereMasks(cams);
  const double truth = 4.0 / 3.0 * kPi * std::pow(kRadius, 3);
  HullOptions o = SphereHull(0.02);
  o.max_background_votes = 0;
  HullStats hs, fs;
  absl::StatusOr<VoxelGrid> h = CarveVisualHull(cams, masks, o, &hs);
  ASSERT_TRUE(h.ok()) << h.status();
  o.hierarchical = false;
  absl::StatusOr<VoxelGrid> f = CarveVisualHull(cams, masks, o, &fs);
  ASSERT_TRUE(f.ok()) << f.status();
  // The same voxels, far fewer projections.
  EXPECT_EQ(h->Count(), f->Count());
  EXPECT_EQ(h->origin_m, f->origin_m);
  EXPECT_EQ(h->occupied, f->occupied);
  EXPECT_LT(hs.voxels_tested + hs.cells_tested, fs.voxels_tested / 4);
  // A visual hull contains the object and, with 12 views, is close to it.
  EXPECT_GT(VolumeM3(*h), truth * 0.97);
  EXPECT_LT(VolumeM3(*h), truth * 1.15);
}

TEST(VisualHull, ToleranceKeepsTheHullWhenOneSilhouetteIsEmptyOrFull) {
  const auto cams = Ring(12);
  auto masks = SphereMasks(cams);
  HullOptions o = SphereHull(0.02);
  absl::StatusOr<VoxelGrid> good = CarveVisualHull(cams, masks, o);
  ASSERT_TRUE(good.ok());
  HullOptions strict_options = o;
  strict_options.max_background_votes = 0;
  absl::StatusOr<VoxelGrid> strict_all = CarveVisualHull(cams, masks, strict_options);
  ASSERT_TRUE(strict_all.ok());
  // With every silhouette good the strict pass makes the tolerance free: the strict hull.
  EXPECT_EQ(good->Count(), strict_all->Count());
  std::fill(masks[3].data.begin(), masks[3].data.end(), 0);  // this camera lost the actor
  HullStats stats;
  absl::StatusOr<VoxelGrid> empty = CarveVisualHull(cams, masks, o, &stats);
  ASSERT_TRUE(empty.ok());
  EXPECT_EQ(stats.bad_cameras, std::vector<std::string>{"cam3"});
  // The hull of the other 11 cameras: it holds the strict hull of all 12 and is close to it.
  EXPECT_GE(empty->Count(), strict_all->Count());
  EXPECT_LT(empty->Count(), strict_all->Count() * 1.02);
  std::fill(masks[3].data.begin(), masks[3].data.end(), 255);  // all foreground (lights off, lens cap ...)
  absl::StatusOr<VoxelGrid> full = CarveVisualHull(cams, masks, o);
  ASSERT_TRUE(full.ok());
  EXPECT_GE(full->Count(), good->Count());
  EXPECT_LT(full->Count(), good->Count() * 1.1);
  // Without tolerance an empty silhouette carves everything.
  std::fill(masks[3].data.begin(), masks[3].data.end(), 0);
  o.max_background_votes = 0;
  absl::StatusOr<VoxelGrid> strict = CarveVisualHull(cams, masks, o);
  ASSERT_TRUE(strict.ok());
  EXPECT_EQ(strict->Count(), 0);
}

TEST(VisualHull, ACameraThatDoesNotSeeTheVoxelDoesNotVote) {
  auto cams = Ring(12);
  auto masks = SphereMasks(cams);
  HullOptions o = SphereHull(0.02);
  o.max_background_votes = 0;
  absl::StatusOr<VoxelGrid> all = CarveVisualHull(cams, masks, o);
  ASSERT_TRUE(all.ok());
  // Camera 5 zoomed in so that the sphere's top half is outside its image.
  cams[5].intrinsics.fx = cams[5].intrinsics.fy = 900;
  cams[5].intrinsics.cy = 0;
  masks[5] = SphereMask(cams[5]);
  absl::StatusOr<VoxelGrid> partial = CarveVisualHull(cams, masks, o);
  ASSERT_TRUE(partial.ok());
  EXPECT_NEAR(static_cast<double>(partial->Count()), static_cast<double>(all->Count()), 0.02 * all->Count());
}

TEST(VisualHull, CollinearCamerasGiveAClearErrorOrExplicitBounds) {
  std::vector<StudioCameraModel> cams = Ring(2);  // two cameras facing each other: a line
  auto masks = SphereMasks(cams);
  HullOptions o;
  o.voxel_m = 0.05;
  absl::StatusOr<VoxelGrid> h = CarveVisualHull(cams, masks, o);
  ASSERT_FALSE(h.ok());
  EXPECT_NE(h.status().message().find("along y"), std::string::npos) << h.status();
  EXPECT_NE(h.status().message().find("bounds_m"), std::string::npos) << h.status();
  o = SphereHull(0.05);  // with bounds: a bounded result (two views carve a cylinder-ish hull)
  h = CarveVisualHull(cams, masks, o);
  ASSERT_TRUE(h.ok()) << h.status();
  EXPECT_GT(h->Count(), 0);
  EXPECT_LE(VolumeM3(*h), 2.0 * 2.0 * 2.0 + 1e-9);
}

TEST(VisualHull, BadInputNamesTheCamera) {
  auto cams = Ring(3);
  auto masks = SphereMasks(cams);
  masks[1].width = 10;
  absl::StatusOr<VoxelGrid> h = CarveVisualHull(cams, masks, SphereHull(0.05));
  ASSERT_FALSE(h.ok());
  EXPECT_NE(h.status().message().find("cam1"), std::string::npos) << h.status();
  HullOptions o = SphereHull(0.05);
  o.voxel_m = -1;
  EXPECT_FALSE(CarveVisualHull(cams, SphereMasks(cams), o).ok());
}

TEST(Surface, OwnMarchingCubesIsWatertightOnARandomBlob) {
  VoxelGrid g;
  g.voxel_m = 0.01;
  g.size = Eigen::Vector3i(14, 12, 13);
  g.occupied.assign(14 * 12 * 13, 0);
  uint32_t s = 12345;
  for (int z = 1; z < 12; ++z)
    for (int y = 1; y < 11; ++y)
      for (int x = 1; x < 13; ++x) {
        s = s * 1664525u + 1013904223u;
        g.occupied[g.Index(x, y, z)] = (s >> 28) < 9;  // ~56 % full, every ambiguous case appears
      }
  for (SurfaceMethod method : {SurfaceMethod::kOwnMarchingCubes, SurfaceMethod::kVtkFlyingEdges, SurfaceMethod::kVtkMarchingCubes}) {
    if (method != SurfaceMethod::kOwnMarchingCubes && !VtkSurfaceAvailable()) continue;
    for (int passes : {0, 1}) {
      SurfaceOptions o;
      o.method = method;
      o.smooth_passes = passes;
      absl::StatusOr<SurfaceMesh> m = ExtractSurface(g, o);
      ASSERT_TRUE(m.ok()) << m.status();
      EXPECT_GT(m->TriangleCount(), 100u);
      SCOPED_TRACE(static_cast<int>(method));
      ExpectWatertight(*m);
    }
  }
}

TEST(Surface, SphereMeshIsClosedOutwardAndMatchesVtk) {
  const auto cams = Ring(12);
  absl::StatusOr<VoxelGrid> h = CarveVisualHull(cams, SphereMasks(cams), SphereHull(0.02));
  ASSERT_TRUE(h.ok());
  SurfaceOptions own_options;
  own_options.method = SurfaceMethod::kOwnMarchingCubes;
  absl::StatusOr<SurfaceMesh> own = ExtractSurface(*h, own_options);
  ASSERT_TRUE(own.ok());
  ExpectWatertight(*own);
  double volume6 = 0, max_radial_error = 0;
  for (size_t t = 0; t < own->TriangleCount(); ++t) {
    const Eigen::Vector3d a = own->positions_m[own->indices[3 * t]].cast<double>(), b = own->positions_m[own->indices[3 * t + 1]].cast<double>(),
                          c = own->positions_m[own->indices[3 * t + 2]].cast<double>();
    volume6 += a.dot(b.cross(c));
  }
  for (size_t i = 0; i < own->positions_m.size(); ++i) {
    const Eigen::Vector3d p = own->positions_m[i].cast<double>();
    max_radial_error = std::max(max_radial_error, std::abs((p - kCentre).norm() - kRadius));
    EXPECT_GT(own->normals[i].cast<double>().dot((p - kCentre).normalized()), 0.0);  // outward
  }
  EXPECT_GT(volume6, 0);
  EXPECT_LT(max_radial_error, 0.06);
  if (!VtkSurfaceAvailable()) GTEST_SKIP() << "no VTK in this build";
  SurfaceOptions vo;
  vo.method = SurfaceMethod::kVtkFlyingEdges;
  absl::StatusOr<SurfaceMesh> vtk = ExtractSurface(*h, vo);
  ASSERT_TRUE(vtk.ok()) << vtk.status();
  EXPECT_NEAR(static_cast<double>(vtk->TriangleCount()), static_cast<double>(own->TriangleCount()), 0.02 * own->TriangleCount());
  ExpectWatertight(*vtk);
}

TEST(Texture, BackIsTexturedFromABackCameraAndColoursComeThrough) {
  // A sphere, red on its +x half and green on its -x half, seen by cameras on +x and -x.
  std::vector<StudioCameraModel> cams = Ring(8);
  std::vector<Image> images;
  for (const auto& c : cams) {
    const PinholeIntrinsics& k = c.intrinsics;
    Image img{k.width, k.height, std::vector<uint8_t>(static_cast<size_t>(k.width) * k.height * 3, 40)};
    const Eigen::Vector3d eye = c.world_from_camera.translation;
    for (int v = 0; v < k.height; ++v)
      for (int u = 0; u < k.width; ++u) {
        const Eigen::Vector3d d = c.world_from_camera.rotation * PixelRay(k, Eigen::Vector2d(u, v));
        const Eigen::Vector3d to = kCentre - eye;
        const double tc = to.dot(d), miss2 = (to - tc * d).squaredNorm();
        if (miss2 >= kRadius * kRadius) continue;
        const Eigen::Vector3d hit = eye + (tc - std::sqrt(kRadius * kRadius - miss2)) * d;
        uint8_t* px = &img.bgr[(static_cast<size_t>(v) * k.width + u) * 3];
        px[0] = 0;
        px[1] = hit.x() > kCentre.x() ? 0 : 255;
        px[2] = hit.x() > kCentre.x() ? 255 : 0;
      }
    images.push_back(std::move(img));
  }
  absl::StatusOr<FrameSetResult> r = ReconstructFromSilhouettes(cams, images, SphereMasks(cams), [] {
    ReconstructOptions o;
    o.hull = SphereHull(0.02);
    return o;
  }());
  ASSERT_TRUE(r.ok()) << r.status();
  const avatar::AvatarFrame& f = r->textured;
  ASSERT_EQ(f.uv.size(), f.positions_m.size());
  ASSERT_EQ(f.atlas_rgb.size(), static_cast<size_t>(f.atlas_width) * f.atlas_height * 3);
  EXPECT_GT(r->texture_stats.charts, 1);
  // Sample the atlas at each triangle's centre uv: red for x > centre + 5 cm, green for x < centre - 5 cm.
  int right = 0, wrong = 0;  // wrong: the other half's colour (textured through the sphere)
  for (size_t t = 0; t + 2 < f.indices.size(); t += 3) {
    const Eigen::Vector3f p = (f.positions_m[f.indices[t]] + f.positions_m[f.indices[t + 1]] + f.positions_m[f.indices[t + 2]]) / 3;
    const Eigen::Vector2f uv = (f.uv[f.indices[t]] + f.uv[f.indices[t + 1]] + f.uv[f.indices[t + 2]]) / 3;
    for (int i = 0; i < 3; ++i) ASSERT_TRUE(f.uv[f.indices[t + i]].x() >= 0 && f.uv[f.indices[t + i]].x() <= 1);
    const int x = std::clamp(static_cast<int>(uv.x() * f.atlas_width), 0, f.atlas_width - 1);
    const int y = std::clamp(static_cast<int>(uv.y() * f.atlas_height), 0, f.atlas_height - 1);
    const uint8_t* rgb = &f.atlas_rgb[(static_cast<size_t>(y) * f.atlas_width + x) * 3];
    const bool red = rgb[0] > 200 && rgb[1] < 50, green = rgb[1] > 200 && rgb[0] < 50;
    if (p.x() > kCentre.x() + 0.05) right += red, wrong += green;
    if (p.x() < kCentre.x() - 0.05) right += green, wrong += red;
  }
  EXPECT_GT(right, 500);
  EXPECT_LT(wrong, right / 100) << "right " << right;
  // Re-rendered from a camera, the textured sphere looks like the camera's image.
  Mask covered;
  const Image back = RenderTextured(cams[4], f, &covered);
  double err = 0;
  int n = 0;
  const Mask truth = SphereMask(cams[4]);
  for (size_t i = 0; i < truth.data.size(); ++i) {
    if (!truth.data[i] || !covered.data[i]) continue;
    for (int c = 0; c < 3; ++c) err += std::abs(back.bgr[3 * i + c] - images[4].bgr[3 * i + c]);
    n += 3;
  }
  ASSERT_GT(n, 1000);
  EXPECT_LT(err / n, 20.0);
}

TEST(StudioIo, CalibrationErrorsNameFileCameraAndField) {
  const std::string path = (std::filesystem::temp_directory_path() / ("ave_studio_cal_" + std::to_string(::getpid()) + ".json")).string();
  const std::string cam0 = R"({"id": "ring00", "width": 64, "height": 48, "fx": 50, "fy": 50, "cx": 31.5, "cy": 23.5,
      "distortion": [0, 0, 0, 0, 0], "world_from_camera": {"qw": 1, "qx": 0, "qy": 0, "qz": 0, "tx": 0, "ty": 0, "tz": 0}})";
  auto write = [&](const std::string& cameras) {
    std::ofstream(path) << R"({"format": "ave-studio-calibration-1", "fps": 10, "frames": 2, "floor_z_m": 0, "cameras": [)" << cameras << "]}";
  };
  write(cam0);
  absl::StatusOr<StudioCalibration> cal = ReadStudioCalibration(path);
  ASSERT_TRUE(cal.ok()) << cal.status();
  ASSERT_EQ(cal->cameras.size(), 1u);
  EXPECT_EQ(cal->cameras[0].id, "ring00");
  EXPECT_EQ(cal->frames, 2);
  std::string no_fx = cam0;
  no_fx.replace(no_fx.find("\"fx\": 50, "), 10, "");
  no_fx.replace(no_fx.find("ring00"), 6, "ring01");
  write(cam0 + ", " + no_fx);
  cal = ReadStudioCalibration(path);
  ASSERT_FALSE(cal.ok());
  for (const char* part : {"cameras[1]", "ring01", "'fx'"}) EXPECT_NE(cal.status().message().find(part), std::string::npos) << cal.status();
  EXPECT_NE(cal.status().message().find(path), std::string::npos);
  std::string distorted = cam0;
  distorted.replace(distorted.find("[0, 0, 0, 0, 0]"), 15, "[0.1, 0, 0, 0, 0]");
  write(distorted);
  cal = ReadStudioCalibration(path);
  ASSERT_FALSE(cal.ok());
  EXPECT_NE(cal.status().message().find("distortion"), std::string::npos) << cal.status();
  write(cam0 + ", " + cam0);
  cal = ReadStudioCalibration(path);
  ASSERT_FALSE(cal.ok());
  EXPECT_NE(cal.status().message().find("used twice"), std::string::npos) << cal.status();
  std::filesystem::remove(path);
}

}  // namespace
}  // namespace ave::studio
