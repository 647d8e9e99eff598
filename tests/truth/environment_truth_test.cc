// The i4D environment (i4D §3.3) from simulated rotating-LiDAR frames of the courtyard scenario,
// scored against the simulator's truth (tests/truth/environment_truth.h).
#include "model_store/environment/environment.h"

#include <cstdio>

#include <gtest/gtest.h>

#include "tests/truth/environment_truth.h"

namespace ave::model {
namespace {

TEST(Environment, CourtyardWallsGroundAndVegetationAgainstTruth) {
  absl::StatusOr<testing::LidarFrames> truth = testing::SimulateLidarFrames("courtyard", 20, 0.15);
  ASSERT_TRUE(truth.ok()) << truth.status();
  const absl::StatusOr<EnvironmentModel> model = ReconstructEnvironment(truth->frames, EnvironmentOptions{});
  ASSERT_TRUE(model.ok()) << model.status();
  const testing::EnvironmentScore s = testing::ScoreEnvironment(*truth, *model);
  std::printf("background %d points (%d mover points left); vegetation removed %d/%d = %.3f, other removed %d/%d = %.3f\n",
              s.background_points, s.mover_points, s.vegetation_removed, s.vegetation_points, s.vegetation_removal_rate,
              s.other_removed, s.other_points, s.false_removal_rate);
  std::printf("vegetation seen in the frames: %d voxels; left in the model %d: overall removal %.3f\n", s.vegetation_observed_voxels,
              s.vegetation_points - s.vegetation_removed, s.overall_vegetation_removal_rate);
  std::printf("ground normal %.3f deg off; walls %d, matched %d, faces %d; position %.3f/%.3f m, angle %.3f/%.3f deg, top %.2f m\n",
              s.ground_angle_deg, s.walls, s.walls_matched, s.faces_found, s.position_err_m_mean, s.position_err_m_max,
              s.angle_err_deg_mean, s.angle_err_deg_max, s.top_err_m_mean);
  EXPECT_LT(s.ground_angle_deg, 0.2);
  EXPECT_LT(s.mover_points, s.background_points / 100);  // people crossing are not background
  EXPECT_GE(s.vegetation_removal_rate, 0.8);
  EXPECT_GE(s.overall_vegetation_removal_rate, 0.9);
  EXPECT_LT(s.false_removal_rate, 0.05);
  EXPECT_GE(s.faces_found, 4);  // the four wings' yard faces at least
  EXPECT_GE(s.walls_matched, s.walls * 8 / 10);
  EXPECT_LT(s.position_err_m_mean, 0.15);
  EXPECT_LT(s.angle_err_deg_mean, 1.0);
  EXPECT_EQ(model->mesh.TriangleCount(), 4 * model->walls.size());
}

}  // namespace
}  // namespace ave::model
