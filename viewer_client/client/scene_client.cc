#include "model_store/avatar/avatar_blob.h"
#include "viewer_client/client/scene_client.h"

#include <algorithm>
#include <limits>
#include <optional>
#include <utility>

#include <grpcpp/grpcpp.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "absl/strings/str_cat.h"
#include "ave/v1/ave.grpc.pb.h"
#include "fusion_server/core/convert.h"
#include "fusion_server/core/view_select.h"
#include "model_store/common/log.h"

namespace ave::viewer {
namespace {

CameraLiveness FromProto(v1::CameraStatus s) {
  switch (s) {
    case v1::CAMERA_STATUS_LIVE: return CameraLiveness::kLive;
    case v1::CAMERA_STATUS_STALE: return CameraLiveness::kStale;
    case v1::CAMERA_STATUS_LOST: return CameraLiveness::kLost;
    default: return CameraLiveness::kUnknown;
  }
}

// The views' corners (each frustum clamped at depth_m), for comparing view sets.
std::vector<std::vector<Eigen::Vector3d>> Corners(const SelectionViews& views, double depth_m) {
  std::vector<std::vector<Eigen::Vector3d>> out;
  for (const Eigen::Matrix4d& m : views.clip_from_local) {
    absl::StatusOr<ConvexVolume> v = FrustumFromClip(m, depth_m, -std::numeric_limits<double>::infinity());
    out.push_back(v.ok() ? v->vertices : std::vector<Eigen::Vector3d>{});
  }
  return out;
}

constexpr int kTimelineFrames = 64;  // frame times kept per camera for the time line

}  // namespace

bool ViewsDifferALot(const SelectionViews& a, const SelectionViews& b, double fraction, double depth_m) {
  if (a.clip_from_local.size() != b.clip_from_local.size()) return true;
  const auto ca = Corners(a, depth_m), cb = Corners(b, depth_m);
  for (size_t i = 0; i < ca.size(); ++i) {
    if (ca[i].size() != cb[i].size() || ca[i].empty()) return ca[i].size() != cb[i].size();
    double size = 0, moved = 0;
    for (size_t k = 0; k < ca[i].size(); ++k) {
      size = std::max(size, (ca[i][k] - ca[i][0]).norm());
      moved = std::max(moved, (ca[i][k] - cb[i][k]).norm());
    }
    if (moved > fraction * size) return true;
  }
  return false;
}

int JpegReduction(int frame_width, int frame_height, int need_width, int need_height) {
  if (need_width <= 0 || need_height <= 0 || frame_width <= 0 || frame_height <= 0) return 1;
  int reduction = 1;
  while (reduction < 8 && frame_width / (2 * reduction) >= need_width && frame_height / (2 * reduction) >= need_height) {
    reduction *= 2;
  }
  return reduction;
}

SceneClient::SceneClient(std::shared_ptr<grpc::Channel> channel, std::string viewer_token, std::string viewer_id)
    : channel_(std::move(channel)), token_(std::move(viewer_token)), viewer_id_(std::move(viewer_id)) {}

SceneClient::~SceneClient() { Stop(); }

absl::StatusOr<avatar::AvatarSequence> SceneClient::FetchAvatarSequence(const std::string& name, uint64_t* version) {
  auto stub = v1::SceneService::NewStub(channel_);
  grpc::ClientContext context;
  context.AddMetadata("authorization", "Bearer " + token_);
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
  v1::AvatarSequenceRequest request;
  request.set_name(name);
  auto reader = stub->GetAvatarSequence(&context, request);
  const std::string what = "avatar sequence '" + name + "'";
  std::string blob;
  v1::AvatarSequenceChunk chunk;
  uint32_t expected = 0, count = 0;
  while (reader->Read(&chunk)) {
    if (chunk.chunk_index() != expected) {
      return absl::DataLossError(absl::StrCat(what, ": chunk ", chunk.chunk_index(), " arrived, expected ", expected));
    }
    if (blob.size() + chunk.data().size() > chunk.total_bytes()) {
      return absl::DataLossError(absl::StrCat(what, ": more bytes than total_bytes ", chunk.total_bytes()));
    }
    blob += chunk.data();
    count = chunk.chunk_count();
    if (version) *version = chunk.version();
    ++expected;
  }
  const grpc::Status status = reader->Finish();
  if (!status.ok()) return absl::Status(static_cast<absl::StatusCode>(status.error_code()), what + ": " + status.error_message());
  if (expected == 0 || expected != count) {
    return absl::DataLossError(absl::StrCat(what, ": ", expected, " of ", count, " chunks arrived"));
  }
  return avatar::DecodeAvatarSequence(blob, what);
}

absl::StatusOr<TriangleMesh> SceneClient::FetchStaticModel(uint64_t* version) {
  auto stub = v1::SceneService::NewStub(channel_);
  grpc::ClientContext context;
  context.AddMetadata("authorization", "Bearer " + token_);
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
  auto reader = stub->GetStaticModel(&context, v1::StaticModelRequest());
  TriangleMesh mesh;
  v1::StaticModelChunk chunk;
  uint32_t expected = 0, count = 0;
  while (reader->Read(&chunk)) {
    if (chunk.chunk_index() != expected) {
      return absl::DataLossError(absl::StrCat("static model: chunk ", chunk.chunk_index(), " arrived, expected ", expected));
    }
    const size_t n = chunk.positions_size() / 3;
    if (chunk.positions_size() % 3 || chunk.normals_size() != chunk.positions_size() ||
        chunk.colors_size() != chunk.positions_size() || chunk.indices_size() % 3) {
      return absl::DataLossError(absl::StrCat("static model: chunk ", expected, " has inconsistent array sizes"));
    }
    const uint32_t base = static_cast<uint32_t>(mesh.positions.size());
    for (size_t v = 0; v < n; ++v) {
      mesh.positions.emplace_back(chunk.positions(3 * v), chunk.positions(3 * v + 1), chunk.positions(3 * v + 2));
      mesh.normals.emplace_back(chunk.normals(3 * v), chunk.normals(3 * v + 1), chunk.normals(3 * v + 2));
      mesh.colors.emplace_back(chunk.colors(3 * v), chunk.colors(3 * v + 1), chunk.colors(3 * v + 2));
    }
    for (uint32_t i : chunk.indices()) {
      if (i >= n) return absl::DataLossError(absl::StrCat("static model: chunk ", expected, " index ", i, " out of range"));
      mesh.indices.push_back(base + i);
    }
    mesh.origin = {chunk.origin().x(), chunk.origin().y(), chunk.origin().z()};
    {
      std::lock_guard lock(mu_);
      model_origin_ = mesh.origin;
    }
    if (version) *version = chunk.version();
    count = chunk.chunk_count();
    ++expected;
  }
  const grpc::Status status = reader->Finish();
  if (!status.ok()) {
    return absl::Status(static_cast<absl::StatusCode>(status.error_code()),
                        "static model: " + status.error_message());
  }
  if (expected != count) return absl::DataLossError(absl::StrCat("static model: ", expected, " of ", count, " chunks"));
  mesh.triangle_material.assign(mesh.TriangleCount(), SurfaceMaterial::kTerrain);
  mesh.triangle_object.assign(mesh.TriangleCount(), -1);
  return mesh;
}

ReplaySeek PlanSeek(int64_t seek_ns, int64_t now_ns, const RecordedSpans& spans, int64_t live_margin_ns) {
  if (seek_ns >= now_ns - live_margin_ns) return {};
  // The earliest recorded instant at or after seek_ns over every camera.
  std::optional<int64_t> start_ns;
  for (const RecordedCameraSpans& camera : spans.cameras) {
    for (const auto& [from_ns, to_ns] : camera.intervals_ns) {
      if (to_ns < seek_ns) continue;
      const int64_t t = std::max(from_ns, seek_ns);
      if (!start_ns || t < *start_ns) start_ns = t;
    }
  }
  if (!start_ns || *start_ns >= now_ns - live_margin_ns) return {};
  return {.live = false, .from_ns = *start_ns, .to_ns = now_ns};
}

absl::StatusOr<RecordedSpans> SceneClient::FetchRecordedSpans(const std::vector<std::string>& camera_ids) {
  auto stub = v1::SceneService::NewStub(channel_);
  grpc::ClientContext context;
  context.AddMetadata("authorization", "Bearer " + token_);
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
  v1::RecordedSpansRequest request;
  for (const std::string& id : camera_ids) request.add_camera_ids(id);
  v1::RecordedSpansResponse response;
  const grpc::Status status = stub->RecordedSpans(&context, request, &response);
  if (!status.ok()) {
    return absl::Status(static_cast<absl::StatusCode>(status.error_code()),
                        "recorded spans: " + status.error_message());
  }
  RecordedSpans out;
  out.server_time_ns = response.server_time_ns();
  for (const v1::RecordedCamera& camera : response.cameras()) {
    RecordedCameraSpans& c = out.cameras.emplace_back();
    c.camera_id = camera.camera_id();
    c.frames = camera.frames();
    for (const v1::RecordedInterval& i : camera.intervals()) c.intervals_ns.emplace_back(i.from_ns(), i.to_ns());
  }
  return out;
}

void SceneClient::Start(const SubscribeOptions& options) {
  Stop();
  stop_ = false;
  replay_ended_ = false;
  replay_time_ns_ = 0;
  reselect_interval_ = options.reselect_interval;
  {
    std::lock_guard lock(mu_);
    include_points_ = options.include_lidar_points;
  }
  thread_ = std::thread([this, options] { Loop(options); });
}

void SceneClient::Stop() {
  stop_ = true;
  {
    std::lock_guard lock(mu_);
    if (context_) static_cast<grpc::ClientContext*>(context_.get())->TryCancel();
  }
  if (thread_.joinable()) thread_.join();
}

std::vector<CameraView> SceneClient::Snapshot() const {
  std::map<std::string, PendingJpeg> pending;
  {
    std::lock_guard lock(mu_);
    pending = pending_;
  }
  std::map<std::string, std::shared_ptr<const DecodedImage>> decoded;
  for (const auto& [id, p] : pending) {  // decode outside the lock
    absl::StatusOr<std::shared_ptr<const DecodedImage>> image = DecodeJpegFrame(*p.bytes, p.reduction);
    ++jpegs_decoded_;
    if (!image.ok()) {
      AVE_LOG(WARNING) << "camera '" << id << "': undecodable JPEG (frame " << p.frame_sequence << "): " << image.status().message();
    }
    decoded[id] = image.ok() ? *std::move(image) : nullptr;
  }
  std::lock_guard lock(mu_);
  for (auto& [id, image] : decoded) {
    auto it = pending_.find(id);
    if (it == pending_.end() || it->second.bytes != pending.at(id).bytes) continue;  // taken, or a newer one came
    pending_.erase(it);
    auto cam = cameras_.find(id);
    if (image == nullptr || cam == cameras_.end()) continue;  // an undecodable frame keeps the previous image
    cam->second.image = std::move(image);
    cam->second.image_serial = next_serial_++;
  }
  std::vector<CameraView> out;
  for (const auto& [id, cam] : cameras_) out.push_back(cam);
  return out;
}

std::vector<ObjectView> SceneClient::Objects() const {
  std::lock_guard lock(mu_);
  return objects_;
}

std::vector<LidarView> SceneClient::Lidars() const {
  std::lock_guard lock(mu_);
  std::vector<LidarView> out;
  for (const auto& [id, lidar] : lidars_) out.push_back(lidar);
  return out;
}

void SceneClient::SetViews(const SelectionViews& views) {
  std::lock_guard lock(mu_);
  wanted_views_ = views;
  if (!context_ || resubscribe_) return;  // not subscribed yet: the next Subscribe takes them
  if (std::chrono::steady_clock::now() - last_subscribe_ < reselect_interval_) return;
  if (!ViewsDifferALot(views, subscribed_views_)) return;
  resubscribe_ = true;
  static_cast<grpc::ClientContext*>(context_.get())->TryCancel();
}

void SceneClient::SetIncludeLidarPoints(bool include) {
  std::lock_guard lock(mu_);
  if (include == include_points_) return;
  include_points_ = include;
  if (!context_ || resubscribe_) return;  // the next Subscribe takes it
  resubscribe_ = true;
  static_cast<grpc::ClientContext*>(context_.get())->TryCancel();
}

SelectionViews SceneClient::subscribed_views() const {
  std::lock_guard lock(mu_);
  return subscribed_views_;
}

Eigen::Vector3d SceneClient::model_origin() const {
  std::lock_guard lock(mu_);
  return model_origin_;
}

std::string SceneClient::last_error() const {
  std::lock_guard lock(mu_);
  return last_error_;
}

bool SceneClient::WaitUntil(const std::function<bool(const std::vector<CameraView>&)>& ready,
                            std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (std::chrono::steady_clock::now() < deadline) {
    if (ready(Snapshot())) return true;
    std::unique_lock lock(mu_);
    changed_.wait_for(lock, std::chrono::milliseconds(50));
  }
  return ready(Snapshot());
}

void SceneClient::UpdateLidarLocked(const v1::LidarState& l, bool with_points) {
  LidarView& v = lidars_[l.sensor_id()];
  const bool new_sweep = l.sweep_sequence() != v.sweep_sequence;
  v.id = l.sensor_id();
  v.name = l.name();
  v.world_from_sensor = ave::FromProto(l.pose());
  v.status = FromProto(l.status());
  v.sweep_capture_time_ns = l.sweep_capture_time_ns();
  v.sweep_sequence = l.sweep_sequence();
  v.tracks.clear();
  for (int i = 0; i < l.tracks_size(); ++i) {
    const v1::FootTrack& t = l.tracks(i);
    v.tracks.push_back({t.track_id(),
                        {t.position().x(), t.position().y(), t.position().z()},
                        {t.velocity_x_mps(), t.velocity_y_mps()},
                        i < l.track_object_ids_size() ? l.track_object_ids(i) : 0});
  }
  // A newer sweep without points had none (the server sends every newer sweep's points to a
  // subscription that asked): the old cloud goes.
  if (!with_points || (!new_sweep && l.foreground().count() == 0)) return;
  absl::StatusOr<LidarPointCloud> cloud =
      DecodeLidarPoints(l.foreground().packed(), l.foreground().count(), v.world_from_sensor, v.tracks);
  if (!cloud.ok()) {
    AVE_LOG(WARNING) << "viewer: lidar '" << v.id << "': " << cloud.status().message();
    return;
  }
  cloud->sweep_sequence = v.sweep_sequence;
  v.points = std::make_shared<const LidarPointCloud>(*std::move(cloud));
  v.points_serial = next_serial_++;
  v.points_received += l.foreground().count() > 0;
}

void SceneClient::Loop(SubscribeOptions options) {
  auto stub = v1::SceneService::NewStub(channel_);
  auto backoff = std::chrono::milliseconds(200);
  while (!stop_.load()) {
    auto context = std::make_shared<grpc::ClientContext>();
    context->AddMetadata("authorization", "Bearer " + token_);
    v1::SubscribeRequest request;
    request.set_viewer_id(viewer_id_);
    for (const auto& id : options.camera_ids) request.add_camera_ids(id);
    request.set_max_rate_hz(options.max_rate_hz);
    request.set_include_jpeg(options.include_jpeg);
    request.set_max_jpeg_width(options.max_jpeg_width);
    {
      std::lock_guard lock(mu_);
      options.include_lidar_points = include_points_;
      request.set_include_lidar_points(include_points_);
      if (!include_points_) {
        for (auto& [id, lidar] : lidars_) {
          if (lidar.points) lidar.points_serial = next_serial_++;
          lidar.points.reset();
        }
      }
      context_ = context;
      resubscribe_ = false;
      subscribed_views_ = wanted_views_;
      last_subscribe_ = std::chrono::steady_clock::now();
      const Eigen::Vector3d origin = subscribed_views_.origin.value_or(model_origin_);
      for (const Eigen::Matrix4d& m : subscribed_views_.clip_from_local) {
        v1::ViewFrustum* f = request.add_views();
        for (int k = 0; k < 16; ++k) f->add_view_projection(static_cast<float>(m(k % 4, k / 4)));
        f->set_origin_x(origin.x());
        f->set_origin_y(origin.y());
        f->set_origin_z(origin.z());
      }
    }
    ++subscriptions_;
    std::unique_ptr<grpc::ClientReader<v1::SceneUpdate>> reader;
    if (options.replay()) {
      // The same request fields, as a replay from where the last one reached (a re-request after
      // a change of views is a seek).
      v1::ReplayRequest replay;
      replay.set_viewer_id(request.viewer_id());
      *replay.mutable_camera_ids() = request.camera_ids();
      replay.set_start_time_ns(std::max(options.replay_from_ns, replay_time_ns_.load()));
      replay.set_end_time_ns(options.replay_to_ns);
      replay.set_rate(options.replay_rate);
      replay.set_include_jpeg(request.include_jpeg());
      *replay.mutable_views() = request.views();
      replay.set_max_rate_hz(request.max_rate_hz());
      reader = stub->Replay(context.get(), replay);
    } else {
      reader = stub->Subscribe(context.get(), request);
    }
    v1::SceneUpdate update;
    bool replay_end = false;
    while (reader->Read(&update)) {
      if (stop_.load()) {
        context->TryCancel();
        break;
      }
      if (update.has_replay()) {
        replay_time_ns_ = update.replay().replay_time_ns();
        replay_end = update.replay().end();
        for (const v1::ReplayGap& gap : update.replay().gaps()) {
          AVE_LOG(WARNING) << "viewer '" << viewer_id_ << "': replay gap in camera '" << gap.camera_id() << "' ("
                           << gap.frames() << " frames): " << gap.reason();
        }
      }
      backoff = std::chrono::milliseconds(200);
      {
        std::lock_guard lock(mu_);
        for (const auto& id : update.removed_camera_ids()) {
          cameras_.erase(id);
          pending_.erase(id);
          lidars_.erase(id);
        }
        for (const v1::LidarState& l : update.lidars()) UpdateLidarLocked(l, options.include_lidar_points);
        for (auto& cam : *update.mutable_cameras()) {
          CameraView& v = cameras_[cam.camera_id()];
          v.id = cam.camera_id();
          v.name = cam.name();
          v.intrinsics = ave::FromProto(cam.intrinsics());
          v.world_from_camera = ave::FromProto(cam.pose());
          v.view = GetMatrix(cam.view_matrix());
          v.projection = GetMatrix(cam.projection_matrix());
          v.near_m = cam.near_m();
          v.far_m = cam.far_m();
          v.status = FromProto(cam.status());
          v.frame_capture_time_ns = cam.frame_capture_time_ns();
          v.frame_sequence = cam.frame_sequence();
          if (!cam.jpeg().empty()) {
            const int reduction = JpegReduction(v.intrinsics.width, v.intrinsics.height, options.decode_width,
                                                options.decode_height);
            ++v.jpegs_received;
            v.jpeg_bytes_received += cam.jpeg().size();
            jpeg_bytes_ += cam.jpeg().size();
            v.recent_frame_times_ns.push_back(update.server_time_ns());
            if (v.recent_frame_times_ns.size() > kTimelineFrames) v.recent_frame_times_ns.erase(v.recent_frame_times_ns.begin());
            pending_[v.id] = {std::make_shared<const std::string>(std::move(*cam.mutable_jpeg())), v.frame_sequence, reduction};
          }
        }
        objects_.clear();
        for (const auto& o : update.objects()) {
          ObjectView ov;
          ov.id = o.object_id();
          ov.position = {o.position().x(), o.position().y(), o.position().z()};
          ov.size = {o.size().x(), o.size().y(), o.size().z()};
          ov.heading_rad = o.heading_rad();
          ov.model = o.model();
          ov.kind = o.kind();
          ov.source_camera_id = o.source_camera_id();
          ov.sensor_ids.assign(o.camera_ids().begin(), o.camera_ids().end());
          for (const auto& p : o.path()) ov.path.emplace_back(p.x(), p.y(), p.z());
          ov.avatar_sequence = o.avatar_sequence();
          ov.avatar_version = o.avatar_sequence_version();
          ov.avatar_phase_cycles = o.avatar_phase_cycles();
          ov.avatar_heading_rad = o.avatar_heading_rad();
          objects_.push_back(std::move(ov));
        }
      }
      ++updates_;
      changed_.notify_all();
    }
    const grpc::Status status = reader->Finish();
    {
      std::lock_guard lock(mu_);
      context_.reset();
      last_error_ = status.error_message();
    }
    if (stop_.load()) break;
    bool reselect = false;
    {
      std::lock_guard lock(mu_);
      reselect = resubscribe_;
    }
    if (reselect) continue;  // cancelled by SetViews: subscribe again at once with the new views
    if (options.replay() && (replay_end || status.error_code() == grpc::StatusCode::NOT_FOUND ||
                             status.error_code() == grpc::StatusCode::INVALID_ARGUMENT ||
                             status.error_code() == grpc::StatusCode::FAILED_PRECONDITION)) {
      if (!status.ok()) AVE_LOG(ERROR) << "viewer '" << viewer_id_ << "': replay refused: " << status.error_message();
      replay_ended_ = true;
      changed_.notify_all();
      break;
    }
    if (status.error_code() == grpc::StatusCode::UNAUTHENTICATED ||
        status.error_code() == grpc::StatusCode::PERMISSION_DENIED) {
      AVE_LOG(ERROR) << "viewer '" << viewer_id_ << "': refused: " << status.error_message();
      replay_ended_ = options.replay();
      break;
    }
    AVE_LOG(WARNING) << "viewer '" << viewer_id_ << "': subscription ended (" << status.error_message()
                     << "); retrying in " << backoff.count() << " ms";
    const auto until = std::chrono::steady_clock::now() + backoff;
    while (!stop_.load() && std::chrono::steady_clock::now() < until) std::this_thread::sleep_for(std::chrono::milliseconds(20));
    backoff = std::min(backoff * 2, std::chrono::milliseconds(5000));
  }
}

}  // namespace ave::viewer
