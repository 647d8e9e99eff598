#include "sensor_agent/sim/airborne_lidar.h"

#include <chrono>
#include <cmath>
#include <filesystem>
#include <map>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "sensor_agent/sim/sensor_test_site.h"

namespace ave::sim {
namespace {

std::string TempLas(const std::string& name) {
  return (std::filesystem::temp_directory_path() / ("ave_" + name + "_" + std::to_string(::getpid()) + ".las")).string();
}

// The courtyard without movers: every class has an analytic source.
scene::SyntheticCampus StillSite() {
  scene::SyntheticCampus site = testing::CourtyardSite();
  site.movers.clear();
  return site;
}

// Horizontal distance from (x, y) to the nearest building footprint edge (negative inside).
double FootprintMargin(const scene::SyntheticCampus& site, double x, double y) {
  double best = 1e9;
  for (double r : {0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.3, 0.4, 0.6, 0.8, 1.0})
    for (int k = 0; k < 16; ++k) {
      const double a = k * M_PI / 8;
      if ((site.BuildingAt(x + r * std::cos(a), y + r * std::sin(a)) >= 0) != (site.BuildingAt(x, y) >= 0)) best = std::min(best, r);
    }
  return best;
}

bool UnderTree(const scene::SyntheticCampus& site, double x, double y, double margin_m) {
  for (const auto& t : site.trees)
    if ((Eigen::Vector2d(x, y) - t.position_m).norm() < t.crown_radius_m + margin_m) return true;
  return false;
}

TEST(AirborneLidar, LasHeaderRoundTripsAndClassesMatchThePrimitives) {
  const scene::SyntheticCampus site = StillSite();
  AirborneLidarSpec spec;
  spec.point_spacing_m = 0.7;
  const std::string path = TempLas("airborne");
  ResetEvaluations();
  const auto t0 = std::chrono::steady_clock::now();
  ASSERT_TRUE(SimulateAirborneLidar(site, spec, EffectSet{}, 3, path).ok());
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  const absl::StatusOr<LasFile> las = ReadLas6(path);
  ASSERT_TRUE(las.ok()) << las.status();
  std::printf("airborne lidar: %llu points in %.0f ms\n", static_cast<unsigned long long>(las->point_count), ms);
  EXPECT_EQ(las->version_major, 1);
  EXPECT_EQ(las->version_minor, 4);
  EXPECT_EQ(las->header_size, 375);
  EXPECT_EQ(las->offset_to_points, 375u);
  EXPECT_EQ(las->point_format, 6);
  EXPECT_EQ(las->record_length, 30);
  EXPECT_EQ(std::filesystem::file_size(path), 375 + 30 * las->point_count);
  EXPECT_EQ(las->points_by_return[0], las->point_count);
  EXPECT_EQ(las->scale, Eigen::Vector3d::Constant(0.001));
  EXPECT_LT((las->offset - site.origin).cwiseAbs().maxCoeff(), 0.5 + 1e-9);
  // About one point per spacing² over the 120 m x 120 m tile, more where the swath crosses walls.
  const double expected = (120 / 0.7) * (120 / 0.7);
  EXPECT_GT(las->point_count, 0.8 * expected);
  EXPECT_LT(las->point_count, 1.3 * expected);

  std::map<int, int> classes;
  int checked_ground = 0, checked_roof = 0;
  double gps_prev = -1;
  for (const LasPoint6& p : las->points) {
    ++classes[p.classification];
    const Eigen::Vector3d local = p.p_world - site.origin;
    EXPECT_TRUE((p.p_world.array() >= las->min.array() - 1e-9).all() && (p.p_world.array() <= las->max.array() + 1e-9).all());
    EXPECT_LE(std::abs(p.scan_angle_deg), spec.swath_half_angle_deg + 0.01);
    EXPECT_GE(p.gps_time, gps_prev - 0.02);  // time runs on (within a mirror sweep)
    gps_prev = std::max(gps_prev, p.gps_time);
    EXPECT_EQ(p.return_number, 1);
    EXPECT_EQ(p.number_of_returns, 1);
    EXPECT_EQ(p.intensity, 25700);  // intensity by material not named
    const int b = site.BuildingAt(local.x(), local.y());
    // What a ray straight down at this xy hits, from the scenario's primitives.
    if (p.classification == kLasBuilding) {
      ASSERT_GE(p.point_source_id, 1);
      const int id = p.point_source_id - 1;
      EXPECT_TRUE(b == id || FootprintMargin(site, local.x(), local.y()) < 0.02) << "building point outside its footprint";
      if (b == id && FootprintMargin(site, local.x(), local.y()) > 0.3) {
        const std::optional<double> roof = site.RoofHeightAt(site.buildings[id], local.x(), local.y());
        ASSERT_TRUE(roof.has_value());
        EXPECT_NEAR(local.z(), *roof, 0.002);
        ++checked_roof;
      }
    } else {
      EXPECT_EQ(p.point_source_id, 0);
    }
    if (p.classification == kLasGround) {
      EXPECT_NEAR(local.z(), site.TerrainHeight(local.x(), local.y()), 0.005);
      EXPECT_TRUE(b < 0 || FootprintMargin(site, local.x(), local.y()) < 0.02) << "ground inside a building";
      ++checked_ground;
    }
    if (p.classification == kLasHighVegetation) {
      EXPECT_TRUE(UnderTree(site, local.x(), local.y(), 0.05));
    }
    if (p.classification == kLasUnclassified) {
      const Eigen::Vector2d kiosk = site.objects[0].position_m;
      EXPECT_LT((local.head<2>() - kiosk).cwiseAbs().maxCoeff(), 1.6);
    }
    // Conversely: well inside a footprint and clear of trees, a vertical look sees a roof.
    if (b >= 0 && !UnderTree(site, local.x(), local.y(), 0.5) && FootprintMargin(site, local.x(), local.y()) > 0.3 &&
        std::abs(p.scan_angle_deg) < 1) {
      EXPECT_EQ(p.classification, kLasBuilding);
    }
  }
  EXPECT_GT(classes[kLasGround], 1000);
  EXPECT_GT(classes[kLasBuilding], 500);
  EXPECT_GT(classes[kLasHighVegetation], 20);
  EXPECT_GT(classes[kLasUnclassified], 2);
  EXPECT_GT(checked_roof, 300);
  EXPECT_GT(checked_ground, 1000);
  for (int k = 0; k < kEffectCount; ++k) EXPECT_EQ(Evaluations(static_cast<EffectKind>(k)), 0u) << EffectName(static_cast<EffectKind>(k));
  std::filesystem::remove(path);
}

TEST(AirborneLidar, DeterministicAndEffectsDoWhatTheySay) {
  const scene::SyntheticCampus site = StillSite();
  AirborneLidarSpec spec;
  spec.point_spacing_m = 2;
  EffectSet effects;
  effects.Enable(EffectKind::kLidarRangeNoise, {{{"sigma_m", 0.05}}});
  effects.Enable(EffectKind::kLidarMissingReturns, {{{"probability", 0.1}}});
  effects.Enable(EffectKind::kLidarIntensityByMaterial, {});
  const std::string a = TempLas("a"), b = TempLas("b"), clean = TempLas("clean");
  ASSERT_TRUE(SimulateAirborneLidar(site, spec, effects, 5, a).ok());
  ASSERT_TRUE(SimulateAirborneLidar(site, spec, effects, 5, b).ok());
  ASSERT_TRUE(SimulateAirborneLidar(site, spec, EffectSet{}, 5, clean).ok());
  const auto la = ReadLas6(a), lb = ReadLas6(b), lc = ReadLas6(clean);
  ASSERT_TRUE(la.ok() && lb.ok() && lc.ok());
  ASSERT_EQ(la->point_count, lb->point_count);
  for (size_t i = 0; i < la->points.size(); ++i) EXPECT_EQ(la->points[i].p_world, lb->points[i].p_world);
  EXPECT_NEAR(static_cast<double>(la->point_count) / lc->point_count, 0.9, 0.02);
  double ground = 0, building = 0;
  int ng = 0, nb = 0;
  for (const auto& p : la->points) {
    if (p.classification == kLasGround) {
      ground += p.intensity;
      ++ng;
    } else if (p.classification == kLasBuilding) {
      building += p.intensity;
      ++nb;
    }
  }
  ASSERT_GT(ng * nb, 0);
  EXPECT_GT(building / nb, ground / ng);
  for (const auto& path : {a, b, clean}) std::filesystem::remove(path);
}

TEST(AirborneLidar, BadSpecWritesNothing) {
  const scene::SyntheticCampus site = StillSite();
  const std::string path = TempLas("bad");
  for (auto mutate : std::vector<void (*)(AirborneLidarSpec&)>{
           [](AirborneLidarSpec& s) { s.altitude_m = -1; }, [](AirborneLidarSpec& s) { s.altitude_m = 20; },
           [](AirborneLidarSpec& s) { s.swath_half_angle_deg = 75; }, [](AirborneLidarSpec& s) { s.point_spacing_m = NAN; }}) {
    AirborneLidarSpec spec;
    mutate(spec);
    const absl::Status status = SimulateAirborneLidar(site, spec, EffectSet{}, 1, path);
    EXPECT_EQ(status.code(), absl::StatusCode::kInvalidArgument) << status;
    EXPECT_FALSE(std::filesystem::exists(path));
  }
  EXPECT_FALSE(ReadLas6(path).ok());
}

}  // namespace
}  // namespace ave::sim
