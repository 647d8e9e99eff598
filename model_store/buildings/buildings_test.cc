// Unit tests of the building fits and meshes that need no simulated survey; the survey-based
// tests (campus precision and recall, the semi-automatic fit, `ave-model fit`) score against the
// simulator's truth and live in tests/truth/buildings_truth_test.cc.
#include "model_store/buildings/buildings.h"

#include <cmath>
#include <map>
#include <tuple>

#include <gtest/gtest.h>

#include "model_store/buildings/roof_fit.h"
#include "model_store/terrain/terrain.h"

namespace ave::model {
namespace {

using Eigen::Vector2d;
using Eigen::Vector3d;

TEST(RoofFit, CollinearAndCoincidentPointsFailClearly) {
  std::vector<Vector3d> line, same;
  for (int i = 0; i < 20; ++i) line.emplace_back(i * 0.5, 2 * i * 0.5, 5 + 0.1 * i), same.emplace_back(1, 2, 3);
  internal::Rect2 rect;
  const auto plane = [](const internal::Rect2&, const Vector2d& uv, Eigen::Ref<Eigen::VectorXd> row) { row << 1, uv.x(), uv.y(); };
  const absl::StatusOr<internal::LinearFit> a = internal::FitLinearRoof(line, rect, 3, plane);
  ASSERT_FALSE(a.ok());
  EXPECT_NE(a.status().message().find("collinear"), std::string::npos) << a.status();
  EXPECT_FALSE(internal::FitLinearRoof(same, rect, 3, plane).ok());
  EXPECT_FALSE(internal::FitSpheroid(same).ok());
  EXPECT_FALSE(internal::FitSpheroid(line).ok());
  std::vector<Vector2d> cells;
  for (int i = 0; i < 10; ++i) cells.emplace_back(0.5 * i, 0.5 * i);
  EXPECT_FALSE(internal::ShapeOfCells(cells, 0.5).ok());
  for (const PrimitiveType type : {PrimitiveType::kBox, PrimitiveType::kWedge, PrimitiveType::kSphere, PrimitiveType::kCylinder}) {
    const absl::StatusOr<BuildingPrimitive> p = internal::FitPart(line, cells, 0.5, 0, {type, std::nullopt});
    EXPECT_FALSE(p.ok()) << PrimitiveTypeName(type);
  }
  // A footprint polygon with collinear vertices is refused before any fit.
  PointCloud cloud;
  for (int y = 0; y < 20; ++y)
    for (int x = 0; x < 20; ++x) cloud.xyz.emplace_back(0.5f * x, 0.5f * y, 0.0f);
  const absl::StatusOr<HeightGrid> grid = BuildHeightGrid(cloud, 0.5);
  ASSERT_TRUE(grid.ok()) << grid.status();
  const absl::StatusOr<BuildingRecord> r =
      FitBuilding(cloud, *grid, {Vector2d(0, 0), Vector2d(1, 1), Vector2d(2, 2)}, PrimitiveType::kBox, RoofType::kFlat);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("collinear"), std::string::npos) << r.status();
}

TEST(RoofFit, SpheroidRecoversADome) {
  std::vector<Vector3d> pts;
  for (double x = -7.75; x < 8; x += 0.5)
    for (double y = -7.75; y < 8; y += 0.5) {
      const double rho2 = (x * x + y * y) / 64;
      if (rho2 < 1) pts.emplace_back(100 + x, -50 + y, 20 + 5 * std::sqrt(1 - rho2));
    }
  const absl::StatusOr<internal::SpheroidFit> f = internal::FitSpheroid(pts);
  ASSERT_TRUE(f.ok()) << f.status();
  EXPECT_NEAR(f->radius_m, 8, 0.05);
  EXPECT_NEAR(f->rise_m, 5, 0.05);
  EXPECT_NEAR(f->z0_m, 20, 0.05);
  EXPECT_LT((f->center - Vector2d(100, -50)).norm(), 0.01);
}

// Every edge of a closed mesh is used by an even number of triangles (vertices are per face, so
// edges are matched by position).
TEST(BuildingMesh, EveryPrimitiveIsClosed) {
  BuildingRecord rec;
  int k = 0;
  for (const RoofType roof : {RoofType::kFlat, RoofType::kShed, RoofType::kGable, RoofType::kHip, RoofType::kDome, RoofType::kCylinder}) {
    BuildingPrimitive p;
    p.roof = roof;
    p.type = roof == RoofType::kHip ? PrimitiveType::kPolyhedron : PrimitiveType::kBox;
    p.center_m = Vector2d(30.0 * k++, 0);
    p.size_m = Vector2d(12, 8);
    p.yaw_rad = 0.4;
    p.eave_height_m = 6;
    p.roof_height_m = 3;
    rec.parts.push_back(p);
  }
  TriangleMesh mesh;
  AppendBuildingMesh(rec, 7, mesh);
  ASSERT_GT(mesh.TriangleCount(), 100u);
  EXPECT_EQ(mesh.triangle_object.size(), mesh.TriangleCount());
  std::map<std::pair<std::tuple<long, long, long>, std::tuple<long, long, long>>, int> edges;
  auto key = [&](uint32_t i) {
    const Eigen::Vector3f& p = mesh.positions[i];
    return std::make_tuple(std::lround(p.x() * 1000), std::lround(p.y() * 1000), std::lround(p.z() * 1000));
  };
  for (size_t t = 0; t < mesh.TriangleCount(); ++t)
    for (int e = 0; e < 3; ++e) {
      auto a = key(mesh.indices[3 * t + e]), b = key(mesh.indices[3 * t + (e + 1) % 3]);
      if (b < a) std::swap(a, b);
      ++edges[{a, b}];
    }
  int open = 0;
  for (const auto& [edge, uses] : edges) open += uses % 2;
  EXPECT_EQ(open, 0);
  for (const auto& n : mesh.normals) EXPECT_NEAR(n.norm(), 1.0f, 1e-4f);
}

}  // namespace
}  // namespace ave::model
