// sim:SCENARIO#LIDAR (issue 16): the scenario's rotating LiDAR as a source, with truth, level and tilted.
#include <cmath>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "sensor_agent/lidar/lidar_source.h"
#include "sensor_agent/sim/scenario.h"
#include "sensor_agent/sim/sim_camera.h"

namespace ave::lidar {
namespace {

constexpr double kPi = 3.14159265358979323846;

TEST(LidarSourceSpec, TheScenarioTellsALidarFromACamera) {
  EXPECT_TRUE(*IsLidarSourceSpec("sim:courtyard#hdl64"));
  EXPECT_FALSE(*IsLidarSourceSpec("sim:courtyard#cam1"));
  EXPECT_TRUE(*IsLidarSourceSpec("pcap:/x.pcap"));
  EXPECT_TRUE(*IsLidarSourceSpec("udp:2368"));
  EXPECT_FALSE(*IsLidarSourceSpec("file:/v.mp4"));
  EXPECT_FALSE(IsLidarSourceSpec("sim:no-such-scenario#x").ok());
  EXPECT_THAT(std::string(OpenLidarSource("sim:courtyard#cam1", {}).status().message()),
              ::testing::HasSubstr("has no rotating LiDAR with that id"));
}

// Ground returns placed in the world by world_from_sensor lie on the terrain (within the
// courtyard's 2 cm range noise, a few sigma); with the sensor tilted 5° they do only when the
// tilt is applied (points stay in the tilted sensor frame).
double WorstGroundError_m(const LidarSweep& sweep, const scene::SyntheticCampus& campus, const Rigid3d& world_from_sensor) {
  double worst = 0;
  for (const SweepPoint& p : sweep.points) {
    if (p.truth_label != sim::kGroundId) continue;
    const Eigen::Vector3d w = world_from_sensor * p.p_in_sensor.cast<double>();
    worst = std::max(worst, std::abs(w.z() - campus.TerrainHeight(w.x(), w.y())));
  }
  return worst;
}

TEST(SimLidarSource, SweepsCarryTruthAndAreDeterministic) {
  auto a = OpenLidarSource("sim:courtyard#hdl64", {});
  auto b = OpenLidarSource("sim:courtyard#hdl64", {});
  ASSERT_TRUE(a.ok() && b.ok()) << a.status();
  EXPECT_DOUBLE_EQ((*a)->rate_hz(), 10);
  EXPECT_FALSE((*a)->live());
  absl::StatusOr<LidarSweep> s0 = (*a)->Next();
  absl::StatusOr<LidarSweep> s1 = (*a)->Next();
  absl::StatusOr<LidarSweep> t0 = (*b)->Next();
  ASSERT_TRUE(s0.ok() && s1.ok() && t0.ok());
  EXPECT_EQ(s0->t_ns, 0);
  EXPECT_EQ(s1->t_ns, 100'000'000);
  EXPECT_EQ(s0->rings, 64);
  ASSERT_EQ(s0->ring_elevation_rad.size(), 64u);
  EXPECT_NEAR(s0->ring_elevation_rad.front(), 2.0 * kPi / 180, 1e-6);
  EXPECT_NEAR(s0->ring_elevation_rad.back(), -24.8 * kPi / 180, 1e-6);
  ASSERT_EQ(s0->points.size(), t0->points.size());
  ASSERT_GT(s0->points.size(), 10000u);
  for (size_t i = 0; i < s0->points.size(); i += 97) EXPECT_EQ(s0->points[i].p_in_sensor, t0->points[i].p_in_sensor);
  ASSERT_TRUE(s0->world_from_sensor.has_value());
  absl::StatusOr<sim::Scenario> scenario = sim::LoadScenario("courtyard");
  EXPECT_TRUE(s0->world_from_sensor->translation.isApprox(scenario->rotating_lidars[0].position_m));
  // People around the sensor: truth feet, and points labelled with their mover ids.
  ASSERT_FALSE(s0->truth_feet_in_world.empty());
  size_t person_points = 0;
  for (const SweepPoint& p : s0->points) person_points += p.truth_label >= sim::kMoverIdBase;
  EXPECT_GT(person_points, 0u);
  EXPECT_LT(WorstGroundError_m(*s0, scenario->world, *s0->world_from_sensor), 0.1);
}

TEST(SimLidarSource, TiltedSensorIsPlacedByItsWorldFromSensor) {
  const Eigen::Matrix3d tilt = Eigen::AngleAxisd(5 * kPi / 180, Eigen::Vector3d(1, 1, 0).normalized()).toRotationMatrix();
  auto source = OpenLidarSource("sim:courtyard#hdl64", {.sim_world_from_sensor_rotation = tilt});
  ASSERT_TRUE(source.ok()) << source.status();
  absl::StatusOr<LidarSweep> s = (*source)->Next();
  ASSERT_TRUE(s.ok());
  ASSERT_TRUE(s->world_from_sensor.has_value());
  EXPECT_TRUE(s->world_from_sensor->rotation.toRotationMatrix().isApprox(tilt, 1e-12));
  absl::StatusOr<sim::Scenario> scenario = sim::LoadScenario("courtyard");
  EXPECT_LT(WorstGroundError_m(*s, scenario->world, *s->world_from_sensor), 0.1);
  Rigid3d level = *s->world_from_sensor;
  level.rotation = Eigen::Quaterniond::Identity();
  EXPECT_GT(WorstGroundError_m(*s, scenario->world, level), 1.0) << "the tilt must matter";
}

}  // namespace
}  // namespace ave::lidar
