#include "model_store/terrain/mesh_export.h"

#include <cmath>
#include <cstdio>
#include <map>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "model_store/lidar/read_file.h"

namespace ave::model {
namespace {

HeightGrid MakeDtm(int cols, int rows, const Eigen::Vector3d& origin) {
  HeightGrid g;
  g.origin = origin;
  g.cols = cols;
  g.rows = rows;
  g.resolution_m = 0.5;
  g.min_xy = {-10, -5};
  g.dtm.resize(g.CellCount());
  g.zmax.resize(g.CellCount());
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) {
      // Flat in the west half, a bump in the east: the flat part merges, the bump does not.
      const double x = c - cols * 0.75, y = r - rows * 0.5;
      g.dtm[g.Index(c, r)] = c < cols / 2 ? 2.f : static_cast<float>(2 + 3 * std::exp(-(x * x + y * y) / 30));
      g.zmax[g.Index(c, r)] = g.dtm[g.Index(c, r)] + (c % 3 == 0 ? 5.f : 0.f);
    }
  }
  return g;
}

TEST(Tessellate, FlatAreasMergeWithoutCracks) {
  const HeightGrid g = MakeDtm(65, 49, {1e6, 2e6, 0});
  const TriangleMesh mesh = TessellateDtm(g);
  const size_t full = 2u * 64 * 48;
  EXPECT_LT(mesh.TriangleCount(), full / 2);
  EXPECT_GT(mesh.TriangleCount(), 0u);
  EXPECT_EQ(mesh.origin, g.origin);
  EXPECT_EQ(mesh.triangle_material.size(), mesh.TriangleCount());
  // Every vertex lies exactly on the DTM sample it came from.
  for (const auto& p : mesh.positions) {
    int c, r;
    ASSERT_TRUE(g.CellOf(p.x(), p.y(), &c, &r));
    EXPECT_EQ(p.z(), g.dtm[g.Index(c, r)]);
  }
  // Crack-free: an edge used by one triangle only lies on the grid border; none is used 3 times.
  std::map<std::pair<uint32_t, uint32_t>, int> uses;
  double area = 0;
  for (size_t t = 0; t < mesh.TriangleCount(); ++t) {
    const uint32_t* i = &mesh.indices[3 * t];
    const Eigen::Vector3f a = mesh.positions[i[0]], b = mesh.positions[i[1]], c = mesh.positions[i[2]];
    const float cross_z = (b - a).x() * (c - a).y() - (b - a).y() * (c - a).x();
    EXPECT_GT(cross_z, 0) << "triangle " << t << " is not counter-clockwise from above";
    area += 0.5 * cross_z;
    for (int k = 0; k < 3; ++k) ++uses[std::minmax(i[k], i[(k + 1) % 3])];
  }
  EXPECT_NEAR(area, 64 * 0.5 * 48 * 0.5, 1e-3);
  const Eigen::Vector2d lo = g.CellCenter(0, 0), hi = g.CellCenter(g.cols - 1, g.rows - 1);
  auto on_border = [&](const Eigen::Vector3f& p) {
    return std::abs(p.x() - lo.x()) < 1e-4 || std::abs(p.x() - hi.x()) < 1e-4 || std::abs(p.y() - lo.y()) < 1e-4 ||
           std::abs(p.y() - hi.y()) < 1e-4;
  };
  for (const auto& [edge, n] : uses) {
    EXPECT_LE(n, 2);
    if (n == 1) {
      EXPECT_TRUE(on_border(mesh.positions[edge.first]) && on_border(mesh.positions[edge.second])) << "crack at an inner edge";
    }
  }
}

TEST(Export, MeshFilesCarryTheOrigin) {
  const TriangleMesh mesh = TessellateDtm(MakeDtm(17, 9, {384500, 3768200, 85}));
  const std::string dir = ::testing::TempDir();
  for (const char* ext : {"ply", "obj", "gltf", "glb"}) {
    const std::string path = dir + "/ave_mesh." + ext;
    ASSERT_TRUE(WriteMesh(mesh, path).ok()) << ext;
    absl::StatusOr<std::string> bytes = ReadWholeFile(path);
    ASSERT_TRUE(bytes.ok());
    EXPECT_THAT(*bytes, ::testing::HasSubstr("384500")) << ext;
    std::remove(path.c_str());
  }
  const std::string gltf = *EncodeGltf(mesh, false);
  EXPECT_THAT(gltf, ::testing::HasSubstr("\"version\":\"2.0\""));
  EXPECT_THAT(gltf, ::testing::HasSubstr("\"count\":" + std::to_string(mesh.indices.size())));
  EXPECT_THAT(std::string(WriteMesh(mesh, dir + "/x.stl").message()), ::testing::HasSubstr("unknown mesh extension"));
}

TEST(Export, ExrHeightGridRoundTripsExactly) {
  const HeightGrid g = MakeDtm(33, 21, {4512345.0, 12345678.0, 250});
  const std::string path = ::testing::TempDir() + "/ave_dtm.exr";
  ASSERT_TRUE(WriteHeightExr(g, path).ok());
  absl::StatusOr<HeightGrid> back = ReadHeightExr(path);
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(back->origin, g.origin);
  EXPECT_EQ(back->min_xy, g.min_xy);
  EXPECT_EQ(back->resolution_m, g.resolution_m);
  ASSERT_EQ(back->cols, g.cols);
  ASSERT_EQ(back->rows, g.rows);
  EXPECT_EQ(back->dtm, g.dtm);
  EXPECT_EQ(back->zmax, g.zmax);
  std::remove(path.c_str());
  EXPECT_FALSE(ReadHeightExr("/nonexistent.exr").ok());
}

}  // namespace
}  // namespace ave::model
