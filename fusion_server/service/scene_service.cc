#include <algorithm>
#include <thread>

#include "absl/strings/str_cat.h"
#include "fusion_server/service/services.h"
#include "model_store/common/log.h"

namespace ave::internal {

grpc::Status SceneServiceImpl::Subscribe(grpc::ServerContext* context, const v1::SubscribeRequest* request,
                                         grpc::ServerWriter<v1::SceneUpdate>* writer) {
  if (grpc::Status s = CheckBearer(*context, options_.viewer_token, "viewer"); !s.ok()) return s;
  if (request->viewer_id().size() > 128) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "viewer_id longer than 128 characters");
  }
  if (!std::isfinite(request->max_rate_hz()) || request->max_rate_hz() < 0) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "max_rate_hz must be finite and >= 0");
  }
  const std::vector<std::string> camera_ids(request->camera_ids().begin(), request->camera_ids().end());
  const float rate_hz = std::min(options_.max_viewer_rate_hz,
                                 request->max_rate_hz() > 0 ? request->max_rate_hz() : options_.default_viewer_rate_hz);
  const auto min_interval = std::chrono::microseconds(static_cast<int64_t>(1e6 / rate_hz));
  const std::string viewer = request->viewer_id().empty() ? context->peer() : request->viewer_id();
  AVE_LOG(INFO) << "viewer '" << viewer << "' subscribed (" << (camera_ids.empty() ? std::string("all") : absl::StrCat(camera_ids.size()))
                << " cameras, " << rate_hz << " Hz)";

  ViewerCursor cursor;
  uint64_t seen = 0;
  uint64_t sent = 0;
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
    v1::SceneUpdate update = state_.BuildUpdate(camera_ids, request->include_jpeg(), NowNs(), cursor);
    if (!writer->Write(update)) break;
    ++sent;
  }
  AVE_LOG(INFO) << "viewer '" << viewer << "' left after " << sent << " updates";
  return grpc::Status::OK;
}

grpc::Status SceneServiceImpl::GetStaticModel(grpc::ServerContext* context, const v1::StaticModelRequest* request,
                                              grpc::ServerWriter<v1::StaticModelChunk>* writer) {
  if (grpc::Status s = CheckBearer(*context, options_.viewer_token, "viewer"); !s.ok()) return s;
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
