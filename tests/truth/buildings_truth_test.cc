// The building extraction and fits scored against the simulator's truth: simulated airborne
// surveys (tests/truth/survey_truth.h) of the campus and of small synthetic sites.
#include "model_store/buildings/buildings.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <sstream>
#include <map>
#include <tuple>

#include <gtest/gtest.h>

#include "model_store/buildings/fit_command.h"
#include "model_store/terrain/terrain.h"
#include "tests/truth/survey_truth.h"

namespace ave::model {
namespace {

using Eigen::Vector2d;
using Eigen::Vector3d;

// The campus survey is the slow part (~seconds): simulate it once for every test that uses it.
const testing::Survey& CampusSurvey() {
  static const testing::Survey survey = [] {
    absl::StatusOr<testing::Survey> s = testing::SurveySite(scene::BuiltinCampus(), 0.5, 0.5, 11);
    EXPECT_TRUE(s.ok()) << s.status();
    return s.ok() ? *std::move(s) : testing::Survey{};
  }();
  return survey;
}

// A site with flat ground (no hills) and the given buildings and trees.
scene::SyntheticCampus FlatSite(Vector3d origin) {
  scene::SyntheticCampus site;
  site.name = "flat";
  site.origin = origin;
  site.half_extent_m = 40;
  site.terrain.amplitude_m = 0;
  site.terrain.tilt_x = site.terrain.tilt_y = 0;
  return site;
}

scene::BoxBuilding Box(std::string id, Vector2d center, Vector2d size, double height) {
  scene::BoxBuilding b;
  b.id = std::move(id);
  b.center_m = center;
  b.size_m = size;
  b.height_m = height;
  return b;
}
TEST(Buildings, CampusPrecisionRecallAndRoofTypesMeetTheIssueTargets) {
  const testing::Survey& s = CampusSurvey();
  ASSERT_GT(s.cloud.size(), 100000u);
  std::vector<uint8_t> classes;
  const std::vector<BuildingRecord> found = ExtractBuildings(s.cloud, s.grid, BuildingOptions{}, &classes);
  const scene::SyntheticCampus campus = scene::BuiltinCampus();
  const testing::BuildingScore score = testing::ScoreBuildings(campus, s.cloud.origin, found);
  for (const auto& m : score.mistakes) std::printf("  %s\n", m.c_str());
  std::printf("campus 0.5 m: %d detected / %d true, precision %.3f recall %.3f roof accuracy %.3f, split %d\n", score.detected,
              score.truth, score.precision, score.recall, score.roof_accuracy, score.split);
  std::printf("main-part error mean/max: centre %.2f/%.2f m, size %.2f/%.2f m, eaves %.2f/%.2f m, rise %.2f/%.2f m, yaw %.2f/%.2f deg\n",
              score.center_err_m_mean, score.center_err_m_max, score.size_err_m_mean, score.size_err_m_max, score.eave_err_m_mean,
              score.eave_err_m_max, score.roof_height_err_m_mean, score.roof_height_err_m_max, score.yaw_err_deg_mean,
              score.yaw_err_deg_max);
  std::printf("mean centre offset (%.2f, %.2f) m\n", score.center_bias_m.x(), score.center_bias_m.y());
  EXPECT_GE(score.precision, 0.95);
  EXPECT_GE(score.recall, 0.95);
  EXPECT_GE(score.roof_accuracy, 0.9);
  EXPECT_LT(score.eave_err_m_mean, 0.2);
  EXPECT_LT(score.center_err_m_mean, 0.3);
  EXPECT_LT(score.size_err_m_mean, 0.5);
  EXPECT_LT(score.yaw_err_deg_mean, 1.0);
  // Building points labelled 6 agree with the simulator's truth class.
  size_t agree = 0, labelled = 0;
  for (size_t i = 0; i < classes.size(); ++i) {
    if (classes[i] != 6) continue;
    ++labelled;
    agree += s.cloud.classification[i] == 6;
  }
  ASSERT_GT(labelled, 1000u);
  EXPECT_GT(static_cast<double>(agree) / labelled, 0.97);
}

// Finer cells than the 0.5 m point spacing leave most cells empty; coarser ones blur edges.
TEST(Buildings, CampusAtOtherResolutions) {
  const testing::Survey& s = CampusSurvey();
  const scene::SyntheticCampus campus = scene::BuiltinCampus();
  for (const double res : {0.25, 1.0, 2.0}) {
    const HeightGrid grid = testing::GridWithTruthGround(s.cloud, campus, res);
    const testing::BuildingScore score =
        testing::ScoreBuildings(campus, s.cloud.origin, ExtractBuildings(s.cloud, grid, BuildingOptions{}, nullptr));
    for (const auto& m : score.mistakes) std::printf("  %s\n", m.c_str());
    std::printf("campus %.2f m: precision %.3f recall %.3f roof accuracy %.3f; size error %.2f m mean\n", res, score.precision,
                score.recall, score.roof_accuracy, score.size_err_m_mean);
    if (res <= 1.0) {
      EXPECT_GE(score.precision, 0.9) << res;
      EXPECT_GE(score.recall, 0.9) << res;
    }
  }
}

// The path `ave-model build` takes: gridding and the ground filter of model_store/terrain, then
// the buildings, on the same survey.
TEST(Buildings, CampusThroughTheTerrainPipeline) {
  const testing::Survey& s = CampusSurvey();
  absl::StatusOr<TerrainResult> terrain = BuildTerrain(s.cloud, 0.5, GroundFilterOptions{});
  ASSERT_TRUE(terrain.ok()) << terrain.status();
  std::vector<uint8_t> classes = terrain->point_class;
  const std::vector<BuildingRecord> found = ExtractBuildings(s.cloud, terrain->grid, BuildingOptions{}, &classes);
  const testing::BuildingScore score = testing::ScoreBuildings(scene::BuiltinCampus(), s.cloud.origin, found);
  for (const auto& m : score.mistakes) std::printf("  %s\n", m.c_str());
  std::printf("campus 0.5 m, terrain filter DTM: precision %.3f recall %.3f roof accuracy %.3f; error mean/max: centre %.2f/%.2f m, "
              "size %.2f/%.2f m, eaves %.2f/%.2f m, rise %.2f/%.2f m, yaw %.2f/%.2f deg\n",
              score.precision, score.recall, score.roof_accuracy, score.center_err_m_mean, score.center_err_m_max, score.size_err_m_mean,
              score.size_err_m_max, score.eave_err_m_mean, score.eave_err_m_max, score.roof_height_err_m_mean, score.roof_height_err_m_max,
              score.yaw_err_deg_mean, score.yaw_err_deg_max);
  EXPECT_GE(score.precision, 0.95);
  EXPECT_GE(score.recall, 0.95);
  EXPECT_GE(score.roof_accuracy, 0.9);
  EXPECT_LT(score.size_err_m_mean, 0.5);
  EXPECT_LT(score.eave_err_m_mean, 0.3);
}

TEST(Buildings, MultiPrimitiveBuildingsGetSeveralParts) {
  const testing::Survey& s = CampusSurvey();
  const std::vector<BuildingRecord> found = ExtractBuildings(s.cloud, s.grid, BuildingOptions{}, nullptr);
  const scene::SyntheticCampus campus = scene::BuiltinCampus();
  std::map<std::string, const BuildingRecord*> by_id;
  for (const auto& r : found) {
    const int b = campus.BuildingAt(r.parts.front().center_m.x(), r.parts.front().center_m.y());
    if (b >= 0 && (!by_id[campus.buildings[b].id] || by_id[campus.buildings[b].id]->area_m2 < r.area_m2))
      by_id[campus.buildings[b].id] = &r;
  }
  ASSERT_TRUE(by_id["admin"]);
  const BuildingRecord& admin = *by_id["admin"];
  ASSERT_GE(admin.parts.size(), 2u);
  EXPECT_EQ(admin.parts[0].roof, RoofType::kFlat);
  bool dome = false;
  for (const auto& p : admin.parts) dome |= p.roof == RoofType::kDome;
  EXPECT_TRUE(dome);
  ASSERT_TRUE(by_id["museum"]);
  EXPECT_GE(by_id["museum"]->parts.size(), 2u);
  // The footprint outline is a closed counter-clockwise polygon around the main part's centre.
  ASSERT_GE(admin.footprint_m.size(), 4u);
}

TEST(Buildings, FlatRoofExactlyOnCellBoundaries) {
  scene::SyntheticCampus site = FlatSite(Vector3d(500000, 4000000, 50));
  site.buildings.push_back(Box("block", {5.0, -5.0}, {20.0, 10.0}, 8.0));  // edges at x = -5, 15; y = -10, 0
  absl::StatusOr<testing::Survey> s = testing::SurveySite(site, 0.5, 0.5, 3);
  ASSERT_TRUE(s.ok()) << s.status();
  // The grid corner is on a multiple of the resolution, so every wall lies on a cell boundary.
  EXPECT_NEAR(std::remainder(s->grid.min_xy.x() + 5.0, 0.5), 0.0, 1e-9);
  const std::vector<BuildingRecord> found = ExtractBuildings(s->cloud, s->grid, BuildingOptions{}, nullptr);
  ASSERT_EQ(found.size(), 1u);
  const BuildingPrimitive& p = found[0].parts.front();
  EXPECT_EQ(p.roof, RoofType::kFlat);
  EXPECT_EQ(p.type, PrimitiveType::kBox);
  Vector2d size = p.size_m;
  if (size.x() < size.y()) std::swap(size.x(), size.y());
  EXPECT_NEAR(size.x(), 20.0, 0.6);
  EXPECT_NEAR(size.y(), 10.0, 0.6);
  EXPECT_NEAR(p.base_z_m + p.eave_height_m, 8.0, 0.1);
  EXPECT_LT((p.center_m - Vector2d(5, -5)).norm(), 0.4);
}

TEST(Buildings, SinglePointBuildingIsDroppedWithoutCrash) {
  PointCloud cloud;
  cloud.origin = Vector3d(1e6, 1e7, 0);
  for (int y = 0; y < 40; ++y)
    for (int x = 0; x < 40; ++x) cloud.xyz.emplace_back(0.5f * x, 0.5f * y, 0.0f);
  cloud.xyz.emplace_back(10.1f, 10.1f, 12.0f);  // one point "building"
  const HeightGrid grid = testing::GridWithTruthGround(cloud, FlatSite(cloud.origin), 0.5);
  std::vector<uint8_t> classes;
  EXPECT_TRUE(ExtractBuildings(cloud, grid, BuildingOptions{}, &classes).empty());
  EXPECT_EQ(classes.size(), cloud.size());
  // The semi-automatic fit on that one cell fails with a reason instead of a NaN primitive.
  const absl::StatusOr<BuildingRecord> fit = FitBuilding(cloud, grid, {Vector2d(10.1, 10.1)}, PrimitiveType::kBox, RoofType::kFlat);
  ASSERT_FALSE(fit.ok());
  EXPECT_FALSE(fit.status().message().empty());
}

TEST(Buildings, CloudWithNoBuildingsGivesNoneAndTreesAreVegetation) {
  scene::SyntheticCampus site = FlatSite(Vector3d(0, 0, 0));
  for (int i = 0; i < 6; ++i) {
    scene::Tree t;
    t.position_m = Vector2d(-20 + 8.0 * i, 5.0 * (i % 2));
    t.crown_radius_m = 2.0 + 0.3 * i;
    site.trees.push_back(t);
  }
  absl::StatusOr<testing::Survey> s = testing::SurveySite(site, 0.5, 0.5, 5);
  ASSERT_TRUE(s.ok()) << s.status();
  std::vector<uint8_t> classes;
  EXPECT_TRUE(ExtractBuildings(s->cloud, s->grid, BuildingOptions{}, &classes).empty());
  size_t veg = 0;
  for (uint8_t c : classes) veg += c == 5;
  EXPECT_GT(veg, 100u);
  // Bare ground only.
  site.trees.clear();
  s = testing::SurveySite(site, 1.0, 0.5, 6);
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_TRUE(ExtractBuildings(s->cloud, s->grid, BuildingOptions{}, nullptr).empty());
}

TEST(Buildings, HugeCoordinatesGiveTheSameBuildings) {
  std::vector<std::tuple<double, double, double>> results;
  for (const Vector3d& origin : {Vector3d(0, 0, 0), Vector3d(1e6, 1e6, 100), Vector3d(1e7, 1e7, 100)}) {
    scene::SyntheticCampus site = FlatSite(origin);
    scene::BoxBuilding gable = Box("gable", {3.3, 4.1}, {16, 10}, 6);
    gable.kind = scene::PrimitiveKind::kGable;
    gable.roof_height_m = 3;
    gable.yaw_rad = 0.3;
    site.buildings.push_back(gable);
    absl::StatusOr<testing::Survey> s = testing::SurveySite(site, 0.5, 0.5, 9);
    ASSERT_TRUE(s.ok()) << s.status();
    const std::vector<BuildingRecord> found = ExtractBuildings(s->cloud, s->grid, BuildingOptions{}, nullptr);
    ASSERT_EQ(found.size(), 1u) << "origin " << origin.transpose();
    const BuildingPrimitive& p = found[0].parts.front();
    EXPECT_EQ(p.roof, RoofType::kGable);
    EXPECT_TRUE(std::isfinite(p.eave_height_m) && std::isfinite(p.roof_height_m));
    EXPECT_NEAR(p.roof_height_m, 3.0, 0.3);
    EXPECT_LT((p.center_m + (origin - site.origin).head<2>() - Vector2d(3.3, 4.1)).norm(), 0.5);
    results.emplace_back(p.center_m.x(), p.eave_height_m, p.roof_height_m);
  }
  // Millimetre-level agreement is not expected (the simulated returns differ), centimetres are.
  for (const auto& r : results) EXPECT_NEAR(std::get<1>(r), std::get<1>(results[0]), 0.05);
}

TEST(Buildings, SemiAutomaticFitFromFootprintAndClick) {
  const testing::Survey& s = CampusSurvey();
  // The gym: a 30 x 20 m box at (30, 30), eaves 9 m; the footprint drawn roughly, 1 m loose.
  const absl::StatusOr<BuildingRecord> gym = FitBuilding(
      s.cloud, s.grid, {Vector2d(14, 19), Vector2d(46, 19), Vector2d(46, 41), Vector2d(14, 41)}, PrimitiveType::kBox, RoofType::kFlat);
  ASSERT_TRUE(gym.ok()) << gym.status();
  const BuildingPrimitive& g = gym->parts.front();
  EXPECT_EQ(g.type, PrimitiveType::kBox);
  EXPECT_NEAR(g.eave_height_m, 9.0, 0.3);
  EXPECT_LT((g.center_m - Vector2d(30, 30)).norm(), 0.5);
  EXPECT_NEAR(std::max(g.size_m.x(), g.size_m.y()), 30.0, 0.6);
  EXPECT_NEAR(std::min(g.size_m.x(), g.size_m.y()), 20.0, 0.6);
  // A click on the library (hip roof) fitted as a polyhedron with a hip roof.
  const absl::StatusOr<BuildingRecord> lib = FitBuilding(s.cloud, s.grid, {Vector2d(28, -30)}, PrimitiveType::kPolyhedron, RoofType::kHip);
  ASSERT_TRUE(lib.ok()) << lib.status();
  EXPECT_EQ(lib->parts.front().roof, RoofType::kHip);
  EXPECT_NEAR(lib->parts.front().roof_height_m, 4.0, 0.4);
  // A click on the planetarium as a sphere.
  const absl::StatusOr<BuildingRecord> dome = FitBuilding(s.cloud, s.grid, {Vector2d(35, -70)}, PrimitiveType::kSphere, RoofType::kDome);
  ASSERT_TRUE(dome.ok()) << dome.status();
  EXPECT_NEAR(dome->parts.front().size_m.x(), 16.0, 1.0);
  // A click on bare ground says so.
  const absl::StatusOr<BuildingRecord> none = FitBuilding(s.cloud, s.grid, {Vector2d(0, -50)}, PrimitiveType::kBox, RoofType::kFlat);
  ASSERT_FALSE(none.ok());
  EXPECT_NE(none.status().message().find("not on a building"), std::string::npos) << none.status();
}

TEST(FitCommand, FitsAClickedBoxFromALasFileAndNamesBadInput) {
  scene::SyntheticCampus site = FlatSite(Vector3d(384500, 3768200, 85));
  site.buildings.push_back(Box("block", {2.0, 3.0}, {12.0, 8.0}, 7.0));
  const std::string las = (std::filesystem::temp_directory_path() / ("ave_fit_" + std::to_string(::getpid()) + ".las")).string();
  ASSERT_TRUE(testing::WriteSurveyLas(site, 0.5, 4, las).ok());
  FitCommandOptions o;
  o.input = las;
  o.click = "384502,3768203";  // world metres
  o.type = "box";
  std::ostringstream out, err;
  ASSERT_EQ(RunFit(o, out, err), 0) << err.str();
  EXPECT_NE(out.str().find("\"type\":\"box\""), std::string::npos) << out.str();
  EXPECT_NE(out.str().find("\"eave_height_m\":7."), std::string::npos) << out.str();
  // --db stores it as a scene with one building.
  const std::string db = las + ".db";
  o.db = db;
  std::ostringstream outd, errd;
  ASSERT_EQ(RunFit(o, outd, errd), 0) << errd.str();
  {
    absl::StatusOr<std::unique_ptr<store::Store>> st = store::Store::Open(db);
    ASSERT_TRUE(st.ok()) << st.status();
    absl::StatusOr<std::vector<store::SceneRecord>> scenes = (*st)->ListScenes();
    ASSERT_TRUE(scenes.ok() && scenes->size() == 1u);
    absl::StatusOr<std::vector<store::StoredBuilding>> stored = (*st)->GetBuildings(scenes->front().id);
    ASSERT_TRUE(stored.ok()) << stored.status();
    ASSERT_EQ(stored->size(), 1u);
    EXPECT_EQ(stored->front().parts.front().type, "box");
    EXPECT_NEAR(stored->front().parts.front().eave_height_m, 7.0, 0.2);
  }
  for (const char* suffix : {"", "-wal", "-shm"}) std::filesystem::remove(db + suffix);
  o.db.clear();
  o.type = "pyramid";
  std::ostringstream out2, err2;
  EXPECT_EQ(RunFit(o, out2, err2), 1);
  EXPECT_NE(err2.str().find("--type 'pyramid'"), std::string::npos) << err2.str();
  o.type = "box";
  o.click.clear();
  o.footprint = "384496,3768199;oops";
  std::ostringstream out3, err3;
  EXPECT_EQ(RunFit(o, out3, err3), 1);
  EXPECT_NE(err3.str().find("vertex 1 'oops'"), std::string::npos) << err3.str();
  o.footprint = "384496,3768199;384508,3768199;384508,3768207;384496,3768207";
  o.input = las + ".missing.las";
  std::ostringstream out4, err4;
  EXPECT_EQ(RunFit(o, out4, err4), 1);
  EXPECT_NE(err4.str().find(".missing.las"), std::string::npos) << err4.str();
  std::filesystem::remove(las);
}

}  // namespace
}  // namespace ave::model
