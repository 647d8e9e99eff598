// Avatar sequences at the service edge (issue 17), through a real server on loopback: ave-admin's
// client stores one (audited), a viewer fetches it once by name and version in chunks, every
// field of the new requests refused by name when bad, and sequences reach the people of the
// scene state from the store at start.
#include <cstring>

#include <gmock/gmock.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "fusion_server/admin/admin_client.h"
#include "fusion_server/service/server.h"
#include "fusion_server/service/test_fixtures.h"
#include "model_store/avatar/avatar_blob.h"
#include "model_store/avatar/procedural_avatar.h"
#include "model_store/db/store.h"

namespace ave {
namespace {

using ::testing::HasSubstr;

constexpr char kViewer[] = "viewer-secret";
constexpr char kAdmin[] = "admin-secret";

std::string Blob(const avatar::AvatarSequence& s) {
  absl::StatusOr<std::string> blob = avatar::EncodeAvatarSequence(s, "test");
  EXPECT_TRUE(blob.ok()) << blob.status();
  return blob.ok() ? *blob : std::string();
}

class AvatarServiceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_TRUE(server_.Start(server_.Options("", kViewer, kAdmin)).ok());
    Connect();
  }
  void Connect() {
    channel_ = server_.InsecureChannel();
    admin_ = std::make_unique<AdminClient>(channel_, kAdmin);
    scene_ = v1::SceneService::NewStub(channel_);
  }
  // The chunks a viewer receives for (name, known_version), and the call's status.
  grpc::Status Fetch(const std::string& name, uint64_t known_version, std::vector<v1::AvatarSequenceChunk>* chunks) {
    grpc::ClientContext context;
    context.AddMetadata("authorization", std::string("Bearer ") + kViewer);
    v1::AvatarSequenceRequest request;
    request.set_name(name);
    request.set_known_version(known_version);
    auto reader = scene_->GetAvatarSequence(&context, request);
    v1::AvatarSequenceChunk chunk;
    while (reader->Read(&chunk)) chunks->push_back(chunk);
    return reader->Finish();
  }
  // A raw put of `chunks` with `token`.
  absl::Status Put(const std::vector<v1::AvatarSequenceChunk>& chunks, const std::string& token = kAdmin) {
    grpc::ClientContext context;
    context.AddMetadata("authorization", "Bearer " + token);
    v1::AvatarSequenceInfo info;
    auto writer = v1::AdminService::NewStub(channel_)->PutAvatarSequence(&context, &info);
    for (const auto& c : chunks)
      if (!writer->Write(c)) break;
    writer->WritesDone();
    return FromGrpc(writer->Finish());
  }
  static v1::AvatarSequenceChunk Whole(const std::string& blob, const std::string& name = "") {
    v1::AvatarSequenceChunk c;
    c.set_name(name);
    c.set_chunk_count(1);
    c.set_total_bytes(blob.size());
    c.set_data(blob);
    return c;
  }

  fixtures::LocalServer server_{"ave_avatar_service"};
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<AdminClient> admin_;
  std::unique_ptr<v1::SceneService::Stub> scene_;
};

