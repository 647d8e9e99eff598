#include "model_store/terrain/terrain.h"

#include <cmath>
#include <random>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace ave::model {
namespace {

using ::testing::HasSubstr;

// Sloped ground (10 % along x, 5 % along y) sampled every `spacing` m over [-half, half]^2, a
// 20 x 16 m flat-roofed building 8 m high, a 1-point "building" 6 m up, a bench 0.6 m high.
// truth: 2 ground, 6 building, 1 other.
struct Scene {
  PointCloud cloud;
  std::vector<uint8_t> truth;
};
double Ground(double x, double y) { return 0.1 * x + 0.05 * y + 0.5 * std::sin(x / 15); }

Scene MakeScene(const Eigen::Vector3d& origin, double half = 40, double spacing = 0.5) {
  Scene s;
  s.cloud.origin = origin;
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> jitter(-0.2f, 0.2f);
  for (double y = -half; y <= half; y += spacing) {
    for (double x = -half; x <= half; x += spacing) {
      const double px = x + jitter(rng) * spacing, py = y + jitter(rng) * spacing;
      double z = Ground(px, py);
      uint8_t cls = 2;
      if (px > 5 && px < 25 && py > -10 && py < 6) {
        z = Ground(25, 6) + 8;  // flat roof above the highest ground under it
        cls = 6;
      } else if (px > -20 && px < -18 && py > 10 && py < 10.6) {
        z += 0.6;
        cls = 1;
      }
      s.cloud.xyz.emplace_back(static_cast<float>(px), static_cast<float>(py), static_cast<float>(z));
      s.truth.push_back(cls);
    }
  }
  s.cloud.xyz.emplace_back(-30.f, -30.f, static_cast<float>(Ground(-30, -30) + 6));  // single-point building
  s.truth.push_back(6);
  return s;
}

class TerrainOnSlope : public ::testing::TestWithParam<double> {};

TEST_P(TerrainOnSlope, ClassifiesGroundAndKeepsBuildingsOutOfTheDtm) {
  const Scene s = MakeScene(Eigen::Vector3d(GetParam(), GetParam() * 0.7, 300));
  absl::StatusOr<TerrainResult> r = BuildTerrain(s.cloud, 0.5, GroundFilterOptions{});
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_EQ(r->grid.origin, s.cloud.origin);
  size_t right = 0;
  for (size_t i = 0; i < s.truth.size(); ++i) right += (r->point_class[i] == 2) == (s.truth[i] == 2);
  EXPECT_GT(static_cast<double>(right) / s.truth.size(), 0.995);
  EXPECT_EQ(r->point_class.back(), 1) << "the single-point building is not ground";
  // DTM against the analytic ground, including under the building (hole filled from ground only).
  double se = 0, worst_under_building = 0;
  int n = 0;
  for (int row = 2; row < r->grid.rows - 2; ++row) {
    for (int col = 2; col < r->grid.cols - 2; ++col) {
      const Eigen::Vector2d c = r->grid.CellCenter(col, row);
      const double e = r->grid.dtm[r->grid.Index(col, row)] - Ground(c.x(), c.y());
      ASSERT_TRUE(std::isfinite(e));
      se += e * e;
      ++n;
      if (c.x() > 6 && c.x() < 24 && c.y() > -9 && c.y() < 5) worst_under_building = std::max(worst_under_building, std::abs(e));
    }
  }
  EXPECT_LT(std::sqrt(se / n), 0.08);
  EXPECT_LT(worst_under_building, 0.5) << "the roof leaked into the terrain";
}

// Hard case: coordinates near 1e6 m and 1e7 m give the same answer as near zero.
INSTANTIATE_TEST_SUITE_P(Origins, TerrainOnSlope, ::testing::Values(0.0, 1e6, 1e7));

TEST(HeightGrid, FlatRoofExactlyOnCellBoundaries) {
  PointCloud cloud;
  // Points exactly on cell edges of a 0.5 m grid: each lands in the cell it starts.
  for (int j = 0; j <= 8; ++j) {
    for (int i = 0; i <= 8; ++i) cloud.xyz.emplace_back(i * 0.5f, j * 0.5f, 12.f);
  }
  absl::StatusOr<HeightGrid> g = BuildHeightGrid(cloud, 0.5);
  ASSERT_TRUE(g.ok());
  EXPECT_EQ(g->cols, 9);
  EXPECT_EQ(g->rows, 9);
  EXPECT_EQ(g->min_xy, Eigen::Vector2d(0, 0));
  for (size_t i = 0; i < g->CellCount(); ++i) {
    EXPECT_EQ(g->count[i], 1u);
    EXPECT_EQ(g->zmax[i], 12.f);
    EXPECT_EQ(g->znearest[i], 12.f);
  }
}

TEST(HeightGrid, StatisticsPerCell) {
  PointCloud cloud;
  cloud.xyz = {{0.1f, 0.1f, 1.f}, {0.4f, 0.4f, 3.f}, {0.26f, 0.24f, 2.5f}, {1.2f, 0.1f, 7.f}};
  absl::StatusOr<HeightGrid> g = BuildHeightGrid(cloud, 0.5);
  ASSERT_TRUE(g.ok());
  EXPECT_EQ(g->count[0], 3u);
  EXPECT_EQ(g->zmin[0], 1.f);
  EXPECT_EQ(g->zmax[0], 3.f);
  EXPECT_FLOAT_EQ(g->zmean[0], 6.5f / 3);
  EXPECT_EQ(g->znearest[0], 2.5f);
  EXPECT_TRUE(std::isnan(g->zmin[1]));  // empty middle cell
  EXPECT_THAT(std::string(BuildHeightGrid(PointCloud{}, 0.5).status().message()), HasSubstr("empty"));
  EXPECT_FALSE(BuildHeightGrid(cloud, 0).ok());
  EXPECT_FALSE(BuildHeightGrid(cloud, std::nan("")).ok());
}

TEST(GroundFilter, NoGroundAtAllIsAClearError) {
  HeightGrid grid;
  grid.cols = grid.rows = 4;
  grid.zmin.assign(16, NAN);
  grid.count.assign(16, 0);
  absl::StatusOr<size_t> r = ClassifyGroundCells(grid, GroundFilterOptions{});
  EXPECT_EQ(r.status().code(), absl::StatusCode::kFailedPrecondition);
  GroundFilterOptions bad;
  bad.slope = -1;
  EXPECT_THAT(std::string(ClassifyGroundCells(grid, bad).status().message()), HasSubstr("slope"));
}

TEST(GroundFilter, RoofOnlyCloudGivesAFiniteSurface) {
  // Every return hit one flat roof: the lowest surface there is becomes the bare earth, finite.
  PointCloud cloud;
  for (int j = 0; j < 20; ++j) {
    for (int i = 0; i < 20; ++i) cloud.xyz.emplace_back(i * 0.5f, j * 0.5f, 15.f);
  }
  absl::StatusOr<TerrainResult> r = BuildTerrain(cloud, 0.5, GroundFilterOptions{});
  ASSERT_TRUE(r.ok()) << r.status();
  for (float z : r->grid.dtm) EXPECT_FLOAT_EQ(z, 15.f);
}

TEST(FillHoles, LinearRampIsRestoredInsideAHole) {
  const int cols = 40, rows = 30;
  std::vector<float> v(cols * rows);
  for (int y = 0; y < rows; ++y) {
    for (int x = 0; x < cols; ++x) v[y * cols + x] = (x >= 10 && x < 30 && y >= 8 && y < 22) ? NAN : 0.2f * x - 0.1f * y;
  }
  FillHoles(v, cols, rows, 400);
  for (int y = 0; y < rows; ++y) {
    for (int x = 0; x < cols; ++x) EXPECT_NEAR(v[y * cols + x], 0.2f * x - 0.1f * y, 0.02f) << x << "," << y;
  }
}

}  // namespace
}  // namespace ave::model
