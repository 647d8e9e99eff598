#include "model_store/geometry/raycast.h"

#include <gtest/gtest.h>

namespace ave {
namespace {

TriangleMesh UnitSquareAtZ0() {
  TriangleMesh m;
  m.positions = {{0, 0, 0}, {10, 0, 0}, {10, 10, 0}, {0, 10, 0}};
  m.indices = {0, 1, 2, 0, 2, 3};
  return m;
}

TEST(Raycast, HitsAtTheRightDistance) {
  const auto hit = RaycastMesh(UnitSquareAtZ0(), {5, 5, 10}, {0, 0, -1});
  ASSERT_TRUE(hit.has_value());
  EXPECT_NEAR(hit->distance_m, 10, 1e-9);
}

TEST(Raycast, GrazingRayIsRejected) {
  // Parallel to the plane, inside it: no intersection rather than a NaN or an arbitrary point.
  EXPECT_FALSE(RaycastMesh(UnitSquareAtZ0(), {-1, 5, 0}, {1, 0, 0}).has_value());
  EXPECT_FALSE(RaycastMesh(UnitSquareAtZ0(), {-1, 5, 1e-3}, {1, 0, 0}).has_value());
}

TEST(Raycast, SkyRayAndDegenerateDirectionsMiss) {
  EXPECT_FALSE(RaycastMesh(UnitSquareAtZ0(), {5, 5, 10}, {0, 0, 1}).has_value());
  EXPECT_FALSE(RaycastMesh(UnitSquareAtZ0(), {5, 5, 10}, {0, 0, 0}).has_value());
  EXPECT_FALSE(RaycastMesh(UnitSquareAtZ0(), {5, 5, 10}, {NAN, 0, -1}).has_value());
}

TEST(Raycast, SegmentClearIgnoresEndpointSurfaces) {
  const TriangleMesh m = UnitSquareAtZ0();
  EXPECT_TRUE(SegmentIsClear(m, {5, 5, 0}, {5, 5, 20}));
  EXPECT_FALSE(SegmentIsClear(m, {5, 5, -5}, {5, 5, 20}));
}

}  // namespace
}  // namespace ave