TEST_F(AvatarServiceTest, PutIsAuditedAndViewersFetchItOnceInChunks) {
  // Large atlases make a blob of several 1 MiB chunks.
  const avatar::AvatarSequence walk = avatar::MakeProceduralWalk({.frame_count = 6, .atlas_side = 512});
  const std::string blob = Blob(walk);
  ASSERT_GT(blob.size(), 3u << 20);
  absl::StatusOr<v1::AvatarSequenceInfo> info = admin_->PutAvatarSequence(blob, "walk");
  ASSERT_TRUE(info.ok()) << info.status();
  EXPECT_EQ(info->name(), "walk");
  EXPECT_EQ(info->frame_count(), 6u);
  EXPECT_GT(info->version(), 0u);
  auto list = admin_->ListAvatarSequences();
  ASSERT_TRUE(list.ok()) << list.status();
  ASSERT_EQ(list->size(), 1u);
  EXPECT_EQ((*list)[0].version(), info->version());

  std::vector<v1::AvatarSequenceChunk> chunks;
  ASSERT_TRUE(Fetch("walk", 0, &chunks).ok());
  ASSERT_GE(chunks.size(), 4u);
  std::string fetched;
  for (size_t i = 0; i < chunks.size(); ++i) {
    EXPECT_EQ(chunks[i].chunk_index(), i);
    EXPECT_EQ(chunks[i].chunk_count(), chunks.size());
    EXPECT_EQ(chunks[i].version(), info->version());
    fetched += chunks[i].data();
  }
  absl::StatusOr<avatar::AvatarSequence> decoded = avatar::DecodeAvatarSequence(fetched, "fetched");
  ASSERT_TRUE(decoded.ok()) << decoded.status();
  EXPECT_EQ(decoded->name, "walk");  // stored under the name the admin gave
  EXPECT_EQ(decoded->frames[5].positions_m, walk.frames[5].positions_m);
  EXPECT_EQ(decoded->frames[5].atlas_rgb, walk.frames[5].atlas_rgb);
  chunks.clear();
  ASSERT_TRUE(Fetch("walk", info->version(), &chunks).ok());
  EXPECT_TRUE(chunks.empty()) << "a viewer holding this version gets nothing";

  const std::string store_path = server_.store_path();
  server_.Stop();
  auto store = store::Store::Open(store_path);
  ASSERT_TRUE(store.ok());
  auto audit = (*store)->ListAudit();
  ASSERT_TRUE(audit.ok());
  bool audited = false;
  for (const auto& a : *audit) {
    if (a.action != "PutAvatarSequence") continue;
    audited = true;
    EXPECT_EQ(a.target, "walk");
    EXPECT_THAT(a.actor, HasSubstr("admin:"));
    EXPECT_THAT(a.after_json, HasSubstr("\"frames\":6"));
  }
  EXPECT_TRUE(audited);
}

