#include "model_store/geometry/bvh.h"

#include <chrono>
#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "model_store/geometry/raycast.h"

namespace ave {
namespace {

// A wavy height-field grid plus axis-aligned boxes and a soup of random triangles: flat faces that
// coincide with BVH box faces, shared edges, and thin slivers.
TriangleMesh TestMesh(uint64_t seed) {
  TriangleMesh m;
  const int n = 41;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const double x = -20 + i, y = -20 + j;
      m.positions.emplace_back(x, y, 0.5 * std::sin(x / 5) * std::cos(y / 7));
    }
  for (int j = 0; j + 1 < n; ++j)
    for (int i = 0; i + 1 < n; ++i) {
      const uint32_t a = j * n + i, b = a + 1, c = a + n + 1, d = a + n;
      m.indices.insert(m.indices.end(), {a, b, c, a, c, d});
    }
  auto box = [&](Eigen::Vector3f lo, Eigen::Vector3f hi) {
    const uint32_t f = static_cast<uint32_t>(m.positions.size());
    for (int k = 0; k < 8; ++k) m.positions.emplace_back(k & 1 ? hi.x() : lo.x(), k & 2 ? hi.y() : lo.y(), k & 4 ? hi.z() : lo.z());
    const uint32_t q[6][4] = {{0, 1, 3, 2}, {4, 6, 7, 5}, {0, 4, 5, 1}, {2, 3, 7, 6}, {0, 2, 6, 4}, {1, 5, 7, 3}};
    for (const auto& s : q) m.indices.insert(m.indices.end(), {f + s[0], f + s[1], f + s[2], f + s[0], f + s[2], f + s[3]});
  };
  box({-10, -10, -1}, {-4, -2, 8});
  box({3, 3, -1}, {9, 12, 15});
  box({-2, 6, -1}, {2, 8, 3});
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-18, 18), h(0, 10), small(-2, 2);
  for (int k = 0; k < 300; ++k) {
    const Eigen::Vector3f c(u(rng), u(rng), h(rng));
    const uint32_t f = static_cast<uint32_t>(m.positions.size());
    for (int v = 0; v < 3; ++v) m.positions.push_back(c + Eigen::Vector3f(small(rng), small(rng), small(rng)));
    m.indices.insert(m.indices.end(), {f, f + 1, f + 2});
  }
  return m;
}

void ExpectSameHit(const std::optional<RayHit>& brute, const std::optional<RayHit>& fast, const TriangleMesh& mesh,
                   const Eigen::Vector3d& o, const Eigen::Vector3d& d) {
  ASSERT_EQ(brute.has_value(), fast.has_value()) << "origin " << o.transpose() << " dir " << d.transpose();
  if (!brute) return;
  EXPECT_DOUBLE_EQ(brute->distance_m, fast->distance_m);
  if (brute->triangle != fast->triangle) {
    // Only an exact tie (a ray through a shared edge) may pick a different triangle.
    const auto other = RaycastMesh(mesh, o, d, fast->distance_m * (1 - 1e-12) - 1e-12, fast->distance_m);
    ASSERT_TRUE(other.has_value());
    EXPECT_DOUBLE_EQ(other->distance_m, fast->distance_m);
  }
}

TEST(MeshBvh, AgreesWithBruteForceOnRandomRays) {
  const TriangleMesh mesh = TestMesh(7);
  const MeshBvh bvh(mesh);
  EXPECT_EQ(bvh.TriangleCount(), mesh.TriangleCount());
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-25, 25), z(-2, 20), dir(-1, 1);
  int hits = 0;
  for (int k = 0; k < 3000; ++k) {
    const Eigen::Vector3d o(u(rng), u(rng), z(rng));
    const Eigen::Vector3d d(dir(rng), dir(rng), dir(rng));
    const auto brute = RaycastMesh(mesh, o, d);
    hits += brute.has_value();
    ExpectSameHit(brute, bvh.Raycast(o, d), mesh, o, d);
  }
  EXPECT_GT(hits, 600);  // the test exercises hits, not only misses
}

