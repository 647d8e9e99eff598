#pragma once
// Test-only: a real FusionServer on loopback with many cameras spread over the campus, for data
// selection (issue 7 item 5): the end-to-end test (select_test.cc) and `ave-bench select`.
#include <atomic>
#include <cmath>
#include <filesystem>
#include <memory>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include <grpcpp/grpcpp.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "absl/status/statusor.h"
#include "absl/strings/str_cat.h"
#include "ave/v1/ave.grpc.pb.h"
#include "fusion_server/admin/admin_client.h"
#include "fusion_server/core/convert.h"
#include "fusion_server/service/server.h"
#include "fusion_server/service/test_fixtures.h"
#include "model_store/geometry/bvh.h"
#include "model_store/geometry/camera.h"
#include "model_store/scene/campus.h"
#include "viewer_client/client/viewer_app.h"

namespace ave::select_site {

inline constexpr char kSensor[] = "sel-sensor";
inline constexpr char kViewer[] = "sel-viewer";
inline constexpr char kAdmin[] = "sel-admin";

struct GridCamera {
  std::string id;
  PinholeIntrinsics intrinsics;
  Rigid3d world_from_camera;  // local frame
};

// `count` cameras on a regular grid over the campus (10 per row), each 12 m above the ground
// looking down at a point 8 m ahead, headings turning from camera to camera: the kind of
// pole-mounted cameras that each watch a patch of one block.
inline std::vector<GridCamera> GridCameras(const scene::SyntheticCampus& campus, int count) {
  std::vector<GridCamera> out;
  const int columns = 10, rows = (count + columns - 1) / columns;
  const double span = 0.85 * campus.half_extent_m;
  for (int i = 0; i < count; ++i) {
    const int c = i % columns, r = i / columns;
    const double x = -span + 2 * span * (c + 0.5) / columns;
    const double y = -span + 2 * span * (r + 0.5) / std::max(rows, 1);
    const double heading = 0.7 * i;
    const Eigen::Vector3d eye(x, y, campus.TerrainHeight(x, y) + 12);
    const Eigen::Vector2d ahead = Eigen::Vector2d(x, y) + 8 * Eigen::Vector2d(std::cos(heading), std::sin(heading));
    const Eigen::Vector3d target(ahead.x(), ahead.y(), campus.TerrainHeight(ahead.x(), ahead.y()));
    out.push_back({absl::StrCat("grid", i < 10 ? "0" : "", i), PinholeIntrinsics::FromFov(320, 240, 60),
                   LookAt(eye, target)});
  }
  return out;
}

// The viewer "looking at one block": straight-ish down from `height_m` above (x, y).
inline viewer::View BlockView(const scene::SyntheticCampus& campus, double x, double y, double height_m = 45,
                              int width = 640, int height = 480) {
  const double ground = campus.TerrainHeight(x, y);
  return viewer::BrowseView({0, 0, width, height}, {x, y - 0.35 * height_m, ground + height_m}, {x, y, ground}, 50);
}

// Cameras that see a surface point `view` shows (ray-cast truth on a 32 x 24 pixel grid, within
// `far_m`): a selecting server must send their frames.
inline std::set<std::string> CamerasSeenInView(const MeshBvh& bvh, const std::vector<GridCamera>& cameras,
                                               const viewer::View& view, double far_m) {
  std::set<std::string> seen;
  const Eigen::Matrix4d clip_from_local = view.projection * view.view;
  for (const GridCamera& cam : cameras) {
    for (int gy = 0; gy < 24 && !seen.count(cam.id); ++gy) {
      for (int gx = 0; gx < 32; ++gx) {
        const Eigen::Vector2d uv((gx + 0.5) * cam.intrinsics.width / 32 - 0.5, (gy + 0.5) * cam.intrinsics.height / 24 - 0.5);
        const Eigen::Vector3d ray = cam.world_from_camera.rotation * PixelRay(cam.intrinsics, uv);
        const auto hit = bvh.Raycast(cam.world_from_camera.translation, ray, 0.5, far_m);
        if (!hit) continue;
        const Eigen::Vector4d clip = clip_from_local * (cam.world_from_camera.translation + hit->distance_m * ray).homogeneous();
        if (clip.w() > 0 && (clip.head<3>().cwiseAbs().array() <= clip.w()).all()) {
          seen.insert(cam.id);
          break;
        }
      }
    }
  }
  return seen;
}

inline std::string Jpeg(int width, int height, int seed) {
  cv::Mat image(height, width, CV_8UC3);
  cv::randu(image, cv::Scalar::all(0), cv::Scalar::all(255));  // noise: a realistic (large) JPEG size
  cv::Mat smooth;
  cv::blur(image, smooth, cv::Size(3, 3));
  smooth += cv::Scalar(seed % 64, 0, 0);
  std::vector<uchar> bytes;
  cv::imencode(".jpg", smooth, bytes, {cv::IMWRITE_JPEG_QUALITY, 80});
  return std::string(bytes.begin(), bytes.end());
}

// A FusionServer (campus static model, store in a temporary directory named for `tag`, removed
// with the site) with the grid cameras registered.
class Site {
 public:
  static absl::StatusOr<std::unique_ptr<Site>> Start(const std::string& tag, int cameras) {
    auto site = std::unique_ptr<Site>(new Site(tag));
    if (absl::Status started = site->server_.Start(site->server_.Options(kSensor, kViewer, kAdmin)); !started.ok()) {
      return started;
    }
    site->channel_ = site->server_.InsecureChannel();
    site->cameras_ = GridCameras(site->campus_, cameras);
    AdminClient admin(site->channel_, kAdmin);
    for (const GridCamera& cam : site->cameras_) {
      v1::Camera record;
      record.set_id(cam.id);
      record.set_name(cam.id);
      *record.mutable_intrinsics() = ToProto(cam.intrinsics);
      *record.mutable_mounting_pose() = ToProto(cam.world_from_camera);
      record.set_enabled(true);
      if (auto added = admin.AddCamera(record); !added.ok()) return added.status();
    }
    return site;
  }
  ~Site() { StopStreaming(); }