TEST_F(AvatarServiceTest, EveryRequestFieldIsRefusedByName) {
  const std::string blob = Blob(avatar::MakeProceduralWalk());
  std::vector<v1::AvatarSequenceChunk> none;
  // AvatarSequenceRequest.name (known_version accepts any value: see the test above).
  EXPECT_THAT(FromGrpc(Fetch("no spaces", 0, &none)).message(), HasSubstr("name"));
  const absl::Status missing = FromGrpc(Fetch("nobody", 0, &none));
  EXPECT_TRUE(absl::IsNotFound(missing)) << missing;
  EXPECT_THAT(missing.message(), HasSubstr("'nobody'"));
  // AvatarSequenceChunk on put; version is the server's to set and ignored.
  struct Case {
    const char* what;
    std::vector<v1::AvatarSequenceChunk> chunks;
    const char* names;
  };
  auto with = [&](auto mutate) {
    v1::AvatarSequenceChunk c = Whole(blob);
    mutate(c);
    return std::vector<v1::AvatarSequenceChunk>{c};
  };
  // frames[0].uv[5].u set past 1 in a good blob (avatar_blob.h's layout): EncodeAvatarSequence
  // would refuse to write it, a hand-made file may still hold it.
  const avatar::AvatarSequence good = avatar::MakeProceduralWalk();
  const size_t n = good.frames[0].positions_m.size();
  const size_t uv_at = 4 + 4 + 4 + good.name.size() + 8 + 8 + 4 + (8 + 8 + 4 + 4) + 4 * (3 * n + 3 * n) + 4 * (2 * 5);
  std::string bad_uv_blob = blob;
  const float bad_u = 1.5f;
  ASSERT_EQ(std::memcmp(&bad_uv_blob[uv_at], &good.frames[0].uv[5].x(), 4), 0) << "test setup: the blob's layout";
  bad_uv_blob.replace(uv_at, 4, std::string(reinterpret_cast<const char*>(&bad_u), 4));
  const std::vector<Case> cases = {
      {"name", with([](auto& c) { c.set_name("bad name!"); }), "name"},
      {"chunk_index", with([](auto& c) { c.set_chunk_index(1); }), "chunk_index"},
      {"chunk_count", with([](auto& c) { c.set_chunk_count(0); }), "chunk_count"},
      {"chunk_count short", with([](auto& c) { c.set_chunk_count(2); }), "1 of 2 chunks"},
      {"total_bytes", with([](auto& c) { c.set_total_bytes(0); }), "total_bytes"},
      {"total_bytes huge", with([](auto& c) { c.set_total_bytes(uint64_t{1} << 40); }), "total_bytes"},
      {"data truncated", with([&](auto& c) { c.set_data(blob.substr(0, blob.size() - 9)); c.set_total_bytes(blob.size() - 9); }),
       "avatar sequence"},
      {"data past total", with([&](auto& c) { c.set_total_bytes(blob.size() - 1); }), "more data than total_bytes"},
      {"data bad field", {Whole(bad_uv_blob)}, "frames[0].uv[5]"},
      {"no chunks", {}, "no chunks"},
  };
  for (const Case& c : cases) {
    const absl::Status s = Put(c.chunks);
    EXPECT_TRUE(absl::IsInvalidArgument(s)) << c.what << ": " << s;
    EXPECT_THAT(s.message(), HasSubstr(c.names)) << c.what;
  }
  const absl::Status viewer = Put({Whole(blob)}, kViewer);
  EXPECT_TRUE(absl::IsPermissionDenied(viewer)) << viewer;
  auto list = admin_->ListAvatarSequences();
  ASSERT_TRUE(list.ok());
  EXPECT_TRUE(list->empty()) << "nothing bad was stored";
  ASSERT_TRUE(Put({Whole(blob, "walk")}).ok());
  const absl::Status taken = Put({Whole(blob, "walk")});
  EXPECT_TRUE(absl::IsAlreadyExists(taken)) << taken;
  EXPECT_THAT(taken.message(), HasSubstr("'walk'"));
}

TEST_F(AvatarServiceTest, StoredSequencesReachPeopleAfterARestart) {
  ASSERT_TRUE(admin_->PutAvatarSequence(Blob(avatar::MakeProceduralWalk()), "walk").ok());
  ASSERT_TRUE(server_.Start(server_.Options("", kViewer, kAdmin)).ok());  // restart on the same store
  Connect();
  ASSERT_TRUE(admin_->AddCamera(LidarRecord("hdl", "", Rigid3d())).ok());
  SceneState& state = server_->state();
  const uint64_t session = state.StreamOpened("hdl");
  for (int f = 0; f < 20; ++f) {
    auto sweep = std::make_shared<v1::LidarSweepFrame>();
    sweep->set_sequence(f + 1);
    v1::FootTrack* t = sweep->add_tracks();
    t->set_track_id(1);
    t->mutable_position()->set_x(-1.0 * 0.14 * f);  // walking west
    for (float c : {0.01f, 0.0f, 0.01f}) t->add_covariance(c);
    const int64_t t_ns = 1'000'000'000 + f * 100'000'000LL;
    ASSERT_TRUE(state.AcceptLidarSweep("hdl", sweep, t_ns, session).ok());
  }
  ViewerCursor cursor;
  const v1::SceneUpdate update = state.BuildUpdate({}, false, 1'000'000'000 + 20 * 100'000'000LL, cursor);
  ASSERT_EQ(update.objects_size(), 1);
  EXPECT_EQ(update.objects(0).avatar_sequence(), "walk");
  EXPECT_NEAR(std::abs(update.objects(0).avatar_heading_rad()), M_PI, 0.05);
}

}  // namespace
}  // namespace ave
