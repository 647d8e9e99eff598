#include "viewer_client/client/viewer_app.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <future>
#include <limits>
#include <map>
#include <set>
#include <thread>
#include <utility>

#include <grpcpp/grpcpp.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "ave/net/tls.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "model_store/common/cpu_clock.h"
#include "model_store/common/log.h"
#include "model_store/geometry/bvh.h"
#include "viewer_client/client/replay_video.h"
#include "model_store/geometry/camera.h"
#include "viewer_client/client/browse_camera.h"
#include "viewer_client/client/overlay.h"
#include "viewer_client/render/gl_context.h"

namespace ave::viewer {
namespace {

// Distinct frustum colours, cycled by camera index.
const Eigen::Vector3f kPalette[] = {{1.0f, 0.85f, 0.1f}, {0.1f, 0.9f, 1.0f}, {1.0f, 0.3f, 0.8f},
                                    {0.4f, 1.0f, 0.3f},  {1.0f, 0.5f, 0.1f}, {0.6f, 0.5f, 1.0f}};


}  // namespace

std::string ViewerOptions::Check() const {
  if (servers.empty()) return "no server given";
  for (const auto& s : servers) {
    if (s.empty()) return "a server address is empty";
    if (absl::Status t = net::CheckClientTransport(s, {.ca_file = tls_ca, .insecure_plaintext = insecure_plaintext});
        !t.ok()) {
      return std::string(t.message());
    }
  }
  if (width < 64 || height < 64 || width > 8192 || height > 8192) return "size must be 64..8192 pixels per side";
  if (layout != "quad" && layout != "browse") return "layout must be 'quad' or 'browse'";
  if (locked_cameras.size() > 3) return "at most 3 locked cameras";
  if (headless && snapshot_path.empty() && record_dir.empty() && depth_path.empty() && video_path.empty()) {
    return "headless needs --snapshot, --record, --depth or --video";
  }
  if (!video_path.empty() && (!headless || replay_to_ns <= replay_from_ns)) {
    return "--video needs --headless and --replay-from / --replay-to";
  }
  if (!video_path.empty() && !(video_fps >= 1 && video_fps <= 120)) return "--video-fps must be 1 .. 120";
  if (!video_path.empty() && !video_path.ends_with(".mkv") && !video_path.ends_with(".avi")) {
    return "--video " + video_path + ": must end in .mkv or .avi (Motion-JPEG)";
  }
  if (!depth_path.empty() && !headless && snapshot_path.empty()) return "--depth needs --headless or --snapshot";
  if (!(timeout_s > 0)) return "timeout must be > 0";
  if (!(max_rate_hz > 0)) return "max rate must be > 0";
  if (!eye.allFinite() || !target.allFinite() || (eye - target).norm() < 1e-6) return "eye and target must differ";
  if (max_frames < 0) return "frames must be >= 0";
  if ((replay_from_ns != 0 || replay_to_ns != 0) && replay_to_ns <= replay_from_ns) {
    return "--replay-to must be after --replay-from";
  }
  if (!(replay_rate >= 0.25f && replay_rate <= 16.0f)) return "--replay-rate must be 0.25 .. 16";
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
    p.distortion = cam.intrinsics.distortion;
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

std::array<std::string, 3> FillLockedViews(std::array<std::string, 3> locked, const std::vector<std::string>& camera_ids) {
  auto next = camera_ids.begin();
  for (std::string& cell : locked) {
    if (!cell.empty()) continue;
    while (next != camera_ids.end() && std::find(locked.begin(), locked.end(), *next) != locked.end()) ++next;
    if (next == camera_ids.end()) break;
    cell = *next++;
  }
  return locked;
}

SelectionViews SelectionOf(const std::vector<View>& views) {
  SelectionViews out;
  for (const View& v : views) out.clip_from_local.push_back(v.projection * v.view);
  return out;
}

PointCloud LidarPointsByTrack(const std::vector<LidarView>& lidars) {
  PointCloud cloud;
  cloud.point_size_px = 3;
  for (const LidarView& lidar : lidars) {
    if (!lidar.points) continue;
    const LidarPointCloud& points = *lidar.points;
    cloud.positions_local_m.insert(cloud.positions_local_m.end(), points.p_local.begin(), points.p_local.end());
    for (size_t k = 0; k < points.p_local.size(); ++k) {
      cloud.colors.push_back(IdColor(k < points.track_id.size() ? points.track_id[k] : 0));
    }
  }
  return cloud;
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


namespace {

// Proto ObjectModel numbers (ave.proto) to the renderer's shapes; people default to billboards.
DynamicModel ToModel(const ObjectView& o) {
  DynamicModel m;
  m.base = o.position;
  m.heading_rad = o.heading_rad;
  // ObjectView.size is width, length, height; the renderer wants length, width, height.
  const Eigen::Vector3d size(o.size.y(), o.size.x(), o.size.z());
  if (size.allFinite() && size.minCoeff() > 0) m.size = size;
  m.shape = o.model == 1 ? ModelShape::kBillboard : o.model == 3 ? ModelShape::kCylinder : ModelShape::kCuboid;
  m.color = o.kind == 2 ? Eigen::Vector3f(0.25f, 0.4f, 0.85f) : Eigen::Vector3f(0.85f, 0.25f, 0.2f);
  return m;
}

bool SameDisplay(const DisplayOptions& a, const DisplayOptions& b) {
  return a.overlap == b.overlap && a.seam_feather == b.seam_feather &&
         a.retention_half_life_s == b.retention_half_life_s && a.tint_by_age == b.tint_by_age && a.sky == b.sky &&
         a.video_on_people == b.video_on_people;
}

// One run of the viewer: the servers' clients, the renderer, the overlay and what the user set.
class Session {
 public:
  Session(const ViewerOptions& options, GlContext& context, Renderer& renderer, Overlay* overlay)
      : options_(options), context_(context), renderer_(renderer), overlay_(overlay),
        browse_(options.eye, options.target) {
    state_.frustums = options.draw_frustums;
    state_.select_data = options.select_data;
    state_.lidar_points = options.lidar_points;
    state_.avatars = options.avatars || options.avatars_only;
    state_.avatars_locked = options.avatars_only;
    state_.selected_camera = options.selected_camera;
    state_.display = renderer.options().display;
    if (options.avatars_only) state_.display.video_on_people = false;
    for (size_t i = 0; i < options.locked_cameras.size() && i < 3; ++i) state_.locked[i] = options.locked_cameras[i];
    auto_lock_ = options.locked_cameras.empty();
    browse_.set_speed(20);
  }

  absl::Status Connect() {
    for (size_t i = 0; i < options_.servers.size(); ++i) {
      absl::StatusOr<std::shared_ptr<grpc::Channel>> made = net::MakeChannel(
          options_.servers[i], {.ca_file = options_.tls_ca, .cert_file = options_.tls_cert,
                                .key_file = options_.tls_key, .server_name = options_.tls_server_name,
                                .insecure_plaintext = options_.insecure_plaintext});
      if (!made.ok()) return absl::InvalidArgumentError("viewer: " + std::string(made.status().message()));
      clients_.push_back(std::make_unique<SceneClient>(*made, options_.token, options_.viewer_id));
    }
    uint64_t model_version = 0;
    absl::StatusOr<TriangleMesh> mesh = clients_[0]->FetchStaticModel(&model_version);
    if (!mesh.ok()) return absl::Status(mesh.status().code(), absl::StrCat(options_.servers[0], ": ", mesh.status().message()));
    AVE_LOG(INFO) << "viewer: static model version " << model_version << ", " << mesh->TriangleCount() << " triangles";
    for (size_t i = 1; i < clients_.size(); ++i) {  // the others' origins, so views travel in their frames
      if (absl::StatusOr<TriangleMesh> other = clients_[i]->FetchStaticModel(); !other.ok()) {
        AVE_LOG(WARNING) << "viewer: " << options_.servers[i] << ": no static model (" << other.status().message()
                         << "); its cameras are shown in the first server's frame";
      }
    }
    if (absl::Status s = renderer_.SetStaticMesh(*mesh); !s.ok()) return s;
    mesh_ = *std::move(mesh);
    // The first subscription already carries the browse view, so a viewer never receives every
    // camera's frames just because it has not drawn yet.
    const int w = context_.framebuffer_width(), h = context_.framebuffer_height();
    const std::vector<View> first = ComputeViews({}, w, h);
    UpdateSelection(first);
    subscribe_ = {.camera_ids = options_.camera_filter, .max_rate_hz = options_.max_rate_hz, .include_jpeg = true,
                  .include_lidar_points = state_.lidar_points,
                  .decode_width = renderer_.options().video_layer_width,
                  .decode_height = renderer_.options().video_layer_height,
                  .replay_from_ns = options_.replay_from_ns, .replay_to_ns = options_.replay_to_ns,
                  .replay_rate = options_.replay_rate};
    for (auto& c : clients_) c->Start(subscribe_);
    replaying_ = subscribe_.replay();
    if (replaying_) state_.replay_status = "replay";
    state_.replay_rate = options_.replay_rate;  // the panel's rate starts at --replay-rate
    return absl::OkStatus();
  }

  void Stop() {
    for (auto& c : clients_) c->Stop();
  }

  // Every server's cameras, merged by id, in the first server's local frame (another server's
  // model may sit at another origin). A camera several servers know comes from the one with the
  // newest frame (the first server on a tie).
  std::vector<CameraView> Cameras() const {
    std::vector<CameraView> out;
    std::map<std::string, size_t> index;
    for (size_t i = 0; i < clients_.size(); ++i) {
      const Eigen::Vector3d origin = clients_[i]->model_origin();
      const Eigen::Vector3d shift = i == 0 || origin.isZero(0) ? Eigen::Vector3d::Zero() : Eigen::Vector3d(origin - mesh_.origin);
      for (CameraView& cam : clients_[i]->Snapshot()) {
        cam.server_index = static_cast<int>(i);
        if (!shift.isZero(0)) {
          cam.world_from_camera.translation += shift;
          cam.view = GlViewFromWorld(cam.world_from_camera);
        }
        auto [it, fresh] = index.try_emplace(cam.id, out.size());
        if (fresh) {
          out.push_back(std::move(cam));
        } else if (cam.image && (!out[it->second].image || cam.frame_capture_time_ns > out[it->second].frame_capture_time_ns)) {
          out[it->second] = std::move(cam);
        }
      }
    }
    std::sort(out.begin(), out.end(), [](const CameraView& a, const CameraView& b) { return a.id < b.id; });
    return out;
  }

  // Every server's rotating LiDARs (issue 16), by id; the first server's on a duplicate id.
  std::vector<LidarView> Lidars() const {
    std::map<std::string, LidarView> out;
    for (size_t i = 0; i < clients_.size(); ++i) {
      for (LidarView& lidar : clients_[i]->Lidars()) {
        lidar.server_index = static_cast<int>(i);
        out.try_emplace(lidar.id, std::move(lidar));
      }
    }
    std::vector<LidarView> list;
    for (auto& [id, lidar] : out) list.push_back(std::move(lidar));
    return list;
  }

  std::vector<View> ComputeViews(const std::vector<CameraView>& cams, int w, int h) {
    // Without --lock the cells take the first cameras by id as they report, until the operator
    // presses a lock button (the cells then differ from what was filled in last).
    if (auto_lock_ && state_.locked != auto_locked_) auto_lock_ = false;
    if (auto_lock_) {
      std::vector<std::string> ids;
      for (const CameraView& c : cams) ids.push_back(c.id);
      state_.locked = auto_locked_ = FillLockedViews(state_.locked, ids);
    }
    if (state_.locked != logged_locked_) {
      logged_locked_ = state_.locked;
      AVE_LOG(INFO) << "viewer: locked views: " << absl::StrJoin(state_.locked, ", ", [](std::string* out, const std::string& id) {
        out->append(id.empty() ? "(plan view)" : id);
      });
    }
    for (const CameraView& c : cams) {
      if (c.image && first_frame_logged_.insert(c.id).second) AVE_LOG(INFO) << "viewer: first frame from camera '" << c.id << "'";
    }
    projectors_ = MakeProjectors(cams);
    View browse = BrowseView({0, 0, w, h}, browse_.eye(), browse_.Target(), options_.browse_fov_deg);
    std::vector<View> views =
        options_.layout == "quad"
            ? QuadViews(w, h, browse, projectors_, std::vector<std::string>(state_.locked.begin(), state_.locked.end()))
            : std::vector<View>{browse};
    for (size_t i = 0; i < views.size(); ++i) {
      View& v = views[i];
      v.draw_frustums = state_.frustums;
      v.draw_paths = state_.paths;
      if (!state_.selected_camera.empty() || i == 0) v.highlight_camera_id = state_.selected_camera;
    }
    return views;
  }

  // Tells every server which views to select cameras by (rate-limited inside SceneClient).
  void UpdateSelection(const std::vector<View>& views) {
    SelectionViews selection;
    if (state_.select_data) selection = SelectionOf(views);
    selection.origin = mesh_.origin;  // every server gets the views in the first server's frame
    for (auto& c : clients_) c->SetViews(selection);
  }

  // Draws one frame into the context's framebuffer; returns the views drawn. `saved`: the frame
  // goes to a PNG, so the overlay is redrawn if its content changed (no 4 Hz lag in pictures).
  // The panel's replay controls (issue 18): the clients re-subscribe as a replay from the time
  // dragged to on the time line (or where a pause left it, or replay_back_s before now), stop where
  // they are, change rate from where they are, or go back to the start-up subscription.
  void ApplyReplay() {
    using Command = OverlayState::ReplayCommand;
    PollRecordedSpans();
    Command command = std::exchange(state_.replay_command, Command::kNone);
    SceneClient& first = *clients_[0];
    const int64_t now_ns = NowNs();
    state_.timeline_now_ns = now_ns;
    if (replaying_ && first.replay_time_ns() > 0) {
      state_.replay_time_ns = first.replay_time_ns();
      // The log says when a panel replay shows its first recorded moment (and how far back it is).
      if (std::exchange(replay_first_logged_, true) == false && panel_replay_) {
        AVE_LOG(INFO) << "viewer: replaying recorded time " << state_.replay_time_ns << " ns ("
                      << absl::StrFormat("%.1f", (now_ns - state_.replay_time_ns) * 1e-9) << " s before now)";
      }
    }
    const char* why = "live button";
    if (command == Command::kNone && replaying_ && !paused_ && panel_replay_ && first.replay_ended() &&
        first.last_error().empty()) {
      command = Command::kLive;  // a panel replay runs to the time it was asked at: it caught up
      why = "replay caught up";
    }
    if (command == Command::kNone) {
      if (replaying_ && !paused_) {
        state_.replay_status = first.replay_ended()
                                   ? (first.last_error().empty() ? std::string("replay ended") : first.last_error())
                                   : absl::StrFormat("%.0f s ago, %gx", (now_ns - first.replay_time_ns()) * 1e-9,
                                                     state_.replay_rate);
      }
      return;
    }
    if (command == Command::kPause) {
      if (!replaying_) return;  // live cannot pause: nothing would say where it stopped
      for (auto& c : clients_) c->Stop();
      paused_ = true;
      state_.replay_status = "paused";
      AVE_LOG(INFO) << "viewer: paused at recorded time " << first.replay_time_ns() << " ns ("
                    << absl::StrFormat("%.1f", (now_ns - first.replay_time_ns()) * 1e-9) << " s before now)";
      return;
    }
    if (command == Command::kRate && (!replaying_ || paused_)) return;  // the next play takes it
    ReplaySeek seek;  // live unless set below
    if (command == Command::kSeek) {
      seek = PlanSeek(state_.replay_seek_ns, now_ns, state_.recorded);
    } else if (command == Command::kPlay || command == Command::kRate) {
      const bool resume = replaying_ && first.replay_time_ns() > 0 && !first.replay_ended();
      seek = {.live = false,
              .from_ns = resume ? first.replay_time_ns() : now_ns - static_cast<int64_t>(state_.replay_back_s * 1e9),
              .to_ns = now_ns};
    }
    SubscribeOptions o = subscribe_;
    replaying_ = !seek.live;
    if (replaying_) {
      o.replay_from_ns = seek.from_ns;
      o.replay_to_ns = seek.to_ns;
      o.replay_rate = state_.replay_rate;
    } else {
      o.replay_from_ns = o.replay_to_ns = 0;  // live even when started with --replay-*
    }
    paused_ = false;
    panel_replay_ = replaying_;
    state_.replay_time_ns = replaying_ ? seek.from_ns : 0;
    for (auto& c : clients_) c->Start(o);
    state_.replay_status = replaying_ ? "seeking" : "live";
    replay_first_logged_ = false;
    if (replaying_) {
      AVE_LOG(INFO) << "viewer: replay from " << seek.from_ns << " ns ("
                    << absl::StrFormat("%.1f", (now_ns - seek.from_ns) * 1e-9) << " s before now) to " << seek.to_ns
                    << " ns at " << state_.replay_rate << "x ("
                    << (command == Command::kSeek ? "time line" : command == Command::kPlay ? "play" : "rate") << ")";
    } else {
      AVE_LOG(INFO) << "viewer: live (" << (command == Command::kSeek ? "time line at now" : why) << ")";
    }
  }

  // Where the Replay section's time line and "live" and "pause" buttons are in the window, logged
  // when they appear or move (whole pixels): what an operator's pointer (or a script driving it) aims at.
  void LogReplayLayout() {
    std::array<int, 12> px{};
    for (int i = 0; i < 4; ++i) {
      px[i] = static_cast<int>(std::lround(state_.timeline_rect_px[i]));
      px[4 + i] = static_cast<int>(std::lround(state_.live_button_rect_px[i]));
      px[8 + i] = static_cast<int>(std::lround(state_.pause_button_rect_px[i]));
    }
    if (px == logged_replay_px_ || px[2] <= 0) return;
    logged_replay_px_ = px;
    AVE_LOG(INFO) << absl::StrFormat(
        "viewer: replay time line at x %d y %d w %d h %d px; live button at x %d y %d w %d h %d px; "
        "pause button at x %d y %d w %d h %d px",
        px[0], px[1], px[2], px[3], px[4], px[5], px[6], px[7], px[8], px[9], px[10], px[11]);
  }

  // The time line's spans, asked of the first server every 2 s off the render thread; a server
  // that does not record is asked no more.
  void PollRecordedSpans() {
    if (spans_future_.valid()) {
      if (spans_future_.wait_for(std::chrono::seconds(0)) != std::future_status::ready) return;
      absl::StatusOr<RecordedSpans> spans = spans_future_.get();
      if (spans.ok()) {
        if (spans->cameras.size() != state_.recorded.cameras.size()) {
          int64_t earliest_ns = 0;
          for (const RecordedCameraSpans& c : spans->cameras) {
            if (!c.intervals_ns.empty() && (earliest_ns == 0 || c.intervals_ns.front().first < earliest_ns)) {
              earliest_ns = c.intervals_ns.front().first;
            }
          }
          AVE_LOG(INFO) << "viewer: the server records " << spans->cameras.size() << " cameras, from " << earliest_ns
                        << " ns";
        }
        state_.recorded = *std::move(spans);
      } else if (spans.status().code() == absl::StatusCode::kFailedPrecondition) {
        spans_off_ = true;
        state_.replay_status = std::string(spans.status().message());
      }
    }
    const auto now = std::chrono::steady_clock::now();
    if (spans_off_ || now < next_spans_) return;
    next_spans_ = now + std::chrono::seconds(2);
    SceneClient* client = clients_[0].get();
    spans_future_ = std::async(std::launch::async, [client] { return client->FetchRecordedSpans(); });
  }

  absl::StatusOr<std::vector<View>> Draw(const WindowInput* input, bool saved = false) {
    ApplyReplay();
    const auto now = std::chrono::steady_clock::now();
    const double dt = std::chrono::duration<double>(now - last_frame_).count();
    last_frame_ = now;
    const std::vector<CameraView> cams = Cameras();
    const int w = context_.framebuffer_width(), h = context_.framebuffer_height();
    std::vector<View> views = ComputeViews(cams, w, h);
    // The renderer keeps its own copies; `cams` holds the images alive across SetProjectors.
    if (absl::Status s = renderer_.SetProjectors(projectors_); !s.ok()) return s;
    // A camera whose last pose had NaNs keeps its last good pose in the renderer: list it as stale.
    std::vector<CameraView> listed = cams;
    for (const std::string& id : renderer_.StaleCameras()) {
      for (CameraView& c : listed)
        if (c.id == id) c.status = CameraLiveness::kStale;
    }
    std::vector<ObjectView> objects;
    std::vector<DynamicModel> models;
    std::vector<AvatarInstance> avatars;
    std::vector<Polyline> paths;
    for (auto& c : clients_) {
      for (ObjectView& o : c->Objects()) {
        if (o.path.size() > 1) paths.push_back({o.path, Eigen::Vector3f(1.0f, 0.5f, 0.15f)});
        absl::StatusOr<bool> avatar = state_.avatars && o.kind == 1 ? LoadAvatar(*c, o) : false;
        if (!avatar.ok()) return avatar.status();
        if (*avatar) {
          avatars.push_back({o.avatar_sequence, o.position, o.avatar_heading_rad, o.avatar_phase_cycles});
        } else if (options_.avatars_only && o.kind == 1) {
          return absl::FailedPreconditionError(
              "--avatars-only: person " + std::to_string(o.id) +
              " has no avatar (the server holds no avatar sequence: ave-admin put-avatar --file F.avseq)");
        } else {
          models.push_back(ToModel(o));
        }
        objects.push_back(std::move(o));
      }
    }
    if (absl::Status s = renderer_.SetDynamicModels(models); !s.ok()) return s;
    if (absl::Status s = renderer_.SetAvatars(avatars); !s.ok()) return s;
    if (absl::Status s = renderer_.SetPaths(paths); !s.ok()) return s;
    const std::vector<LidarView> lidars = Lidars();
    if (absl::Status s = UpdatePoints(lidars); !s.ok()) return s;
    if (!applied_display_ || !SameDisplay(*applied_display_, state_.display)) {
      if (absl::Status s = renderer_.SetDisplayOptions(state_.display); !s.ok()) return s;
      applied_display_ = state_.display;
    }
    context_.BindFramebuffer();
    if (absl::Status s = renderer_.Render(views, w, h); !s.ok()) return s;
    if (overlay_ != nullptr) {
      const OverlayStats stats = Stats(cams, dt);
      int64_t now_ns = 0;
      for (const CameraView& c : cams)
        if (!c.recent_frame_times_ns.empty()) now_ns = std::max(now_ns, c.recent_frame_times_ns.back());
      now_ns = std::max(now_ns, latest_server_ns_);
      latest_server_ns_ = now_ns;
      const int builds = frames_ == 0 ? 2 : 1;  // the first frame twice: auto-sized windows get their size
      for (int b = 0; b < builds; ++b) {
        overlay_->BeginFrame(w, h, input, dt);
        if (state_.panel) overlay_->Panel(listed, stats, now_ns, state_, lidars);
        for (const View& v : views) overlay_->Annotate(v, h, listed, objects, state_);
        if (b + 1 < builds) overlay_->DiscardFrame();
      }
      context_.BindFramebuffer();
      overlay_->EndFrame(saved || ViewsMoved(views));
      LogReplayLayout();
    }
    last_views_ = views;
    UpdateSelection(views);
    ++frames_;
    return views;
  }

  // Window input to the browse camera and the selection (skipped where the panel has the mouse).
  void HandleInput(const WindowInput& in, const std::vector<View>& last_views) {
    const bool panel_mouse = overlay_ != nullptr && overlay_->WantsMouse();
    const int h = context_.framebuffer_height();
    BrowseMotion m;
    m.forward = double(in.forward) - double(in.back);
    m.right = double(in.right) - double(in.left);
    m.up = double(in.up) - double(in.down);
    m.fast = in.fast;
    m.dt_s = 1.0 / 30;
    if (!panel_mouse) {
      m.orbit_px = in.left_drag_px;
      m.look_px = in.right_drag_px;
      m.wheel = in.scroll;
      if (in.left_presses > 0 && !last_views.empty()) {
        for (const View& v : last_views) {
          const Viewport& vp = v.viewport;
          const double y_up = h - in.cursor_px.y();
          if (in.cursor_px.x() < vp.x || in.cursor_px.x() >= vp.x + vp.width || y_up < vp.y || y_up >= vp.y + vp.height) continue;
          const std::string picked = PickCamera(v, h, Cameras(), in.cursor_px);
          if (!picked.empty()) state_.selected_camera = picked;
        }
      }
      if ((in.middle_presses > 0 || in.typed.find('o') != std::string::npos) && !last_views.empty()) PickPivot(last_views[0], in.cursor_px);
    }
    browse_.Apply(m);
    const std::vector<CameraView> cams = Cameras();
    for (char c : in.typed) {
      if (c == 'f') state_.frustums = !state_.frustums;
      if (c == 'l') state_.annotations = !state_.annotations;
      if (c == 'h') state_.panel = !state_.panel;
      if (c == 'r') state_.panel = state_.open_replay = true;  // the panel, its Replay section open
      if (c == 't') state_.display.tint_by_age = !state_.display.tint_by_age;
      if (c == 'k') state_.paths = !state_.paths;
      if (c == 'n') state_.lidar_points = !state_.lidar_points;
      if (c == 'v' && !state_.avatars_locked) state_.avatars = !state_.avatars;
      if (c >= '1' && c <= '9' && size_t(c - '1') < cams.size()) state_.selected_camera = cams[c - '1'].id;
      if (c == '0') state_.selected_camera.clear();
    }
  }

  int frames() const { return frames_; }
  uint64_t jpegs_decoded() const {
    uint64_t n = 0;
    for (const auto& c : clients_) n += c->jpegs_decoded();
    return n;
  }
  SceneClient& client(size_t i) { return *clients_[i]; }

 private:
  // Whether `o`'s avatar can be drawn: its sequence is fetched (once per name and version, from
  // the server that sent the object) and given to the renderer. false: the server assigned none.
  absl::StatusOr<bool> LoadAvatar(SceneClient& client, const ObjectView& o) {
    if (o.avatar_sequence.empty()) return false;
    auto it = avatar_versions_.find(o.avatar_sequence);
    if (it != avatar_versions_.end() && it->second >= o.avatar_version) return true;
    uint64_t version = 0;
    absl::StatusOr<avatar::AvatarSequence> sequence = client.FetchAvatarSequence(o.avatar_sequence, &version);
    if (!sequence.ok()) return sequence.status();
    sequence->name = o.avatar_sequence;
    if (absl::Status s = renderer_.SetAvatarSequence(*sequence); !s.ok()) return s;
    avatar_versions_[o.avatar_sequence] = version;
    AVE_LOG(INFO) << "avatar sequence '" << o.avatar_sequence << "' version " << version << ": "
                  << sequence->frames.size() << " frames";
    return true;
  }
  std::map<std::string, uint64_t> avatar_versions_;  // sequences given to the renderer
  OverlayStats Stats(const std::vector<CameraView>& cams, double dt) {
    OverlayStats s;
    if (dt > 0 && frames_ > 0) fps_ = fps_ == 0 ? 1 / dt : 0.9 * fps_ + 0.1 / dt;  // frame 0's dt is start-up
    s.fps = fps_;
    const auto now = std::chrono::steady_clock::now();
    for (const CameraView& c : cams) {
      auto& [count, when] = last_jpegs_[c.id];
      if (c.jpegs_received != count) {
        count = c.jpegs_received;
        when = now;
      }
      s.cameras_receiving += c.jpegs_received > 0 && now - when < std::chrono::seconds(2);
    }
    uint64_t bytes = 0;
    for (auto& c : clients_) {
      bytes += c->jpeg_bytes_received();
      s.subscriptions += c->subscriptions();
    }
    const double since = std::chrono::duration<double>(now - bytes_at_).count();
    if (since >= 1) {
      bytes_per_s_ = (bytes - bytes_then_) / since;
      bytes_then_ = bytes;
      bytes_at_ = now;
    }
    s.jpeg_bytes_per_s = bytes_per_s_;
    s.servers = static_cast<int>(clients_.size());
    return s;
  }

  // The point layer: the subscriptions ask for points only while it is on; the renderer's cloud is
  // replaced only when a LiDAR's points changed (or the layer was toggled).
  absl::Status UpdatePoints(const std::vector<LidarView>& lidars) {
    for (auto& c : clients_) c->SetIncludeLidarPoints(state_.lidar_points);
    std::vector<std::pair<std::string, uint64_t>> serials;
    if (state_.lidar_points) {
      for (const LidarView& l : lidars)
        if (l.points) serials.emplace_back(l.id, l.points_serial);
    }
    if (points_drawn_ && serials == point_serials_) return absl::OkStatus();
    if (absl::Status s = renderer_.SetPointCloud(state_.lidar_points ? LidarPointsByTrack(lidars) : PointCloud{}); !s.ok()) {
      return s;
    }
    point_serials_ = std::move(serials);
    points_drawn_ = true;
    return absl::OkStatus();
  }

  // Whether a view's pose, projection or viewport differs from the last frame's (labels move).
  bool ViewsMoved(const std::vector<View>& views) const {
    if (views.size() != last_views_.size()) return true;
    for (size_t i = 0; i < views.size(); ++i) {
      const View &a = views[i], &b = last_views_[i];
      if (a.view != b.view || a.projection != b.projection || a.viewport.x != b.viewport.x ||
          a.viewport.y != b.viewport.y || a.viewport.width != b.viewport.width || a.viewport.height != b.viewport.height) {
        return true;
      }
    }
    return false;
  }

  void PickPivot(const View& browse, const Eigen::Vector2d& cursor_px) {
    if (!bvh_) bvh_ = std::make_unique<MeshBvh>(mesh_);
    const auto [origin, dir] = PixelRayOfView(browse, context_.framebuffer_height(), cursor_px);
    if (const auto hit = bvh_->Raycast(origin, dir)) browse_.SetPivot(origin + hit->distance_m * dir);
  }

  const ViewerOptions& options_;
  GlContext& context_;
  Renderer& renderer_;
  Overlay* overlay_;
  BrowseCamera browse_;
  OverlayState state_;
  SubscribeOptions subscribe_;  // the start-up subscription (live, or the --replay-* one)
  bool replaying_ = false, paused_ = false;  // the panel's replay (issue 18)
  bool panel_replay_ = false;  // started from the panel (to the time asked): live once it ends
  bool replay_first_logged_ = false;  // its first recorded moment shown was logged
  std::array<int, 12> logged_replay_px_{};  // the time line, live and pause button rectangles last logged
  bool auto_lock_ = false;                       // set in the constructor: no --lock given
  std::array<std::string, 3> auto_locked_;       // the cells as the automatic lock last left them
  std::array<std::string, 3> logged_locked_;     // the cells as last logged
  std::set<std::string> first_frame_logged_;     // cameras whose first frame was logged
  std::optional<DisplayOptions> applied_display_;
  std::vector<std::unique_ptr<SceneClient>> clients_;
  // The time line's RecordedSpans call in flight (declared after clients_: destroyed first, it
  // waits for the call that uses clients_[0]).
  std::future<absl::StatusOr<RecordedSpans>> spans_future_;
  std::chrono::steady_clock::time_point next_spans_{};
  bool spans_off_ = false;
  std::vector<Projector> projectors_;
  std::vector<View> last_views_;  // the previous frame's, for the overlay cache
  std::vector<std::pair<std::string, uint64_t>> point_serials_;  // the LiDAR clouds in the renderer
  bool points_drawn_ = false;
  TriangleMesh mesh_;
  std::unique_ptr<MeshBvh> bvh_;
  std::chrono::steady_clock::time_point last_frame_ = std::chrono::steady_clock::now();
  std::chrono::steady_clock::time_point bytes_at_ = std::chrono::steady_clock::now();
  uint64_t bytes_then_ = 0;
  double bytes_per_s_ = 0, fps_ = 0;
  int64_t latest_server_ns_ = 0;
  std::map<std::string, std::pair<uint64_t, std::chrono::steady_clock::time_point>> last_jpegs_;
  int frames_ = 0;
};

// Writes the framebuffer to `path` as PNG.
absl::Status SaveFramebuffer(GlContext& context, const std::string& path) {
  auto pixels = context.ReadPixels();
  if (!pixels.ok()) return pixels.status();
  return WritePng(path, *pixels, context.framebuffer_width(), context.framebuffer_height());
}

std::string RecordPath(const std::string& dir, int frame) {
  char name[32];
  std::snprintf(name, sizeof name, "frame_%06d.png", frame);
  return (std::filesystem::path(dir) / name).string();
}

}  // namespace

absl::Status RunViewer(const ViewerOptions& options) {
  if (const std::string why = options.Check(); !why.empty()) return absl::InvalidArgumentError("viewer: " + why);
  if (!options.record_dir.empty()) {
    std::error_code ec;
    std::filesystem::create_directories(options.record_dir, ec);
    if (ec) return absl::UnavailableError("viewer: --record " + options.record_dir + ": " + ec.message());
  }
  // Output files are written at the end: a missing folder is said now, not after the whole run.
  for (const auto& [flag, path] : {std::pair<const char*, const std::string&>{"--snapshot", options.snapshot_path},
                                   {"--depth", options.depth_path}, {"--video", options.video_path}}) {
    const std::filesystem::path parent = std::filesystem::path(path).parent_path();
    if (!path.empty() && !parent.empty() && !std::filesystem::is_directory(parent)) {
      return absl::NotFoundError(absl::StrCat("viewer: ", flag, " ", path, ": no folder ", parent.string()));
    }
  }
  std::unique_ptr<GlContext> context;
  WindowContext* window = nullptr;
  if (options.headless) {
    auto c = CreateHeadlessContext(options.width, options.height);
    if (!c.ok()) return c.status();
    context = std::move(*c);
  } else {
    WindowOptions wo;
    wo.title = "AVE — " + options.servers[0];
    wo.width = options.width;
    wo.height = options.height;
    auto c = CreateWindowContext(wo);
    if (!c.ok()) return c.status();
    window = c->get();
    context = std::move(*c);
  }
  if (absl::Status s = context->MakeCurrent(); !s.ok()) return s;
  AVE_LOG(INFO) << "viewer: " << context->Description();
  RendererOptions renderer_options;
  // A recording keeps every frame at full resolution, also while a view moves.
  if (!options.record_dir.empty()) renderer_options.moving_view_scale = 1;
  auto renderer = Renderer::Create(renderer_options);
  if (!renderer.ok()) return renderer.status();
  std::unique_ptr<Overlay> overlay;
  if (options.panel) {
    // The time line and rates refresh at 4 Hz; input and moving views redraw the overlay at once.
    auto o = Overlay::Create({.content_refresh_hz = 4});
    if (o.ok()) {
      overlay = *std::move(o);
    } else {  // the views still work without the panel
      AVE_LOG(WARNING) << "viewer: no on-screen panel: " << o.status().message();
    }
  }
  Session session(options, *context, **renderer, overlay.get());
  if (absl::Status s = session.Connect(); !s.ok()) return s;

  std::unique_ptr<ReplayVideo> video;
  if (!options.video_path.empty()) {
    auto v = ReplayVideo::Open(options.video_path, context->framebuffer_width(), context->framebuffer_height(),
                               options.video_fps, options.replay_from_ns, options.replay_to_ns);
    if (!v.ok()) return absl::Status(v.status().code(), absl::StrCat("viewer: ", v.status().message()));
    video = *std::move(v);
  }
  int recorded = 0;
  auto after_frame = [&]() -> absl::Status {
    if (video) {
      absl::StatusOr<std::vector<uint8_t>> pixels = context->ReadPixels();
      if (!pixels.ok()) return pixels.status();
      if (absl::Status s = video->Add(*pixels, session.client(0).replay_time_ns()); !s.ok()) return s;
    }
    if (options.record_dir.empty()) return absl::OkStatus();
    return SaveFramebuffer(*context, RecordPath(options.record_dir, recorded++));
  };
  absl::Status result = absl::OkStatus();
  if (options.headless) {
    // Wait for frames, re-sending the views as the cameras (and so the locked views) become known.
    auto with_frames = [](const std::vector<CameraView>& cams) {
      return static_cast<int>(std::count_if(cams.begin(), cams.end(), [](const CameraView& c) { return c.image != nullptr; }));
    };
    auto wanted = [&](const std::vector<CameraView>& cams) {
      return options.wait_cameras > 0 ? options.wait_cameras : std::max(1, std::min<int>(3, cams.size()));
    };
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(int64_t(options.timeout_s * 1000));
    std::vector<CameraView> cams;
    while (true) {
      cams = session.Cameras();
      session.UpdateSelection(session.ComputeViews(cams, context->framebuffer_width(), context->framebuffer_height()));
      if (!cams.empty() && with_frames(cams) >= wanted(cams)) break;
      if (options.replay_to_ns > 0 && session.client(0).replay_ended()) {
        if (!session.client(0).last_error().empty()) {
          return absl::NotFoundError("viewer: replay: " + session.client(0).last_error());
        }
        break;  // a short replay that ended before every camera showed a frame: draw what it left
      }
      if (std::chrono::steady_clock::now() >= deadline) {
        std::string missing;
        for (const auto& c : cams)
          if (!c.image) missing += " " + c.id;
        result = absl::DeadlineExceededError(absl::StrCat("viewer: only ", with_frames(cams), " of ", wanted(cams),
                                                          " cameras delivered a frame within ", options.timeout_s,
                                                          " s (no frame from:", missing.empty() ? " -" : missing, ")"));
        break;
      }
      session.client(0).WaitUntil([](const std::vector<CameraView>&) { return false; }, std::chrono::milliseconds(100));
    }
    // A replay draws until it ends (at most --frames when given); live, --frames frames.
    const bool replay = options.replay_to_ns > 0;
    const int frames = replay ? (options.max_frames > 0 ? options.max_frames : std::numeric_limits<int>::max())
                              : std::max(1, options.max_frames);
    std::vector<View> views;
    double draw_s = 0;  // frames after the first (which compiles shaders and renders every shadow map)
    double cpu_at_second_frame = 0;
    uint64_t decoded_at_second_frame = 0;
    int drawn_count = 0;
    for (int f = 0; f < frames; ++f) {
      ++drawn_count;
      if (f == 1) {
        cpu_at_second_frame = ProcessCpuSeconds();
        decoded_at_second_frame = session.jpegs_decoded();
      }
      const auto frame_start = std::chrono::steady_clock::now();
      const bool last = f + 1 == frames || (replay && session.client(0).replay_ended());
      absl::StatusOr<std::vector<View>> drawn =
          session.Draw(nullptr, last || !options.record_dir.empty() || !options.video_path.empty());
      if (!drawn.ok()) return drawn.status();
      views = *std::move(drawn);
      (void)context->ReadPixels();  // waits for the GPU, so the time is the frame's
      if (f > 0) draw_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - frame_start).count();
      if (absl::Status s = after_frame(); !s.ok()) return s;
      if (last) break;
      if (f + 1 < frames) std::this_thread::sleep_until(frame_start + std::chrono::microseconds(int64_t(1e6 / options.max_rate_hz)));
    }
    if (drawn_count > 1) {
      AVE_LOG(INFO) << "viewer: " << drawn_count - 1 << " frames after the first in " << draw_s << " s ("
                    << 1e3 * draw_s / (drawn_count - 1) << " ms per frame, read-back included; "
                    << 1e3 * (ProcessCpuSeconds() - cpu_at_second_frame) / (drawn_count - 1) << " CPU ms per frame, "
                    << session.jpegs_decoded() - decoded_at_second_frame << " JPEG decodes, "
                    << (overlay ? overlay->redraws() : 0) << " overlay redraws); renderer: "
                    << (*renderer)->stats().shadow_map_renders << " shadow-map renders, "
                    << (*renderer)->stats().dynamic_shadow_updates << " dynamic shadow updates, "
                    << (*renderer)->stats().video_uploads << " video uploads, view cache: "
                    << (*renderer)->stats().view_cache_builds << " builds, " << (*renderer)->stats().view_cache_hits
                    << " hits, " << (*renderer)->stats().view_cache_shadow_tests << " shadow-tested, "
                    << (*renderer)->stats().views_uncached << " uncached views ("
                    << (*renderer)->stats().views_static_from_cache << " with the cached static G-buffer)";
    }
    if (video) {
      absl::StatusOr<int64_t> frames = video->Finish();
      if (!frames.ok()) return frames.status();
      AVE_LOG(INFO) << "viewer: wrote " << options.video_path << " (" << *frames << " frames at " << options.video_fps
                    << " per recorded second)";
    }
    if (!options.snapshot_path.empty()) {
      if (absl::Status s = SaveFramebuffer(*context, options.snapshot_path); !s.ok()) return s;
      AVE_LOG(INFO) << "viewer: wrote " << options.snapshot_path;
    }
    if (!options.depth_path.empty()) {
      absl::StatusOr<std::vector<float>> depth = (*renderer)->ReadLinearDepth(views[0]);
      if (!depth.ok()) return depth.status();
      if (absl::Status s = WriteDepthExr(options.depth_path, *depth, views[0].viewport.width, views[0].viewport.height); !s.ok()) return s;
      AVE_LOG(INFO) << "viewer: wrote " << options.depth_path << " (browse view depth, metres)";
    }
  } else {
    std::vector<View> views;
    while (!window->ShouldClose() && (options.max_frames == 0 || session.frames() < options.max_frames)) {
      window->PollEvents();
      const WindowInput in = window->TakeInput();
      if (in.escape_pressed) window->RequestClose();
      session.HandleInput(in, views);
      absl::StatusOr<std::vector<View>> drawn = session.Draw(&in, !options.record_dir.empty() || in.typed.find('p') != std::string::npos);
      if (!drawn.ok()) return drawn.status();
      views = *std::move(drawn);
      if (absl::Status s = after_frame(); !s.ok()) return s;
      if (in.typed.find('p') != std::string::npos && !options.snapshot_path.empty()) {
        if (SaveFramebuffer(*context, options.snapshot_path).ok()) AVE_LOG(INFO) << "viewer: wrote " << options.snapshot_path;
      }
      window->SwapBuffers();
    }
    if (!options.snapshot_path.empty()) {
      if (session.Draw(nullptr, true).ok()) (void)SaveFramebuffer(*context, options.snapshot_path);
    }
  }
  session.Stop();
  return result;
}

}  // namespace ave::viewer
