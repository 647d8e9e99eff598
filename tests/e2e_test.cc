// The whole loop on loopback with real components: ave-server core (gRPC, SQLite store), three
// simulated camera agents streaming JPEG over gRPC, and a headless viewer that renders the
// projected video with shadow-map visibility. Truth comes from ray casting the campus model.
#include <atomic>
#include <functional>
#include <filesystem>
#include <thread>

#include <gtest/gtest.h>
#include <grpcpp/grpcpp.h>

#include "fusion_server/admin/admin_client.h"
#include "fusion_server/service/server.h"
#include "fusion_server/service/test_fixtures.h"
#include "model_store/geometry/raycast.h"
#include "model_store/scene/campus.h"
#include "sensor_agent/stream/agent_streamer.h"
#include "viewer_client/client/scene_client.h"
#include "viewer_client/client/viewer_app.h"
#include "viewer_client/render/gl_context.h"
#include "viewer_client/render/renderer.h"

namespace ave {
namespace {

using viewer::CameraView;

constexpr char kSensor[] = "s3nsor";
constexpr char kViewer[] = "v1ewer";
constexpr char kAdmin[] = "adm1n";

struct Rgb {
  double r = 0, g = 0, b = 0;
  double MaxAbsDiff(const Rgb& o) const { return std::max({std::abs(r - o.r), std::abs(g - o.g), std::abs(b - o.b)}); }
};

Rgb Pixel(const std::vector<uint8_t>& rgba, int width, int col, int row) {
  const uint8_t* p = &rgba[(size_t(row) * width + col) * 4];
  return {double(p[0]), double(p[1]), double(p[2])};
}

struct DecodedImageRef {
  const uint8_t* rgba;
  int width, height;
};

// Bilinear sample at pixel coordinates (OpenCV convention: integers are pixel centres), as the
// GPU samples the projected texture.
Rgb Bilinear(const DecodedImageRef& im, double u, double v) {
  const int x0 = std::clamp(static_cast<int>(std::floor(u)), 0, im.width - 2);
  const int y0 = std::clamp(static_cast<int>(std::floor(v)), 0, im.height - 2);
  const double fx = std::clamp(u - x0, 0.0, 1.0), fy = std::clamp(v - y0, 0.0, 1.0);
  Rgb out;
  for (int dy = 0; dy < 2; ++dy) {
    for (int dx = 0; dx < 2; ++dx) {
      const double w = (dx ? fx : 1 - fx) * (dy ? fy : 1 - fy);
      const uint8_t* p = &im.rgba[(size_t(y0 + dy) * im.width + x0 + dx) * 4];
      out.r += w * p[0];
      out.g += w * p[1];
      out.b += w * p[2];
    }
  }
  return out;
}

class EndToEnd : public ::testing::Test {
 protected:
  void SetUp() override {
    const absl::Status started = server_.Start(server_.Options(kSensor, kViewer, kAdmin));
    ASSERT_TRUE(started.ok()) << started;
    address_ = server_.address();
    channel_ = server_.InsecureChannel();
    AdminClient admin(channel_, kAdmin);
    for (const auto& cam : campus_.cameras) ASSERT_TRUE(admin.AddCamera(CampusCameraRecord(cam)).ok());
    for (size_t i = 0; i < campus_.cameras.size(); ++i) {
      stops_[i] = false;
      agents_.emplace_back([this, i] {
        AgentOptions a;
        a.server = address_;
        a.camera_id = campus_.cameras[i].id;
        a.token = kSensor;
        a.fps = 4;
        auto source = OpenSource("sim:campus#" + a.camera_id, {.fps = a.fps});
        ASSERT_TRUE(source.ok());
        AgentStreamer streamer(a, std::move(*source));
        EXPECT_TRUE(streamer.Run(stops_[i]).ok());
      });
    }
  }
  void TearDown() override {
    for (auto& s : stops_) s = true;
    for (auto& t : agents_) t.join();
    server_.Stop();
  }

