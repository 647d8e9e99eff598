// Issue 19, session pose19j: unknown features on moving things must not join the pose filter's
// state. Real components: the campus scenario's backpack camera (rendered with every effect its
// scenario names, the lens's rolling occluder included, which crosses the image from 2.3 s on),
// plus a textured panel pasted into each frame and sliding across it (a mover the scene does not
// hold), the real VisionTracker in joint mode and a PoseEkf that only vision corrects in
// orientation (a position fix per frame stands in for GPS).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <gtest/gtest.h>

#include "sensor_agent/pose/vision.h"
#include "sensor_agent/sim/camera_effects.h"
#include "sensor_agent/sim/scenario.h"

namespace ave::pose {
namespace {

constexpr int kFirst = 66, kFrames = 60;  // 2.2-4.2 s
// The pasted mover: a panel with sharp-cornered patches, moving right by kSpeed px per frame.
constexpr int kPanelW = 140, kPanelH = 100, kPanelTop = 300, kPanelStart = 60, kSpeed = 5;

cv::Mat Panel() {
  cv::Mat panel(kPanelH, kPanelW, CV_8UC3, cv::Scalar(40, 60, 160));
  cv::RNG rng(19);
  for (int i = 0; i < 30; ++i) {
    const cv::Point a(rng.uniform(0, kPanelW - 10), rng.uniform(0, kPanelH - 10));
    cv::rectangle(panel, a, a + cv::Point(rng.uniform(6, 30), rng.uniform(6, 24)), cv::Scalar(rng.uniform(0, 255), rng.uniform(0, 255), rng.uniform(0, 255)),
                  cv::FILLED);
  }
  return panel;
}
cv::Rect PanelAt(int i) { return {kPanelStart + kSpeed * i, kPanelTop, kPanelW, kPanelH}; }

// On a mover: inside the pasted panel (2 px margin), or the simulator's class mask shows a person,
// a vehicle or the lens's occluder within 2 px.
bool OnMover(const sim::SimImage& frame, int i, const Eigen::Vector2d& px) {
  const cv::Rect panel = PanelAt(i);
  if (px.x() >= panel.x - 2 && px.x() <= panel.x + panel.width + 2 && px.y() >= panel.y - 2 && px.y() <= panel.y + panel.height + 2) return true;
  const int u0 = static_cast<int>(std::lround(px.x())), v0 = static_cast<int>(std::lround(px.y()));
  for (int dv = -2; dv <= 2; ++dv)
    for (int du = -2; du <= 2; ++du) {
      const int u = std::clamp(u0 + du, 0, frame.width - 1), v = std::clamp(v0 + dv, 0, frame.height - 1);
      const auto c = static_cast<sim::PixelClass>(frame.class_id[frame.Index(u, v)]);
      if (c == sim::PixelClass::kPerson || c == sim::PixelClass::kVehicle || c == sim::PixelClass::kOccluder) return true;
    }
  return false;
}

struct RunResult {
  int joined = 0, joined_on_movers = 0, refused = 0;
  double median_px = 0;  // misregistration of the visible model points over the last 30 frames
};

class VisionMoverTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    auto s = sim::LoadScenario("campus");
    ASSERT_TRUE(s.ok()) << s.status();
    scenario_ = new sim::Scenario(std::move(*s));
    const scene::CameraSpec& camera = *scenario_->world.FindCamera("backpack");
    const sim::SimulatedCamera sim_camera(scenario_->world, camera, scenario_->EffectsForCamera("backpack"), scenario_->seed);
    const cv::Mat panel = Panel();
    frames_ = new std::vector<sim::SimImage>;
    truth_ = new std::vector<Rigid3d>;
    for (int i = 0; i < kFrames; ++i) {
      sim::SimImage f = sim_camera.Frame(kFirst + i, (kFirst + i) / 30.0);
      cv::Mat view(f.height, f.width, CV_8UC3, f.bgr.data());
      const cv::Rect r = PanelAt(i) & cv::Rect(0, 0, f.width, f.height);
      panel(cv::Rect(0, 0, r.width, r.height)).copyTo(view(r));
      frames_->push_back(std::move(f));
      truth_->push_back(sim_camera.PoseAt((kFirst + i) / 30.0));
    }
  }
  static void TearDownTestSuite() {
    delete scenario_;
    delete frames_;
    delete truth_;
  }

