// Issue 19, "ave-agent --pose-mode gps-imu-vision streams at the camera's full rate": a real
// ave-server core on loopback, the campus's moving camera (the backpack walker) registered as
// `ave-admin import-campus --moving` registers it, and the real ave-agent executable streaming it
// with its GPS + inertial + vision pose. A viewer's subscription sees every frame's pose; each is
// compared with the simulator's true pose of that frame (scene::CameraPoseAt at the frame's scene
// time, (sequence - 1) / fps) and must land near it; the agent's summary line gives the rate.
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "fusion_server/admin/admin_client.h"
#include "fusion_server/service/test_fixtures.h"
#include "model_store/scene/campus.h"
#include "viewer_client/client/scene_client.h"

namespace ave {
namespace {

constexpr char kSensor[] = "s3nsor";
constexpr char kViewer[] = "v1ewer";
constexpr char kAdmin[] = "adm1n";
constexpr double kFps = 30;
constexpr int kFrames = 150;

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? NAN : v[v.size() / 2];
}

double Quantile(std::vector<double> v, double q) {
  std::sort(v.begin(), v.end());
  return v.empty() ? NAN : v[std::min(v.size() - 1, static_cast<size_t>(q * v.size()))];
}

TEST(PoseEndToEnd, AgentInVisionModeStreamsPosesNearTheTruth) {
  fixtures::LocalServer server{"ave_pose_e2e"};
  const absl::Status started = server.Start(server.Options(kSensor, kViewer, kAdmin));
  ASSERT_TRUE(started.ok()) << started;
  const std::vector<scene::CameraSpec> moving = scene::BuiltinCampusMovingCameras();
  ASSERT_EQ(moving.size(), 1u);
  const scene::CameraSpec& backpack = moving[0];
  ASSERT_EQ(backpack.id, "backpack");
  ASSERT_EQ(backpack.fps, kFps) << "the campus's backpack camera runs at 30 Hz";
  ASSERT_TRUE(AdminClient(server.InsecureChannel(), kAdmin).AddCamera(CampusCameraRecord(backpack)).ok());

  const std::filesystem::path dir = std::filesystem::temp_directory_path() / ("ave_pose_e2e_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const std::string out = (dir / "agent.out").string(), log = (dir / "agent.log").string();
  const pid_t agent = ::fork();
  if (agent == 0) {
    std::freopen(out.c_str(), "w", stdout);
    std::freopen(log.c_str(), "w", stderr);
    const std::string bin = std::string(AVE_BIN_DIR) + "/ave-agent";
    const std::string fps = std::to_string(static_cast<int>(kFps)), frames = std::to_string(kFrames);
    execl(bin.c_str(), bin.c_str(), "--server", server.address().c_str(), "--camera", "backpack", "--token", kSensor, "--source",
          "sim:campus#backpack", "--fps", fps.c_str(), "--max-frames", frames.c_str(), "--pose-mode", "gps-imu-vision",
          static_cast<char*>(nullptr));
    std::_Exit(127);
  }
  ASSERT_GT(agent, 0);

  // Every frame's pose as the server hands it to a viewer, by sequence.
  viewer::SceneClient client(server.InsecureChannel(), kViewer, "pose-e2e");
  client.Start({});
  std::map<uint64_t, Rigid3d> poses;
  int status = 0;
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(100);
  while (std::chrono::steady_clock::now() < until) {
    for (const viewer::CameraView& view : client.Snapshot()) {
      if (view.id == "backpack" && view.frame_sequence > 0) poses.emplace(view.frame_sequence, view.world_from_camera);
    }
    if (::waitpid(agent, &status, WNOHANG) == agent) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  if (::waitpid(agent, &status, WNOHANG) == 0) {
    ::kill(agent, SIGKILL);
    ::waitpid(agent, &status, 0);
    FAIL() << "the agent did not finish " << kFrames << " frames in 100 s";
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  for (const viewer::CameraView& view : client.Snapshot()) {
    if (view.id == "backpack" && view.frame_sequence > 0) poses.emplace(view.frame_sequence, view.world_from_camera);
  }
  client.Stop();
  std::ifstream log_in(log), out_in(out);
  std::stringstream agent_log, summary;
  agent_log << log_in.rdbuf();
  summary << out_in.rdbuf();
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << "agent: " << agent_log.str();
  server.Stop();
  std::filesystem::remove_all(dir);

  // The agent's own summary: every frame sent, and the rate it reached (reported, not asserted:
  // wall time on a shared machine is not a unit-test property; docs/BENCHMARKS.md has the figure).
  std::smatch m;
  const std::string line = summary.str();
  ASSERT_TRUE(std::regex_search(line, m, std::regex("\"frames_sent\":(\\d+)"))) << line;
  EXPECT_EQ(std::stoi(m[1]), kFrames) << line;
  ASSERT_TRUE(std::regex_search(line, m, std::regex("\"frames_per_s\":([0-9.]+)"))) << line;
  std::printf("agent summary: %s", line.c_str());

  // Poses against the truth of their frame, from 2 s on (the vision lock takes its first frames).
  std::vector<double> position_m, angle_deg;
  for (const auto& [sequence, pose] : poses) {
    const double t_s = static_cast<double>(sequence - 1) / kFps;
    if (t_s < 2.0) continue;
    const Rigid3d truth = scene::CameraPoseAt(scene::BuiltinCampus(), backpack, t_s);
    position_m.push_back((pose.translation - truth.translation).norm());
    angle_deg.push_back(Eigen::AngleAxisd(truth.rotation.inverse() * pose.rotation).angle() * 180 / M_PI);
  }
  // A viewer polling every few ms sees most frames even on a loaded machine.
  ASSERT_GE(position_m.size(), 30u) << poses.size() << " frames seen";
  const double pos_median = Median(position_m), ang_median = Median(angle_deg);
  const double pos_p90 = Quantile(position_m, 0.9), ang_p90 = Quantile(angle_deg, 0.9);
  std::printf("%zu frames from 2 s on: position error median %.3f m, p90 %.3f m; orientation error median %.3f deg, p90 %.3f deg\n",
              position_m.size(), pos_median, pos_p90, ang_median, ang_p90);
  // GPS + inertial alone is off by ~2 deg here (the AHRS drifts, the GPS is out from 2 s on:
  // 19 px median misregistration, docs/BENCHMARKS.md "Pose"); the vision-locked pose is within a
  // few tenths of a degree and decimetres.
  EXPECT_LT(ang_median, 0.3);
  EXPECT_LT(ang_p90, 0.8);
  EXPECT_LT(pos_median, 0.5);
  EXPECT_LT(pos_p90, 1.0);
}

}  // namespace
}  // namespace ave