  scene::SyntheticCampus campus_ = scene::BuiltinCampus();
  fixtures::LocalServer server_{"ave_e2e"};
  std::string address_;
  std::shared_ptr<grpc::Channel> channel_;
  std::array<std::atomic<bool>, 3> stops_;
  std::vector<std::thread> agents_;
};

TEST_F(EndToEnd, VideoLandsWhereCameraOneSeesAndNotBehindBuildings) {
  viewer::SceneClient client(channel_, kViewer, "e2e");
  uint64_t version = 0;
  absl::StatusOr<TriangleMesh> mesh = client.FetchStaticModel(&version);
  ASSERT_TRUE(mesh.ok()) << mesh.status();
  EXPECT_EQ(version, server_->static_model_version());
  client.Start({});
  auto all_have_frames = [](const std::vector<CameraView>& cams) {
    return cams.size() == 3 && std::all_of(cams.begin(), cams.end(), [](const CameraView& c) { return c.image != nullptr; });
  };
  ASSERT_TRUE(client.WaitUntil(all_have_frames, std::chrono::seconds(60))) << client.last_error();

  constexpr int kW = 800, kH = 600;
  auto context = viewer::CreateHeadlessContext(kW, kH);
  ASSERT_TRUE(context.ok()) << context.status();
  ASSERT_TRUE((*context)->MakeCurrent().ok());
  auto renderer = viewer::Renderer::Create();
  ASSERT_TRUE(renderer.ok()) << renderer.status();
  ASSERT_TRUE((*renderer)->SetStaticMesh(*mesh).ok());

  // A near-plan view over camera 1's field.
  const Eigen::Vector3d eye(0, -30, 160), target(0, -29, 0);
  viewer::View view = viewer::BrowseView({0, 0, kW, kH}, eye, target, 60);
  view.draw_frustums = false;

  // Baseline: the model's own colours (no projectors).
  ASSERT_TRUE((*renderer)->SetProjectors({}).ok());
  ASSERT_TRUE((*renderer)->Render({view}, kW, kH).ok());
  auto base = (*context)->ReadPixels();
  ASSERT_TRUE(base.ok());

  const std::vector<CameraView> cams = client.Snapshot();
  const std::vector<viewer::Projector> all = viewer::MakeProjectors(cams);
  ASSERT_EQ(all.size(), 3u);
  // The quad view everyone looks at, all three cameras projecting.
  ASSERT_TRUE((*renderer)->SetProjectors(all).ok());
  ASSERT_TRUE((*renderer)->Render({view}, kW, kH).ok());
  auto everything = (*context)->ReadPixels();
  ASSERT_TRUE(everything.ok());
  ASSERT_TRUE(viewer::WritePng((server_.dir() / "e2e_all.png").string(), *everything, kW, kH).ok());

  // Camera 1 alone, so each pixel has one expected colour.
  const CameraView* cam1 = nullptr;
  for (const auto& c : cams)
    if (c.id == "cam1") cam1 = &c;
  ASSERT_NE(cam1, nullptr);
  std::vector<viewer::Projector> only1;
  for (const auto& p : all)
    if (p.camera_id == "cam1") only1.push_back(p);
  ASSERT_TRUE((*renderer)->SetProjectors(only1).ok());
  ASSERT_TRUE((*renderer)->Render({view}, kW, kH).ok());
  auto shot = (*context)->ReadPixels();
  ASSERT_TRUE(shot.ok());

  // Walk the snapshot's pixels: cast each pixel's ray into the model (truth), keep open-ground
  // hits, and ask whether camera 1 sees that ground point.
  const PinholeIntrinsics view_k = PinholeIntrinsics::FromFov(kW, kH, 60);
  const Rigid3d view_pose = LookAt(eye, target);
  const DecodedImageRef video{cam1->image->rgba.data(), cam1->image->width, cam1->image->height};
  int visible_checked = 0, visible_match = 0, hidden_checked = 0, hidden_kept = 0, hidden_discriminative = 0;
  for (int row = 4; row < kH; row += 9) {
    for (int col = 4; col < kW; col += 9) {
      const Eigen::Vector3d dir = view_pose.rotation * PixelRay(view_k, Eigen::Vector2d(col, row));
      const auto hit = RaycastMesh(*mesh, eye, dir);
      if (!hit) continue;
      const Eigen::Vector3d g = eye + hit->distance_m * dir;
      if (campus_.BuildingAt(g.x(), g.y()) >= 0 || std::abs(g.z() - campus_.TerrainHeight(g.x(), g.y())) > 0.1) continue;
      const auto uv = ProjectToPixel(cam1->intrinsics, cam1->world_from_camera.Inverse() * g);
      if (!uv || uv->x() < 3 || uv->y() < 3 || uv->x() > cam1->intrinsics.width - 4 ||
          uv->y() > cam1->intrinsics.height - 4) {
        continue;
      }
      const Rgb out = Pixel(*shot, kW, col, row);
      const Rgb own = Pixel(*base, kW, col, row);
      const Rgb seen = Bilinear(video, uv->x(), uv->y());
      if (SegmentIsClear(*mesh, cam1->world_from_camera.translation, g, 0.25)) {
        // (a) seen by camera 1: the snapshot shows camera 1's video there.
        ++visible_checked;
        if (out.MaxAbsDiff(seen) <= 24) ++visible_match;
      } else {
        // (b) hidden from camera 1 behind a building: the model keeps its own colour.
        ++hidden_checked;
        if (out.MaxAbsDiff(own) <= 6) ++hidden_kept;
        if (seen.MaxAbsDiff(own) > 30) ++hidden_discriminative;
      }
    }
  }
  std::cerr << "ground samples seen by cam1: " << visible_match << " of " << visible_checked
            << " match its video; hidden from cam1: " << hidden_kept << " of " << hidden_checked << " keep the model colour ("
            << hidden_discriminative << " where cam1's video differs)\n";
  ASSERT_GE(visible_checked, 100) << "too few ground points seen by cam1 to judge";
  ASSERT_GE(hidden_checked, 30) << "too few ground points hidden from cam1 to judge";
  ASSERT_GE(hidden_discriminative, 15) << "cam1's video behind the occluders looks like the model; the test can't tell";
  EXPECT_GE(visible_match, visible_checked * 90 / 100);
  EXPECT_GE(hidden_kept, hidden_checked * 95 / 100);

  // (c) Stopping one agent leaves the others flowing.
  stops_[2] = true;
  agents_[2].join();
  agents_[2] = std::thread([] {});
  auto seq = [&](const std::string& id) {
    for (const auto& c : client.Snapshot())
      if (c.id == id) return c.frame_sequence;
    return uint64_t{0};
  };
  // cam3's last frame as the server finally holds it. The agent cancels its stream when stopped, so
  // a frame it sent may still be in the server's handler after the agent's thread has joined: wait
  // (on the state's change counter) until the server has closed cam3's stream, which happens after
  // its last AcceptFrame. Then the viewer must end on exactly that frame.
  const auto closed_by = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  for (;;) {
    const uint64_t version = server_->state().version();
    if (server_->state().OpenStreams("cam3") == 0) break;
    ASSERT_LT(std::chrono::steady_clock::now(), closed_by) << "the server never closed cam3's stream";
    server_->state().WaitForChange(version, std::chrono::milliseconds(500));
  }
  ASSERT_NE(server_->state().LatestFrame("cam3"), nullptr);
  const uint64_t s3 = server_->state().LatestFrame("cam3")->sequence();
  const uint64_t s1 = seq("cam1"), s2 = seq("cam2");
  EXPECT_TRUE(client.WaitUntil(
      [&](const std::vector<CameraView>&) { return seq("cam1") >= s1 + 3 && seq("cam2") >= s2 + 3; },
      std::chrono::seconds(20)));
  EXPECT_EQ(seq("cam3"), s3);
  EXPECT_TRUE(client.WaitUntil(
      [&](const std::vector<CameraView>& cs) {
        for (const auto& c : cs)
          if (c.id == "cam3") return c.status != viewer::CameraLiveness::kLive;
        return false;
      },
      std::chrono::seconds(20)));
  client.Stop();
}

// Agents survive a server restart: the stream breaks, the agent backs off, reconnects to the new
// server on the same port (which reloads the camera from the store) and frames flow again.
TEST(AgentReconnect, SurvivesServerRestart) {
  fixtures::LocalServer server("ave_reconnect");
  ServerOptions options = server.Options(kSensor, "", kAdmin);
  options.campus_grid_m = 8;
  const absl::Status first = server.Start(options);
  ASSERT_TRUE(first.ok()) << first;
  const std::string address = server.address();
  const scene::SyntheticCampus campus = scene::BuiltinCampus();
  ASSERT_TRUE(AdminClient(server.InsecureChannel(), kAdmin).AddCamera(CampusCameraRecord(campus.cameras[1])).ok());

  AgentOptions a;
  a.server = address;
  a.camera_id = campus.cameras[1].id;
  a.token = kSensor;
  a.fps = 10;
  a.backoff_initial = std::chrono::milliseconds(50);
  a.backoff_max = std::chrono::milliseconds(400);
  auto source = OpenSource("sim:campus#" + a.camera_id, {.fps = a.fps});
  ASSERT_TRUE(source.ok());
  AgentStreamer streamer(a, std::move(*source));
  std::atomic<bool> stop{false};
  std::thread agent([&] { EXPECT_TRUE(streamer.Run(stop).ok()); });

  auto wait_for = [](const std::function<bool()>& done, int seconds) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(seconds);
    while (!done() && std::chrono::steady_clock::now() < deadline) std::this_thread::sleep_for(std::chrono::milliseconds(20));
    return done();
  };
  ASSERT_TRUE(wait_for([&] { return server->state().LatestFrame(a.camera_id) != nullptr; }, 20));
  server->Shutdown(std::chrono::milliseconds(0));
  server.Stop();
  const int64_t sent_before = streamer.stats().frames_sent;

  options.listen_address = address;  // same port
  const absl::Status second = server.Start(options);
  ASSERT_TRUE(second.ok()) << second;
  EXPECT_TRUE(wait_for([&] { return server->state().LatestFrame(a.camera_id) != nullptr; }, 20));
  stop = true;
  agent.join();
  const AgentStats stats = streamer.stats();
  EXPECT_GE(stats.connects, 2);
  EXPECT_GT(stats.frames_sent, sent_before);
}

}  // namespace
}  // namespace ave
