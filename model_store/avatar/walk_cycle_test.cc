#include "model_store/avatar/walk_cycle.h"

#include <cmath>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

namespace ave::avatar {
namespace {

constexpr double kPi = 3.14159265358979323846;

// An axis-aligned box as 12 triangles (8 vertices).
void AddBox(AvatarFrame& f, const Eigen::Vector3f& lo, const Eigen::Vector3f& hi) {
  const uint32_t first = static_cast<uint32_t>(f.positions_m.size());
  for (int k = 0; k < 8; ++k) {
    f.positions_m.emplace_back(k & 1 ? hi.x() : lo.x(), k & 2 ? hi.y() : lo.y(), k & 4 ? hi.z() : lo.z());
    f.normals.push_back(Eigen::Vector3f::UnitZ());
    f.uv.emplace_back(0.5f, 0.5f);
  }
  const uint32_t q[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (const auto& s : q) f.indices.insert(f.indices.end(), {first + s[0], first + s[1], first + s[2], first + s[0], first + s[2], first + s[3]});
}

// A "walker": a body box and a leg box swinging with `period` frames, walking `step_m` per frame
// along `heading`, with its vertices densified by extra small boxes so the Chamfer sees shape.
AvatarFrame Walker(int f, int period, double step_m, double heading, Eigen::Vector3d* root) {
  AvatarFrame a;
  const float swing = static_cast<float>(0.25 * std::sin(2 * kPi * f / period));
  AddBox(a, {-0.1f, -0.15f, 0.9f}, {0.1f, 0.15f, 1.5f});
  AddBox(a, {swing - 0.05f, 0.02f, 0.0f}, {swing + 0.05f, 0.12f, 0.9f});
  AddBox(a, {-swing - 0.05f, -0.12f, 0.0f}, {-swing + 0.05f, -0.02f, 0.9f});
  a.atlas_width = a.atlas_height = 1;
  a.atlas_rgb = {200, 100, 50};
  *root = Eigen::Vector3d(1.0, -2.0, 0) + f * step_m * Eigen::Vector3d(std::cos(heading), std::sin(heading), 0);
  const Eigen::Affine3d world_from_avatar = Eigen::Translation3d(*root) * Eigen::AngleAxisd(heading, Eigen::Vector3d::UnitZ());
  for (Eigen::Vector3f& p : a.positions_m) p = (world_from_avatar * p.cast<double>()).cast<float>();
  return a;
}

TEST(WalkCycle, FindsTheKnownPeriodAndRemovesRootAndHeading) {
  const int period = 9;
  const double heading = 2.2, step = 0.07;
  std::vector<AvatarFrame> frames;
  std::vector<Eigen::Vector3d> roots;
  for (int f = 0; f < 14; ++f) {
    Eigen::Vector3d r;
    frames.push_back(Walker(f, period, step, heading, &r));
    roots.push_back(r);
  }
  WalkCycleOptions o;
  o.min_cycle_s = 0.5;  // 5 frames at 10 fps: a half period (4.5 frames, legs swapped) is shorter
  absl::StatusOr<WalkCycle> c = FindWalkCycle(frames, roots, 0.1, "walker", o);
  ASSERT_TRUE(c.ok()) << c.status();
  EXPECT_EQ(c->end - c->first, period);
  EXPECT_LT(c->shape_difference_m, 1e-4);
  EXPECT_EQ(c->sequence.frames.size(), static_cast<size_t>(period));
  EXPECT_NEAR(c->sequence.stride_m, period * step, 1e-9);
  EXPECT_NEAR(c->sequence.SpeedMps(), step / 0.1, 1e-9);
  for (double h : c->heading_rad) EXPECT_NEAR(h, heading, 1e-9);
  // Avatar frame: the body box is centred on the origin in x and y, the legs swing along x.
  for (const AvatarFrame& f : c->sequence.frames) {
    for (int k = 0; k < 8; ++k) {
      EXPECT_LE(std::abs(f.positions_m[k].x()), 0.1f + 1e-5f);
      EXPECT_LE(std::abs(f.positions_m[k].y()), 0.15f + 1e-5f);
    }
  }
}

TEST(WalkCycle, OneFrameIsAStatue) {
  Eigen::Vector3d root;
  const AvatarFrame f = Walker(0, 9, 0.0, 0.0, &root);
  absl::StatusOr<WalkCycle> c = FindWalkCycle({f}, {root}, 0.1, "statue", {});
  ASSERT_TRUE(c.ok()) << c.status();
  ASSERT_EQ(c->sequence.frames.size(), 1u);
  EXPECT_EQ(c->sequence.stride_m, 0.0);
  EXPECT_EQ(c->sequence.SpeedMps(), 0.0);
  EXPECT_NEAR(c->sequence.frames[0].positions_m[0].x(), -0.1f, 1e-5f);  // root removed, heading +x kept
}

TEST(WalkCycle, TooShortForACycleIsAClearError) {
  std::vector<AvatarFrame> frames;
  std::vector<Eigen::Vector3d> roots;
  for (int f = 0; f < 3; ++f) {
    Eigen::Vector3d r;
    frames.push_back(Walker(f, 9, 0.05, 0.0, &r));
    roots.push_back(r);
  }
  absl::StatusOr<WalkCycle> c = FindWalkCycle(frames, roots, 0.1, "short", {});
  ASSERT_FALSE(c.ok());
  EXPECT_NE(c.status().message().find("3 frames"), std::string::npos) << c.status();
  roots.pop_back();
  EXPECT_FALSE(FindWalkCycle(frames, roots, 0.1, "short", {}).ok());
}

TEST(WalkCycle, GroundCentroidIsUnderTheBody) {
  Eigen::Vector3d root;
  const AvatarFrame f = Walker(0, 9, 0.0, 0.0, &root);
  const Eigen::Vector3d g = GroundCentroid(f);
  EXPECT_NEAR(g.x(), root.x(), 0.01);
  EXPECT_NEAR(g.y(), root.y(), 0.01);
  EXPECT_NEAR(g.z(), 0.0, 1e-6);
}

}  // namespace
}  // namespace ave::avatar
