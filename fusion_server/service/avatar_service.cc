// The avatar RPCs (issue 17): SceneService.GetAvatarSequence (viewers fetch each sequence once, by
// name and version, in chunks) and AdminService.PutAvatarSequence / ListAvatarSequences (audited).
#include <algorithm>

#include "absl/strings/str_cat.h"
#include "fusion_server/service/services.h"
#include "model_store/avatar/avatar_blob.h"
#include "model_store/common/log.h"

namespace ave::internal {
namespace {

constexpr size_t kAvatarChunkBytes = 1 << 20;
constexpr uint64_t kMaxAvatarBlobBytes = uint64_t{1} << 30;  // 1 GiB: ~300 frames of 1024² atlases

v1::AvatarSequenceInfo ToInfo(const store::AvatarSequenceRecord& r) {
  v1::AvatarSequenceInfo info;
  info.set_name(r.name);
  info.set_version(static_cast<uint64_t>(r.version));
  info.set_frame_count(static_cast<uint32_t>(r.frame_count));
  info.set_frame_period_s(r.frame_period_s);
  info.set_stride_m(r.stride_m);
  info.set_bytes(static_cast<uint64_t>(r.blob_bytes));
  info.set_created_at_ns(r.created_at_ns);
  return info;
}

}  // namespace

absl::Status PublishAvatarSequences(store::Store& store, SceneState& state) {
  absl::StatusOr<std::vector<store::AvatarSequenceRecord>> list = store.ListAvatarSequences();
  if (!list.ok()) return list.status();
  std::vector<AvatarSequenceInfo> infos;
  for (const auto& r : *list) infos.push_back({r.name, r.version, r.frame_count, r.stride_m});
  state.SetAvatarSequences(std::move(infos));
  return absl::OkStatus();
}

grpc::Status SceneServiceImpl::GetAvatarSequence(grpc::ServerContext* context, const v1::AvatarSequenceRequest* request,
                                                 grpc::ServerWriter<v1::AvatarSequenceChunk>* writer) {
  if (grpc::Status s = AuthorizeCall(shared_, *context, Action::kReadModel); !s.ok()) return s;
  if (std::string why = store::ValidateAvatarName(request->name()); !why.empty()) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "name: " + why);
  }
  absl::StatusOr<store::AvatarSequenceRecord> record = shared_.store.GetAvatarSequenceBlob(request->name());
  if (!record.ok()) return ToGrpc(record.status());
  if (request->known_version() == static_cast<uint64_t>(record->version)) return grpc::Status::OK;
  const size_t total = record->blob.size();
  const uint32_t count = static_cast<uint32_t>(std::max<size_t>(1, (total + kAvatarChunkBytes - 1) / kAvatarChunkBytes));
  for (uint32_t i = 0; i < count; ++i) {
    v1::AvatarSequenceChunk chunk;
    chunk.set_name(record->name);
    chunk.set_version(static_cast<uint64_t>(record->version));
    chunk.set_chunk_index(i);
    chunk.set_chunk_count(count);
    chunk.set_total_bytes(total);
    const size_t begin = i * kAvatarChunkBytes;
    chunk.set_data(record->blob.substr(begin, std::min(kAvatarChunkBytes, total - begin)));
    if (!writer->Write(chunk)) return grpc::Status(grpc::StatusCode::CANCELLED, "viewer went away");
  }
  return grpc::Status::OK;
}

grpc::Status AdminServiceImpl::PutAvatarSequence(grpc::ServerContext* context,
                                                 grpc::ServerReader<v1::AvatarSequenceChunk>* reader,
                                                 v1::AvatarSequenceInfo* response) {
  Principal who;
  if (grpc::Status s = AuthorizeCall(shared_, *context, Action::kManageModels, {}, {}, &who); !s.ok()) return s;
  std::string blob, name;
  uint32_t count = 0;
  uint64_t total = 0;
  v1::AvatarSequenceChunk chunk;
  uint32_t index = 0;
  for (; reader->Read(&chunk); ++index) {
    const std::string where = absl::StrCat("chunk ", index, ": ");
    if (index == 0) {
      count = chunk.chunk_count();
      total = chunk.total_bytes();
      name = chunk.name();
      if (count == 0) return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, where + "chunk_count must be > 0");
      if (total == 0 || total > kMaxAvatarBlobBytes) {
        return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                            absl::StrCat(where, "total_bytes must be in 1..", kMaxAvatarBlobBytes, ", not ", total));
      }
      blob.reserve(total);
    }
    if (chunk.chunk_index() != index) {
      return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                          absl::StrCat(where, "chunk_index is ", chunk.chunk_index(), ", expected ", index));
    }
    if (chunk.chunk_count() != count || chunk.total_bytes() != total) {
      return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, where + "chunk_count / total_bytes changed mid-stream");
    }
    if (index >= count || blob.size() + chunk.data().size() > total) {
      return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                          absl::StrCat(where, "more data than total_bytes (", total, ") or chunk_count (", count, ")"));
    }
    blob += chunk.data();
  }
  if (index == 0) return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "no chunks: the sequence is empty");
  if (index != count || blob.size() != total) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                        absl::StrCat("stream ended after ", index, " of ", count, " chunks, ", blob.size(), " of ",
                                     total, " bytes"));
  }
  absl::StatusOr<avatar::AvatarSequence> sequence =
      avatar::DecodeAvatarSequence(blob, absl::StrCat("avatar sequence '", name, "'"));
  // The blob came from the caller: a bad one is their argument, not our data loss.
  if (!sequence.ok()) return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, std::string(sequence.status().message()));
  if (!name.empty()) sequence->name = name;
  absl::StatusOr<int64_t> version = store_.PutAvatarSequence(*sequence);
  if (!version.ok()) return ToGrpc(version.status());
  absl::StatusOr<store::AvatarSequenceRecord> stored = store_.GetAvatarSequenceBlob(sequence->name);
  if (!stored.ok()) return ToGrpc(stored.status());
  stored->blob.clear();
  *response = ToInfo(*stored);
  if (absl::Status s = PublishAvatarSequences(store_, state_); !s.ok()) return ToGrpc(s);
  std::string after;
  after = absl::StrCat("{\"name\":\"", stored->name, "\",\"version\":", stored->version, ",\"frames\":",
                       stored->frame_count, ",\"bytes\":", stored->blob_bytes, "}");
  Audit(who, *context, "PutAvatarSequence", stored->name, "{}", after);
  return grpc::Status::OK;
}

grpc::Status AdminServiceImpl::ListAvatarSequences(grpc::ServerContext* context, const v1::ListAvatarSequencesRequest*,
                                                   v1::ListAvatarSequencesResponse* response) {
  if (grpc::Status s = AuthorizeCall(shared_, *context, Action::kManageModels); !s.ok()) return s;
  absl::StatusOr<std::vector<store::AvatarSequenceRecord>> list = store_.ListAvatarSequences();
  if (!list.ok()) return ToGrpc(list.status());
  for (const auto& r : *list) *response->add_sequences() = ToInfo(r);
  return grpc::Status::OK;
}

}  // namespace ave::internal
