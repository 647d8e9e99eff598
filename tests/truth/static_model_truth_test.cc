// The issue-4 "done when" on the campus scenario, as a test: the simulated airborne survey
// written as LAS, read back by the real reader, through the whole pipeline at 0.5 m.
#include "model_store/pipeline/static_model.h"

#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>

#include <gtest/gtest.h>

#include "model_store/db/store.h"
#include "model_store/lidar/las.h"
#include "sensor_agent/sim/scenario.h"
#include "tests/truth/survey_truth.h"
#include "tests/truth/terrain_score.h"

namespace ave::model {
namespace {

TEST(StaticModel, CampusSurveyMeetsTheIssueTargetsAndStores) {
  absl::StatusOr<sim::Scenario> scenario = sim::LoadScenario("campus");
  ASSERT_TRUE(scenario.ok()) << scenario.status();
  const scene::SyntheticCampus& site = scenario->world;
  const std::string las = ::testing::TempDir() + "/ave_static_model_" + std::to_string(::getpid()) + ".las";
  ASSERT_TRUE(sim::SimulateAirborneLidar(site, scenario->airborne_lidar.value_or(sim::AirborneLidarSpec{}), scenario->effects, 1, las).ok());
  absl::StatusOr<PointCloud> cloud = ReadLas(las);
  std::filesystem::remove(las);
  ASSERT_TRUE(cloud.ok()) << cloud.status();
  EXPECT_EQ(cloud->origin, site.origin.array().round().matrix());

  absl::StatusOr<StaticModel> model = BuildStaticModel(*cloud, StaticModelOptions{});
  ASSERT_TRUE(model.ok()) << model.status();
  ASSERT_EQ(model->point_class.size(), cloud->size());
  const testing::TerrainScore terrain = testing::ScoreTerrain(model->terrain.grid, site, cloud->origin, model->point_class, cloud->classification);
  ASSERT_GT(terrain.cells, 10000u);
  EXPECT_GE(terrain.ground_accuracy, 0.97);
  EXPECT_LE(terrain.rmse_all_m, 0.15);

  const testing::BuildingScore score = testing::ScoreBuildings(site, cloud->origin, model->buildings);
  EXPECT_GE(score.precision, 0.95);
  EXPECT_GE(score.recall, 0.95);
  EXPECT_GE(score.roof_accuracy, 0.9);
  // Cells finer than the 0.5 m point spacing: buildings are segmented on a doubled grid.
  StaticModelOptions fine;
  fine.resolution_m = 0.25;
  absl::StatusOr<StaticModel> fine_model = BuildStaticModel(*cloud, fine);
  ASSERT_TRUE(fine_model.ok()) << fine_model.status();
  EXPECT_EQ(fine_model->building_grid_m, 0.5);
  EXPECT_GE(testing::ScoreBuildings(site, cloud->origin, fine_model->buildings).recall, 0.95);
  // The assembled mesh (terrain + buildings) is what ave-server serves: the store must take it.
  EXPECT_GT(model->mesh.TriangleCount(), model->terrain_triangles);
  EXPECT_EQ(model->mesh.origin, cloud->origin);
  absl::StatusOr<std::unique_ptr<store::Store>> db = store::Store::Open(":memory:");
  ASSERT_TRUE(db.ok());
  absl::StatusOr<int64_t> version = (*db)->PutStaticModel("lidar:campus", model->mesh);
  ASSERT_TRUE(version.ok()) << version.status();
  absl::StatusOr<std::optional<store::StaticModelRecord>> back = (*db)->LatestStaticModel();
  ASSERT_TRUE(back.ok() && back->has_value());
  EXPECT_EQ((*back)->mesh.TriangleCount(), model->mesh.TriangleCount());
}

}  // namespace
}  // namespace ave::model
