#include <algorithm>
#include <cmath>
#include <limits>
#include <thread>

#include <google/protobuf/arena.h>

#include "absl/strings/str_cat.h"
#include "fusion_server/core/validation.h"
#include "fusion_server/service/services.h"
#include "model_store/common/log.h"

namespace ave::internal {

grpc::Status SelectionViews(const google::protobuf::RepeatedPtrField<v1::ViewFrustum>& views,
                            const std::vector<v1::StaticModelChunk>& chunks, double floor_z, ViewerCursor& cursor) {
  if (views.size() > 16) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "views: at most 16 view frusta per subscription");
  }
  const Eigen::Vector3d model_origin =
      chunks.empty() ? Eigen::Vector3d::Zero()
                     : Eigen::Vector3d(chunks[0].origin().x(), chunks[0].origin().y(), chunks[0].origin().z());
  cursor.selection_floor_z = floor_z;
  for (int i = 0; i < views.size(); ++i) {
    const v1::ViewFrustum& f = views.Get(i);
    if (f.view_projection_size() != 16) {
      return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                          absl::StrCat("views[", i, "].view_projection: 16 floats expected, got ", f.view_projection_size()));
    }
    Eigen::Matrix4d clip_from_view_local;
    for (int k = 0; k < 16; ++k) clip_from_view_local(k % 4, k / 4) = f.view_projection(k);
    // The viewer's local frame is relative to its origin; ours to the model's (both usually equal).
    // An origin of exactly zero means "your local frame" (a viewer that never fetched the model).
    const Eigen::Vector3d view_origin(f.origin_x(), f.origin_y(), f.origin_z());
    const Eigen::Vector3d shift =
        chunks.empty() || view_origin.isZero(0) ? Eigen::Vector3d::Zero() : Eigen::Vector3d(view_origin - model_origin);
    if (!shift.allFinite()) {
      return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, absl::StrCat("views[", i, "]: origin is not finite"));
    }
    Eigen::Matrix4d view_local_from_local = Eigen::Matrix4d::Identity();
    view_local_from_local.topRightCorner<3, 1>() = -shift;
    absl::StatusOr<ConvexVolume> volume =
        FrustumFromClip(clip_from_view_local * view_local_from_local, kDefaultSelectionDepthM, floor_z);
    if (!volume.ok()) {
      return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, absl::StrCat("views[", i, "]: ", volume.status().message()));
    }
    cursor.views.push_back(*std::move(volume));
  }
  return grpc::Status::OK;
}

double SceneServiceImpl::ModelFloorZ(const std::vector<v1::StaticModelChunk>& chunks) {
  double floor_z = std::numeric_limits<double>::infinity();
  for (const auto& chunk : chunks)
    for (int i = 2; i < chunk.positions_size(); i += 3) floor_z = std::min<double>(floor_z, chunk.positions(i));
  return std::isfinite(floor_z) ? floor_z - 0.01 : -std::numeric_limits<double>::infinity();
}

