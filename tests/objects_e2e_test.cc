// The moving-object path end to end on loopback (issues 6 and 8): a real FusionServer with the
// campus static model, a real AgentStreamer sending simulated frames of campus camera cam1 with the
// agent's own detection and validated tracking on (sensor_agent/detect, not the simulator's truth),
// and a raw SceneService Subscribe that must receive SceneUpdate.objects: an object with a stable
// id, placed within a stated distance of the simulator's truth (MoverAt), whose path grows.
#include <algorithm>
#include <atomic>
#include <filesystem>
#include <map>
#include <mutex>
#include <thread>

#include <gtest/gtest.h>
#include <grpcpp/grpcpp.h>
#include <unistd.h>

#include "fusion_server/admin/admin_client.h"
#include "fusion_server/service/server.h"
#include "fusion_server/service/test_fixtures.h"
#include "model_store/scene/campus.h"
#include "sensor_agent/detect/detector.h"
#include "sensor_agent/stream/agent_streamer.h"

namespace ave {
namespace {

constexpr char kSensor[] = "s3nsor";
constexpr char kViewer[] = "v1ewer";
constexpr char kAdmin[] = "adm1n";

// Capture stamp (sensor clock = this machine's wall clock) -> simulated scene time, per frame.
class SceneClock {
 public:
  void Add(int64_t capture_ns, double scene_s) {
    std::lock_guard lock(mu_);
    frames_[capture_ns] = scene_s;
  }
  // The scene time of the frame captured nearest to t_ns (none yet: nullopt).
  std::optional<double> At(int64_t t_ns) const {
    std::lock_guard lock(mu_);
    if (frames_.empty()) return std::nullopt;
    auto after = frames_.lower_bound(t_ns);
    if (after == frames_.end()) return std::prev(after)->second;
    if (after == frames_.begin()) return after->second;
    auto before = std::prev(after);
    return t_ns - before->first < after->first - t_ns ? before->second : after->second;
  }
  // The scene time of the newest frame captured so far (0 before the first).
  double Latest() const {
    std::lock_guard lock(mu_);
    return frames_.empty() ? 0 : frames_.rbegin()->second;
  }

 private:
  mutable std::mutex mu_;
  std::map<int64_t, double> frames_;
};

// A FrameSource that notes each frame's capture stamp and scene time on the way through.
class RecordingSource : public FrameSource {
 public:
  RecordingSource(std::unique_ptr<FrameSource> inner, SceneClock& clock) : inner_(std::move(inner)), clock_(clock) {}
  absl::StatusOr<CapturedFrame> Next() override {
    absl::StatusOr<CapturedFrame> frame = inner_->Next();
    if (frame.ok()) clock_.Add(frame->capture_time_ns, frame->scene_time_s);
    return frame;
  }
  PinholeIntrinsics intrinsics() const override { return inner_->intrinsics(); }
  std::string description() const override { return inner_->description(); }
  bool live() const override { return inner_->live(); }

 private:
  std::unique_ptr<FrameSource> inner_;
  SceneClock& clock_;
};

// One received object position, with the truth nearest to it at the same scene time.
struct Sample {
  double scene_s = 0;
  size_t path = 0;
  uint32_t nearest_mover = 0;
  double error_m = 0;  // ground-plane distance to that mover's MoverAt position
};

TEST(ObjectsEndToEnd, DetectedWalkerArrivesAsAStablePlacedObjectWithAGrowingPath) {
  const scene::SyntheticCampus campus = scene::BuiltinCampus();
  const scene::CameraSpec& cam = *campus.FindCamera("cam1");
  fixtures::LocalServer server("ave_objects_e2e");
  const absl::Status started = server.Start(server.Options(kSensor, kViewer, kAdmin));
  ASSERT_TRUE(started.ok()) << started;
  const std::string address = server.address();
  auto channel = server.InsecureChannel();
  ASSERT_TRUE(AdminClient(channel, kAdmin).AddCamera(CampusCameraRecord(cam)).ok());

  SceneClock scene_clock;
  std::atomic<bool> stop{false};
  std::thread agent([&] {
    AgentOptions a;
    a.server = address;
    a.camera_id = cam.id;
    a.token = kSensor;
    a.fps = 10;
    auto source = OpenSource("sim:campus#" + cam.id, {.fps = a.fps});
    ASSERT_TRUE(source.ok()) << source.status();
    auto detector = std::make_shared<detect::Detector>();
    a.detector = [detector](const CapturedFrame& frame) {
      std::vector<FrameBox> boxes;
      const auto detections = detector->Process(frame.bgr.data(), frame.width, frame.height, frame.scene_time_s);
      for (const detect::Detection& d : detections) boxes.push_back({d.track_id, d.corners, d.score});
      return boxes;
    };
    AgentStreamer streamer(a, std::make_unique<RecordingSource>(std::move(*source), scene_clock));
    EXPECT_TRUE(streamer.Run(stop).ok());
  });

  // The viewer: poses and objects only, 10 updates a second.
  auto stub = v1::SceneService::NewStub(channel);
  grpc::ClientContext context;
  context.AddMetadata("authorization", std::string("Bearer ") + kViewer);
  // The test's budget is scene time (kGiveUpSceneS below): on a loaded machine the agent renders and
  // detects slower than 10 frames a second, and a wall-clock budget failed there (issue 14). The
  // deadline only guards against a hang.
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(240));
  v1::SubscribeRequest request;
  request.set_viewer_id("objects-e2e");
  request.set_max_rate_hz(10);
  request.set_include_jpeg(false);
  auto reader = stub->Subscribe(&context, request);

