// Client side of LiDAR points (issue 16): packed wire points into the local frame, tied to tracks
// and fused objects; labels the sweep does not have are left unassigned, never out of bounds.
#include "viewer_client/client/lidar_points.h"

#include <cmath>
#include <set>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace ave::viewer {
namespace {

using ::testing::HasSubstr;

void Put(std::string& out, int16_t x, int16_t y, int16_t z, uint16_t label) {
  for (uint16_t v : {static_cast<uint16_t>(x), static_cast<uint16_t>(y), static_cast<uint16_t>(z), label}) {
    out.push_back(static_cast<char>(v & 0xFF));
    out.push_back(static_cast<char>(v >> 8));
  }
}

TEST(DecodeLidarPoints, PlacesPointsInTheLocalFrameAndTiesThemToTracksAndObjects) {
  std::string packed;
  Put(packed, 100, -250, 5, 2);     // 1 m, -2.5 m, 5 cm; the second track
  Put(packed, -32767, 0, 0, 0);    // unassigned
  Put(packed, 0, 0, 0, 3);         // a label past the two tracks
  const std::vector<LidarTrackView> tracks = {{11, {}, {}, 900}, {12, {}, {}, 901}};
  // Sensor turned 90 degrees about z (x_sensor -> y_local) and standing at (10, 20, 2).
  const Rigid3d world_from_sensor(Eigen::Quaterniond(Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ())),
                                  Eigen::Vector3d(10, 20, 2));
  auto cloud = DecodeLidarPoints(packed, 3, world_from_sensor, tracks);
  ASSERT_TRUE(cloud.ok()) << cloud.status();
  ASSERT_EQ(cloud->p_local.size(), 3u);
  EXPECT_NEAR(cloud->p_local[0].x(), 10 + 2.5f, 1e-4);
  EXPECT_NEAR(cloud->p_local[0].y(), 20 + 1.0f, 1e-4);
  EXPECT_NEAR(cloud->p_local[0].z(), 2.05f, 1e-4);
  EXPECT_NEAR(cloud->p_local[1].y(), 20 - 327.67f, 1e-3);
  EXPECT_EQ(cloud->track_id, (std::vector<uint32_t>{12, 0, 0}));
  EXPECT_EQ(cloud->object_id, (std::vector<uint64_t>{901, 0, 0}));
  EXPECT_EQ(cloud->bad_labels, 1u);
}

TEST(DecodeLidarPoints, SizeMismatchIsAnErrorNamingTheSizes) {
  const auto cloud = DecodeLidarPoints(std::string(12, '\0'), 2, Rigid3d(), {});
  ASSERT_FALSE(cloud.ok());
  EXPECT_THAT(std::string(cloud.status().message()), HasSubstr("12 bytes for 2 points"));
  EXPECT_TRUE(DecodeLidarPoints("", 0, Rigid3d(), {}).ok());
}

TEST(IdColor, NeighbouringIdsGetDifferentColoursAndZeroIsGrey) {
  std::set<std::tuple<int, int, int>> seen;
  for (uint64_t id = 1; id <= 12; ++id) {
    const Eigen::Vector3f c = IdColor(id);
    EXPECT_TRUE((c.array() >= 0).all() && (c.array() <= 1).all());
    seen.emplace(std::lround(c.x() * 20), std::lround(c.y() * 20), std::lround(c.z() * 20));
    EXPECT_GT((IdColor(id) - IdColor(id + 1)).norm(), 0.1f) << id;
  }
  EXPECT_EQ(seen.size(), 12u);
  EXPECT_FLOAT_EQ(IdColor(0).x(), IdColor(0).y());
}

}  // namespace
}  // namespace ave::viewer