  static RunResult Run(const VisionOptions& options) {
    const scene::CameraSpec& camera = *scenario_->world.FindCamera("backpack");
    const PinholeIntrinsics& k = camera.intrinsics;
    VisionTracker vision(CampusFeatureMap(scenario_->world), scene::BuildStaticMesh(scenario_->world, 2.0), k, options);
    PoseEkf ekf;
    ekf.Initialize(static_cast<int64_t>(std::llround(kFirst * 1e9 / 30)), (*truth_)[0], 0.05, 0.1 * 3.14159265358979323846 / 180);
    RunResult r;
    std::vector<double> errors;
    for (int i = 0; i < kFrames; ++i) {
      const Rigid3d& truth = (*truth_)[i];
      if (i > 0) {
        ekf.Predict(static_cast<int64_t>(std::llround((kFirst + i) * 1e9 / 30)));
        ekf.UpdatePosition(truth.translation, Eigen::Matrix3d::Identity() * 0.05 * 0.05);
      }
      const sim::SimImage& f = (*frames_)[i];
      const VisionFrameStats s = vision.Update(f.bgr.data(), f.width, f.height, ekf);
      r.refused += s.landmarks_refused;
      for (const auto& l : s.landmarks_joined) {
        ++r.joined;
        r.joined_on_movers += OnMover(f, i, l.px);
      }
      if (i < kFrames - 30) continue;
      for (const Eigen::Vector3d& p : vision.VisiblePoints(truth)) {
        const auto a = ProjectToPixel(k, truth.Inverse() * p), b = ProjectToPixel(k, ekf.world_from_camera().Inverse() * p);
        errors.push_back(a && b ? (*a - *b).norm() : 1e9);
      }
    }
    std::sort(errors.begin(), errors.end());
    r.median_px = errors.empty() ? 1e9 : errors[errors.size() / 2];
    return r;
  }

  static VisionOptions Joint() {
    VisionOptions o;
    o.joint_new_points = true;
    o.lock_frames = 3;
    o.lock_sigma_px = 4;  // no AHRS here: the constant-velocity prediction alone is uncertain by ~2 px
    return o;
  }

  static sim::Scenario* scenario_;
  static std::vector<sim::SimImage>* frames_;
  static std::vector<Rigid3d>* truth_;
};
sim::Scenario* VisionMoverTest::scenario_ = nullptr;
std::vector<sim::SimImage>* VisionMoverTest::frames_ = nullptr;
std::vector<Rigid3d>* VisionMoverTest::truth_ = nullptr;

// Without the joining tests, features on the movers (the panel, the lens's occluder) converge to a
// depth that absorbs their motion and join the state; with them, none does, while features on
// static structure still join, and the pose stays as registered as with known features only.
TEST_F(VisionMoverTest, FeaturesOnMoversDoNotJoinTheStateNorPullThePose) {
  VisionOptions untested = Joint();
  untested.join_bearing_drift_px = 0;
  untested.join_model_depth_tolerance = 0;
  const RunResult without = Run(untested);
  const RunResult with = Run(Joint());
  VisionOptions known_only = Joint();
  known_only.joint_new_points = false;
  const RunResult known = Run(known_only);

  std::printf("joined (on movers), refusals, median px over the last second: without the tests %d (%d), %d, %.3f; with %d (%d), %d, %.3f; known only %.3f\n",
              without.joined, without.joined_on_movers, without.refused, without.median_px, with.joined, with.joined_on_movers, with.refused, with.median_px,
              known.median_px);
  EXPECT_GT(without.joined_on_movers, 0) << "the scene must put movers in front of the tests (" << without.joined << " joined)";
  EXPECT_EQ(with.joined_on_movers, 0) << with.joined << " joined, " << with.refused << " refusals";
  EXPECT_GT(with.joined, 0) << "static features must still join";
  EXPECT_GT(with.refused, 0);
  EXPECT_EQ(without.refused, 0);
  // Until issue 19's seventh session the run without the tests was also the worse registered (its
  // movers pulled the pose). With the tracked known features' refusal beyond 3 px of the prediction
  // and their noise at 1 px, only one mover feature joins without the tests here and the 16 joined
  // features register it better (0.43 px against 0.66 with the tests, 0.61 known only); what the
  // tests guarantee is above (no mover joins) and below (the pose as registered as known only).
  EXPECT_LT(with.median_px, 1.2 * known.median_px + 0.05)
      << "joint with tests " << with.median_px << " px, without " << without.median_px << " px, known only " << known.median_px << " px";
}

TEST(VisionOptions, CheckNamesTheJoiningTestFields) {
  VisionOptions o;
  EXPECT_EQ(o.Check(), "");
  o.join_bearing_drift_px = -1;
  EXPECT_NE(o.Check().find("join_bearing_drift_px"), std::string::npos);
  o = VisionOptions();
  o.join_model_depth_tolerance = std::nan("");
  EXPECT_NE(o.Check().find("join_model_depth_tolerance"), std::string::npos);
  o = VisionOptions();
  o.new_point_depth_sigma_ratio = -0.1;
  EXPECT_NE(o.Check().find("new_point_depth_sigma_ratio"), std::string::npos);
}

}  // namespace
}  // namespace ave::pose