  // Every object sighting, by id: scene time, path length, nearest truth.
  std::map<uint64_t, std::vector<Sample>> seen;
  constexpr double kWantSpanS = 3.0;  // one id followed this long (scene time) is enough
  constexpr double kGiveUpSceneS = 20;  // walkers are in view from the start; 3 s of following fits many times
  auto followed_long_enough = [&] {
    return std::any_of(seen.begin(), seen.end(), [&](const auto& s) {
      return s.second.size() >= 10 && s.second.back().scene_s - s.second.front().scene_s >= kWantSpanS;
    });
  };
  v1::SceneUpdate update;
  while (!followed_long_enough() && scene_clock.Latest() < kGiveUpSceneS && reader->Read(&update)) {
    for (const v1::DynamicObject& o : update.objects()) {
      const std::optional<double> t = scene_clock.At(o.last_seen_ns());
      if (!t) continue;
      Sample s{*t, static_cast<size_t>(o.path_size()), 0, 1e9};
      for (const scene::Mover& m : campus.movers) {
        const Eigen::Vector3d truth = scene::MoverAt(campus, m, *t).position_m;
        const double d = std::hypot(o.position().x() - truth.x(), o.position().y() - truth.y());
        if (d < s.error_m) s.error_m = d, s.nearest_mover = m.id;
      }
      std::vector<Sample>& samples = seen[o.object_id()];
      if (samples.empty() || samples.back().scene_s < s.scene_s) samples.push_back(s);
    }
  }
  context.TryCancel();
  reader->Finish();
  stop = true;
  agent.join();
  server.Stop();

  ASSERT_FALSE(seen.empty()) << "the viewer received no objects";
  // The longest-followed object.
  const auto& [id, samples] = *std::max_element(seen.begin(), seen.end(), [](const auto& a, const auto& b) {
    return a.second.back().scene_s - a.second.front().scene_s < b.second.back().scene_s - b.second.front().scene_s;
  });
  std::vector<double> errors;
  for (const Sample& s : samples) errors.push_back(s.error_m);
  std::sort(errors.begin(), errors.end());
  std::cerr << "objects seen: " << seen.size() << "; object " << id << " followed " << samples.front().scene_s
            << " .. " << samples.back().scene_s << " s of scene time in " << samples.size()
            << " updates, path " << samples.front().path << " -> " << samples.back().path
            << " points, error to truth median " << errors[errors.size() / 2] << " m, max " << errors.back() << " m\n";
  // A stable id: one object followed for kWantSpanS of scene time, all the while the same walker.
  EXPECT_GE(samples.back().scene_s - samples.front().scene_s, kWantSpanS);
  for (const Sample& s : samples) {
    EXPECT_EQ(s.nearest_mover, samples.front().nearest_mover) << "at " << s.scene_s << " s";
  }
  // Placed near the truth: the median within 0.5 m (issue 6's figure for pedestrians within 60 m),
  // every sighting within 1.5 m (the fused object lags a walker slightly). Seen: 0.25 / 0.61 m.
  EXPECT_LE(errors[errors.size() / 2], 0.5);
  EXPECT_LE(errors.back(), 1.5);
  // The path grows as the walker walks (a point every 0.25 m).
  EXPECT_GE(samples.back().path, samples.front().path + 4);
}

}  // namespace
}  // namespace ave
