#include "viewer_client/client/viewer_app.h"

#include <algorithm>
#include <cmath>
#include <thread>

#include <grpcpp/grpcpp.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "ave/net/tls.h"
#include "absl/strings/str_cat.h"
#include "model_store/common/log.h"
#include "model_store/geometry/camera.h"
#include "viewer_client/render/gl_context.h"

namespace ave::viewer {
namespace {

// Distinct frustum colours, cycled by camera index.
const Eigen::Vector3f kPalette[] = {{1.0f, 0.85f, 0.1f}, {0.1f, 0.9f, 1.0f}, {1.0f, 0.3f, 0.8f},
                                    {0.4f, 1.0f, 0.3f},  {1.0f, 0.5f, 0.1f}, {0.6f, 0.5f, 1.0f}};

// Orbit camera for the window: yaw/pitch/distance around a target.
struct Orbit {
  Eigen::Vector3d target;
  double yaw = 0, pitch = 0, distance = 100;

  static Orbit From(const Eigen::Vector3d& eye, const Eigen::Vector3d& target) {
    Orbit o;
    o.target = target;
    const Eigen::Vector3d d = eye - target;
    o.distance = std::max(1.0, d.norm());
    o.yaw = std::atan2(d.y(), d.x());
    o.pitch = std::asin(std::clamp(d.z() / o.distance, -1.0, 1.0));
    return o;
  }
  Eigen::Vector3d Eye() const {
    return target + distance * Eigen::Vector3d(std::cos(pitch) * std::cos(yaw), std::cos(pitch) * std::sin(yaw),
                                               std::sin(pitch));
  }
};

}  // namespace

std::string ViewerOptions::Check() const {
  if (server.empty()) return "server is empty";
  if (width < 64 || height < 64 || width > 8192 || height > 8192) return "size must be 64..8192 pixels per side";
  if (layout != "quad" && layout != "browse") return "layout must be 'quad' or 'browse'";
  if (locked_cameras.size() > 3) return "at most 3 locked cameras";
  if (headless && snapshot_path.empty()) return "headless needs a snapshot path";
  if (!(timeout_s > 0)) return "timeout must be > 0";
  if (!(max_rate_hz > 0)) return "max rate must be > 0";
  if (!eye.allFinite() || !target.allFinite() || (eye - target).norm() < 1e-6) return "eye and target must differ";
  if (max_frames < 0) return "frames must be >= 0";
  if (!(browse_fov_deg > 5 && browse_fov_deg < 170)) return "browse fov must be in (5, 170) degrees";
  return {};
}

std::vector<Projector> MakeProjectors(const std::vector<CameraView>& cameras) {
  std::vector<Projector> projectors;
  for (size_t i = 0; i < cameras.size() && projectors.size() < size_t(kMaxProjectors); ++i) {
    const CameraView& cam = cameras[i];
    Projector p;
    p.camera_id = cam.id;
    p.view = cam.view;
    p.projection = cam.projection;
    p.near_m = cam.near_m;
    p.far_m = cam.far_m;
    p.position = cam.world_from_camera.translation;
    if (cam.image) {
      p.image_width = cam.image->width;
      p.image_height = cam.image->height;
      p.image_rgba = std::span<const uint8_t>(cam.image->rgba);
      p.image_serial = cam.image_serial;
    }
    p.color = kPalette[i % std::size(kPalette)];
    projectors.push_back(std::move(p));
  }
  return projectors;
}

View BrowseView(const Viewport& viewport, const Eigen::Vector3d& eye, const Eigen::Vector3d& target, double fov_deg) {
  View v;
  v.viewport = viewport;
  v.view = GlViewFromWorld(LookAt(eye, target));
  const PinholeIntrinsics k = PinholeIntrinsics::FromFov(viewport.width, viewport.height, fov_deg);
  v.projection = GlProjection(k, 0.5, 2000);
  return v;
}

std::vector<View> QuadViews(int width, int height, const View& browse, const std::vector<Projector>& projectors,
                            const std::vector<std::string>& locked) {
  const std::array<Viewport, 4> cells = QuadLayout(width, height);
  std::vector<View> views;
  View main = browse;
  main.viewport = cells[0];
  // The browse projection is rebuilt for the cell's aspect.
  const double fov_y = 2 * std::atan(1.0 / browse.projection(1, 1));
  const double fov_x_deg = 2 * std::atan(std::tan(fov_y / 2) * cells[0].width / cells[0].height) * 180 / M_PI;
  main.projection = GlProjection(PinholeIntrinsics::FromFov(cells[0].width, cells[0].height, fov_x_deg), 0.5, 2000);
  views.push_back(main);
  for (int cell = 1; cell < 4; ++cell) {
    const std::string& id = cell - 1 < int(locked.size()) ? locked[cell - 1] : std::string();
    auto it = std::find_if(projectors.begin(), projectors.end(), [&](const Projector& p) { return p.camera_id == id; });
    if (it != projectors.end()) {
      views.push_back(ViewLockedToProjector(*it, cells[cell]));
    } else {
      View top = main;  // no camera for this cell: a plan view of the site
      top.viewport = cells[cell];
      views.push_back(top);
    }
  }
  return views;
}

absl::Status WritePng(const std::string& path, const std::vector<uint8_t>& rgba, int width, int height) {
  if (rgba.size() != size_t(width) * height * 4) return absl::InvalidArgumentError("WritePng: size mismatch");
  const cv::Mat in(height, width, CV_8UC4, const_cast<uint8_t*>(rgba.data()));
  cv::Mat bgr;
  cv::cvtColor(in, bgr, cv::COLOR_RGBA2BGR);
  try {
    if (!cv::imwrite(path, bgr)) return absl::UnavailableError("cannot write " + path);
  } catch (const cv::Exception& e) {
    return absl::UnavailableError("cannot write " + path + ": " + e.what());
  }
  return absl::OkStatus();
}

absl::Status RunViewer(const ViewerOptions& options) {
  if (const std::string why = options.Check(); !why.empty()) return absl::InvalidArgumentError("viewer: " + why);
  std::unique_ptr<GlContext> context;
  WindowContext* window = nullptr;
  if (options.headless) {
    auto c = CreateHeadlessContext(options.width, options.height);
    if (!c.ok()) return c.status();
    context = std::move(*c);
  } else {
    WindowOptions wo;
    wo.title = "AVE — " + options.server;
    wo.width = options.width;
    wo.height = options.height;
    auto c = CreateWindowContext(wo);
    if (!c.ok()) return c.status();
    window = c->get();
    context = std::move(*c);
  }
  if (absl::Status s = context->MakeCurrent(); !s.ok()) return s;
  AVE_LOG(INFO) << "viewer: " << context->Description();
  auto renderer = Renderer::Create();
  if (!renderer.ok()) return renderer.status();

  absl::StatusOr<std::shared_ptr<grpc::Channel>> made = net::MakeChannel(
      options.server, {.ca_file = options.tls_ca, .cert_file = options.tls_cert, .key_file = options.tls_key,
                       .server_name = options.tls_server_name});
  if (!made.ok()) return absl::InvalidArgumentError("viewer: " + std::string(made.status().message()));
  std::shared_ptr<grpc::Channel> channel = *made;
  SceneClient client(channel, options.token, options.viewer_id);
  uint64_t model_version = 0;
  absl::StatusOr<TriangleMesh> mesh = client.FetchStaticModel(&model_version);
  if (!mesh.ok()) return mesh.status();
  AVE_LOG(INFO) << "viewer: static model version " << model_version << ", " << mesh->TriangleCount() << " triangles";
  if (absl::Status s = (*renderer)->SetStaticMesh(*mesh); !s.ok()) return s;
  client.Start({.camera_ids = options.camera_filter, .max_rate_hz = options.max_rate_hz, .include_jpeg = true});

  auto locked_for = [&](const std::vector<CameraView>& cams) {
    std::vector<std::string> ids = options.locked_cameras;
    for (const auto& c : cams) {
      if (ids.size() >= 3) break;
      if (options.locked_cameras.empty()) ids.push_back(c.id);
    }
    return ids;
  };
  Orbit orbit = Orbit::From(options.eye, options.target);
  bool frustums = options.draw_frustums;
  std::string highlight;

  auto render_once = [&](const std::vector<CameraView>& cams) -> absl::Status {
    const std::vector<Projector> projectors = MakeProjectors(cams);
    if (absl::Status s = (*renderer)->SetProjectors(projectors); !s.ok()) return s;
    const int w = context->framebuffer_width(), h = context->framebuffer_height();
    View browse = BrowseView({0, 0, w, h}, orbit.Eye(), orbit.target, options.browse_fov_deg);
    browse.draw_frustums = frustums;
    browse.highlight_camera_id = highlight;
    std::vector<View> views =
        options.layout == "quad" ? QuadViews(w, h, browse, projectors, locked_for(cams)) : std::vector<View>{browse};
    context->BindFramebuffer();
    return (*renderer)->Render(views, w, h);
  };
  auto snapshot = [&]() -> absl::Status {
    auto pixels = context->ReadPixels();
    if (!pixels.ok()) return pixels.status();
    if (absl::Status s = WritePng(options.snapshot_path, *pixels, context->framebuffer_width(),
                                  context->framebuffer_height());
        !s.ok()) {
      return s;
    }
    AVE_LOG(INFO) << "viewer: wrote " << options.snapshot_path;
    return absl::OkStatus();
  };

  absl::Status result = absl::OkStatus();
  if (options.headless) {
    // By default: every subscribed camera, or three, whichever is fewer (at least one).
    auto wanted = [&](const std::vector<CameraView>& cams) {
      return options.wait_cameras > 0 ? options.wait_cameras : std::max(1, std::min<int>(3, cams.size()));
    };
    auto with_frames = [](const std::vector<CameraView>& cams) {
      return static_cast<int>(std::count_if(cams.begin(), cams.end(), [](const CameraView& c) { return c.image != nullptr; }));
    };
    const bool ready = client.WaitUntil([&](const std::vector<CameraView>& cams) { return with_frames(cams) >= wanted(cams); },
                                        std::chrono::milliseconds(static_cast<int64_t>(options.timeout_s * 1000)));
    const std::vector<CameraView> cams = client.Snapshot();
    const int want = wanted(cams);
    if (!ready) {
      std::string missing;
      for (const auto& c : cams)
        if (!c.image) missing += " " + c.id;
      result = absl::DeadlineExceededError(absl::StrCat("viewer: only ", with_frames(cams), " of ", want,
                                                        " cameras delivered a frame within ", options.timeout_s,
                                                        " s (no frame from:", missing.empty() ? " -" : missing, ")"));
    }
    if (absl::Status s = render_once(cams); !s.ok()) return s;
    if (absl::Status s = snapshot(); !s.ok()) return s;
  } else {
    int frames = 0;
    while (!window->ShouldClose() && (options.max_frames == 0 || frames < options.max_frames)) {
      ++frames;
      window->PollEvents();
      const WindowInput in = window->TakeInput();
      orbit.yaw -= 0.005 * in.left_drag_px.x();
      orbit.pitch = std::clamp(orbit.pitch + 0.005 * in.left_drag_px.y(), 0.05, 1.55);
      orbit.distance = std::clamp(orbit.distance * std::pow(0.9, in.scroll), 5.0, 2000.0);
      const double step = (in.fast ? 4.0 : 1.0) * 0.01 * orbit.distance;
      const Eigen::Vector3d fwd(-std::cos(orbit.yaw), -std::sin(orbit.yaw), 0), side(-fwd.y(), fwd.x(), 0);
      orbit.target += step * ((in.forward - in.back) * fwd + (in.left - in.right) * side +
                              (in.up - in.down) * Eigen::Vector3d::UnitZ());
      if (in.escape_pressed) window->RequestClose();
      const std::vector<CameraView> cams = client.Snapshot();
      for (char c : in.typed) {
        if (c == 'f') frustums = !frustums;
        if (c >= '1' && c <= '9' && size_t(c - '1') < cams.size()) highlight = cams[c - '1'].id;
        if (c == '0') highlight.clear();
      }
      if (absl::Status s = render_once(cams); !s.ok()) return s;
      bool save = false;
      for (char c : in.typed) save |= c == 'p';
      if (save && !options.snapshot_path.empty()) (void)snapshot();
      window->SwapBuffers();
    }
    if (!options.snapshot_path.empty()) {
      if (absl::Status s = render_once(client.Snapshot()); s.ok()) (void)snapshot();
    }
  }
  client.Stop();
  return result;
}

}  // namespace ave::viewer