grpc::Status SceneServiceImpl::Subscribe(grpc::ServerContext* context, const v1::SubscribeRequest* request,
                                         grpc::ServerWriter<v1::SceneUpdate>* writer) {
  if (grpc::Status s = AuthorizeCall(shared_, *context, Action::kSubscribe); !s.ok()) return s;
  if (request->viewer_id().size() > 128) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "viewer_id longer than 128 characters");
  }
  if (!std::isfinite(request->max_rate_hz()) || request->max_rate_hz() < 0) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "max_rate_hz must be finite and >= 0");
  }
  if (request->camera_ids_size() > 4096) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "camera_ids: at most 4096 cameras per subscription");
  }
  for (const std::string& id : request->camera_ids()) {
    if (!IsValidCameraId(id)) {
      return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                          "camera_ids: '" + id.substr(0, 80) + "' is not a camera id ([A-Za-z0-9_.-], 1..64)");
    }
  }
  // A rate near zero would overflow the update interval (found by ave_fuzz_grpc_services).
  if (const float r = request->max_rate_hz(); !(std::isfinite(r) && (r == 0 || r >= 0.1f))) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "max_rate_hz: must be 0 (server default) or at least 0.1 Hz");
  }
  ViewerCursor cursor;
  cursor.include_lidar_points = request->include_lidar_points();
  if (grpc::Status s = SelectionViews(request->views(), chunks_, floor_z_, cursor); !s.ok()) return s;
  const std::vector<std::string> camera_ids(request->camera_ids().begin(), request->camera_ids().end());
  const float rate_hz = std::min(options_.max_viewer_rate_hz,
                                 request->max_rate_hz() > 0 ? request->max_rate_hz() : options_.default_viewer_rate_hz);
  const auto min_interval = std::chrono::microseconds(static_cast<int64_t>(1e6 / rate_hz));
  const std::string viewer = request->viewer_id().empty() ? context->peer() : request->viewer_id();
  AVE_LOG(INFO) << "viewer '" << viewer << "' subscribed (" << (camera_ids.empty() ? std::string("all") : absl::StrCat(camera_ids.size()))
                << " cameras, " << rate_hz << " Hz, " << cursor.views.size() << " view frusta)";

  ServerMetrics& metrics = shared_.metrics;
  ++metrics.viewers_connected;
  int64_t queue_depth = 0;  // this viewer's share of metrics.viewer_queue_depth
  uint64_t seen = 0;
  uint64_t sent = 0;
  uint64_t skipped = 0;
  auto next_send = std::chrono::steady_clock::now();
  while (!context->IsCancelled() && !state_.shut_down()) {
    const uint64_t version = state_.version();
    if (version == seen) {
      // Heartbeat every second even when nothing changed, so status ages (live -> stale) reach viewers.
      if (!state_.WaitForChange(seen, std::chrono::milliseconds(1000)) && state_.shut_down()) break;
    }
    std::this_thread::sleep_until(next_send);
    next_send = std::chrono::steady_clock::now() + min_interval;
    seen = state_.version();
    // One arena per update: its few thousand sub-messages (boxes, paths, matrices) are carved from
    // a few blocks and freed at once instead of one malloc/free each.
    google::protobuf::Arena arena;
    v1::SceneUpdate& update = *google::protobuf::Arena::CreateMessage<v1::SceneUpdate>(&arena);
    state_.BuildUpdate(camera_ids, request->include_jpeg(), NowNs(), cursor, update);
    // The frames in this update waited in the viewer's one-per-camera slots.
    const int64_t depth = static_cast<int64_t>(cursor.last_sent.size());
    metrics.viewer_queue_depth += depth - queue_depth;
    queue_depth = depth;
    size_t bytes = 0;
    for (const auto& cam : update.cameras()) bytes += cam.jpeg().size();
    // A sync Write blocks only this viewer's handler while its link is full: other viewers and the
    // sensors carry on, and frames arriving meanwhile replace each other in this viewer's slots.
    if (!writer->Write(update)) break;
    const int64_t written_ns = NowNs();
    for (const auto& [received_ns, capture_ns] : cursor.last_sent) {
      metrics.ingest_to_send_s.Observe((written_ns - received_ns) * 1e-9);
      metrics.capture_to_send_s.Observe((written_ns - capture_ns) * 1e-9);
    }
    metrics.frames_out += cursor.last_sent.size();
    metrics.bytes_out += bytes;
    metrics.viewer_drops += cursor.last_skipped;
    metrics.updates_out += 1;
    shared_.viewer_sent.Add(cursor.last_sent.size());
    if (cursor.last_skipped) shared_.viewer_skipped.Add(cursor.last_skipped);
    skipped += cursor.last_skipped;
    ++sent;
  }
  metrics.viewer_queue_depth -= queue_depth;
  --metrics.viewers_connected;
  AVE_LOG(INFO) << "viewer '" << viewer << "' left after " << sent << " updates (" << skipped
                << " frames skipped for it)";
  return grpc::Status::OK;
}

grpc::Status SceneServiceImpl::GetStaticModel(grpc::ServerContext* context, const v1::StaticModelRequest* request,
                                              grpc::ServerWriter<v1::StaticModelChunk>* writer) {
  if (grpc::Status s = AuthorizeCall(shared_, *context, Action::kReadModel); !s.ok()) return s;
  if (chunks_.empty()) return grpc::Status(grpc::StatusCode::NOT_FOUND, "the store holds no static model");
  for (const auto& chunk : chunks_) {
    if (!writer->Write(chunk)) return grpc::Status(grpc::StatusCode::CANCELLED, "viewer went away");
  }
  return grpc::Status::OK;
}

std::vector<v1::StaticModelChunk> ChunkMesh(const TriangleMesh& mesh, uint64_t version, const std::string& name,
                                            size_t max_vertices) {
  std::vector<v1::StaticModelChunk> chunks;
  std::vector<int64_t> remap(mesh.positions.size(), -1);
  std::vector<uint32_t> touched;
  v1::StaticModelChunk current;
  auto flush = [&] {
    if (current.indices_size() == 0) return;
    chunks.push_back(std::move(current));
    current = v1::StaticModelChunk();
    for (uint32_t v : touched) remap[v] = -1;
    touched.clear();
  };
  for (size_t t = 0; t < mesh.TriangleCount(); ++t) {
    if (touched.size() + 3 > max_vertices) flush();
    for (int k = 0; k < 3; ++k) {
      const uint32_t v = mesh.indices[3 * t + k];
      if (remap[v] < 0) {
        remap[v] = static_cast<int64_t>(touched.size());
        touched.push_back(v);
        for (int a = 0; a < 3; ++a) {
          current.add_positions(mesh.positions[v][a]);
          current.add_normals(mesh.normals[v][a]);
          current.add_colors(mesh.colors[v][a]);
        }
      }
      current.add_indices(static_cast<uint32_t>(remap[v]));
    }
  }
  flush();
  for (size_t i = 0; i < chunks.size(); ++i) {
    chunks[i].set_version(version);
    chunks[i].set_chunk_index(static_cast<uint32_t>(i));
    chunks[i].set_chunk_count(static_cast<uint32_t>(chunks.size()));
    chunks[i].set_name(name);
    chunks[i].mutable_origin()->set_x(mesh.origin.x());
    chunks[i].mutable_origin()->set_y(mesh.origin.y());
    chunks[i].mutable_origin()->set_z(mesh.origin.z());
  }
  return chunks;
}

}  // namespace ave::internal
