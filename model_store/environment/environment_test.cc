// Unit tests of the environment steps on hand-made clouds; the reconstruction of a simulated
// courtyard scored against the simulator's truth is tests/truth/environment_truth_test.cc.
#include "model_store/environment/environment.h"

#include <cmath>

#include <gtest/gtest.h>

namespace ave::model {
namespace {

using Eigen::Vector3d;
using Eigen::Vector3f;

TEST(Environment, RansacRefusesCollinearAndCoincidentPoints) {
  EnvironmentOptions o;
  std::vector<Vector3f> line, same;
  for (int i = 0; i < 200; ++i) line.emplace_back(0.1f * i, 0.05f * i, 0.0f), same.emplace_back(1.f, 2.f, 3.f);
  for (const auto* pts : {&line, &same}) {
    const absl::StatusOr<GroundPlane> g = FitGroundPlaneRansac(*pts, o);
    ASSERT_FALSE(g.ok());
    EXPECT_NE(g.status().message().find("collinear or coincident"), std::string::npos) << g.status();
  }
  EXPECT_FALSE(FitGroundPlaneRansac({Vector3f(0, 0, 0), Vector3f(1, 0, 0)}, o).ok());
  // A wall only (vertical plane): no ground within the tilt limit.
  std::vector<Vector3f> wall;
  for (int i = 0; i < 20; ++i)
    for (int k = 0; k < 20; ++k) wall.emplace_back(0.2f * i, 0.0f, 0.2f * k);
  const absl::StatusOr<GroundPlane> w = FitGroundPlaneRansac(wall, o);
  ASSERT_FALSE(w.ok());
  EXPECT_NE(w.status().message().find("horizontal"), std::string::npos) << w.status();
  EnvironmentOptions bad;
  bad.voxel_m = 0;
  EXPECT_EQ(bad.Check(), "voxel_m must be > 0");
  EXPECT_FALSE(ReconstructEnvironment({}, o).ok());
}

TEST(Environment, TiltedGroundPlaneWithClutterIsRecovered) {
  std::vector<Vector3f> pts;
  for (int i = 0; i < 60; ++i)
    for (int k = 0; k < 60; ++k) pts.emplace_back(0.5f * i - 15, 0.5f * k - 15, 0.02f * (0.5f * i - 15) + 1.0f);
  for (int i = 0; i < 1500; ++i) pts.emplace_back(static_cast<float>(i % 37) * 0.3f, 5.0f, 0.01f * i);  // a wall
  const absl::StatusOr<GroundPlane> g = FitGroundPlaneRansac(pts, EnvironmentOptions{});
  ASSERT_TRUE(g.ok()) << g.status();
  const Vector3d n = Vector3d(-0.02, 0, 1).normalized();
  EXPECT_LT(std::acos(std::min(1.0, g->normal.dot(n))), 1e-3);
  EXPECT_NEAR(g->HeightAbove(Vector3d(0, 0, 1.0)), 0.0, 1e-3);
  EXPECT_TRUE(std::isfinite(g->d));
}

TEST(Environment, FramesUnderDifferentHugeOriginsAccumulateTogether) {
  // The same static square seen in three frames whose clouds sit under origins ~1e7 m apart by
  // a few metres: one background, in the first frame's frame.
  std::vector<PointCloud> frames(3);
  for (int f = 0; f < 3; ++f) {
    frames[f].origin = Vector3d(1e7 + f * 3.0, 1e7 - f * 2.0, 100);
    const Vector3f shift = (Vector3d(1e7, 1e7, 100) - frames[f].origin).cast<float>();
    for (int i = 0; i < 20; ++i)
      for (int k = 0; k < 20; ++k) frames[f].xyz.push_back(Vector3f(0.5f * i + 0.25f, 0.5f * k + 0.25f, 0.05f) + shift);
  }
  const PointCloud bg = AccumulateBackground(frames, EnvironmentOptions{});
  EXPECT_EQ(bg.origin, frames[0].origin);
  ASSERT_EQ(bg.size(), 400u);
  for (const auto& p : bg.xyz) EXPECT_NEAR(p.z(), 0.05f, 1e-3f);
  // Only ground: no walls, no vegetation, no crash.
  const absl::StatusOr<EnvironmentModel> m = ReconstructEnvironment(frames, EnvironmentOptions{});
  ASSERT_TRUE(m.ok()) << m.status();
  EXPECT_TRUE(m->walls.empty());
  EXPECT_TRUE(m->mesh.positions.empty());
}

}  // namespace
}  // namespace ave::model