TEST(MeshBvh, AgreesOnGrazingAndAxisAlignedRays) {
  const TriangleMesh mesh = TestMesh(8);
  const MeshBvh bvh(mesh);
  std::mt19937_64 rng(12);
  std::uniform_real_distribution<double> u(-25, 25), z(-2, 20), tiny(-1e-9, 1e-9);
  for (int k = 0; k < 2000; ++k) {
    const Eigen::Vector3d o(u(rng), u(rng), z(rng));
    Eigen::Vector3d d = Eigen::Vector3d::Zero();
    d[k % 3] = (k / 3) % 2 ? 1 : -1;  // exactly axis-aligned: zero components in the slab test
    if (k % 5 == 0) d += Eigen::Vector3d(tiny(rng), tiny(rng), tiny(rng));  // nearly so
    ExpectSameHit(RaycastMesh(mesh, o, d), bvh.Raycast(o, d), mesh, o, d);
  }
  // Rays lying in the plane of a box face (x = 3), in a roof's plane (z = 15) and along a box edge.
  for (const auto& [o, d] : std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>>{
           {{3, -5, 5}, {0, 1, 0}}, {{0, 5, 15}, {1, 0.3, 0}}, {{3, 3, 20}, {0, 0, -1}}, {{-30, 3, 15}, {1, 0, 0}}}) {
    ExpectSameHit(RaycastMesh(mesh, o, d), bvh.Raycast(o, d), mesh, o, d);
  }
}

TEST(MeshBvh, RespectsDistanceWindowAndDegenerateInput) {
  const TriangleMesh mesh = TestMesh(9);
  const MeshBvh bvh(mesh);
  const Eigen::Vector3d o(0, 0, 30), down(0, 0, -1);
  const auto full = bvh.Raycast(o, down);
  ASSERT_TRUE(full.has_value());
  EXPECT_FALSE(bvh.Raycast(o, down, 1e-4, full->distance_m - 1e-6).has_value());
  const auto beyond = bvh.Raycast(o, down, full->distance_m + 1e-6);
  const auto beyond_brute = RaycastMesh(mesh, o, down, full->distance_m + 1e-6);
  ASSERT_EQ(beyond.has_value(), beyond_brute.has_value());
  EXPECT_FALSE(bvh.Raycast(o, {0, 0, 0}).has_value());
  EXPECT_FALSE(bvh.Raycast(o, {NAN, 0, -1}).has_value());
  EXPECT_FALSE(bvh.Raycast({INFINITY, 0, 0}, down).has_value());
  EXPECT_FALSE(bvh.Raycast(o, {0, 0, 1}).has_value());  // into the sky
  EXPECT_FALSE(MeshBvh().Raycast(o, down).has_value());
  EXPECT_FALSE(MeshBvh(TriangleMesh{}).Raycast(o, down).has_value());
}

TEST(MeshBvh, TestsAFewTrianglesPerRayWhereBruteForceTestsThemAll) {
  const TriangleMesh mesh = TestMesh(10);
  const MeshBvh bvh(mesh);
  std::mt19937_64 rng(13);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<Eigen::Vector3d> dirs(500);
  for (auto& d : dirs) d = Eigen::Vector3d(u(rng), u(rng), u(rng) - 0.5);
  double sum_brute = 0, sum_fast = 0;
  MeshBvh::Work work;
  for (const auto& d : dirs) {
    if (auto h = RaycastMesh(mesh, {0, 0, 5}, d)) sum_brute += h->distance_m;
    if (auto h = bvh.Raycast({0, 0, 5}, d, 1e-4, 1e9, &work)) sum_fast += h->distance_m;
  }
  EXPECT_DOUBLE_EQ(sum_brute, sum_fast);
  // Brute force tests every triangle for every ray; the hierarchy must test under a twentieth of
  // them (counted, not timed: the speed-up in seconds is ave-bench's business).
  const double brute_tests = static_cast<double>(dirs.size()) * mesh.TriangleCount();
  EXPECT_GT(work.triangles_tested, 0u);
  EXPECT_LT(work.triangles_tested * 20.0, brute_tests) << work.triangles_tested << " triangle tests for " << dirs.size()
                                                       << " rays over " << mesh.TriangleCount() << " triangles";
}

}  // namespace
}  // namespace ave