  // Every camera streams `fps` frames per second (each its own sensor stream and thread) until
  // StopStreaming(); frames carry a noisy JPEG of the camera's size.
  void StartStreaming(double fps) {
    stop_ = false;
    for (size_t i = 0; i < cameras_.size(); ++i) {
      threads_.emplace_back([this, i, fps] {
        const GridCamera& cam = cameras_[i];
        auto stub = v1::SensorService::NewStub(channel_);
        grpc::ClientContext context;
        auto stream = stub->Stream(&context);
        v1::SensorMessage m;
        m.mutable_hello()->set_camera_id(cam.id);
        m.mutable_hello()->set_token(kSensor);
        *m.mutable_hello()->mutable_intrinsics() = ToProto(cam.intrinsics);
        if (!stream->Write(m)) return;
        const std::string jpeg = Jpeg(cam.intrinsics.width, cam.intrinsics.height, int(i));
        auto next = std::chrono::steady_clock::now();
        for (uint64_t seq = 1; !stop_.load(); ++seq) {
          v1::SensorFrame* f = m.mutable_frame();
          f->set_sequence(seq);
          f->set_capture_time_ns(std::chrono::duration_cast<std::chrono::nanoseconds>(
                                     std::chrono::system_clock::now().time_since_epoch()).count());
          *f->mutable_pose() = ToProto(cam.world_from_camera);
          f->set_jpeg(jpeg);
          if (!stream->Write(m)) break;
          v1::SensorAck ack;
          if (!stream->Read(&ack)) break;
          next += std::chrono::microseconds(int64_t(1e6 / fps));
          std::this_thread::sleep_until(next);
        }
        stream->WritesDone();
        (void)stream->Finish();
      });
    }
  }
  void StopStreaming() {
    stop_ = true;
    for (auto& t : threads_) t.join();
    threads_.clear();
  }

  const scene::SyntheticCampus& campus() const { return campus_; }
  const std::vector<GridCamera>& cameras() const { return cameras_; }
  std::shared_ptr<grpc::Channel> channel() const { return channel_; }
  FusionServer& server() { return *server_; }

 private:
  explicit Site(const std::string& tag) : server_(tag) {}
  scene::SyntheticCampus campus_ = scene::BuiltinCampus();
  fixtures::LocalServer server_;
  std::shared_ptr<grpc::Channel> channel_;
  std::vector<GridCamera> cameras_;
  std::atomic<bool> stop_{false};
  std::vector<std::thread> threads_;
};

}  // namespace ave::select_site
