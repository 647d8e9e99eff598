// The store's avatar sequences (issue 17): schema step, put/list/get, and the errors a bad or
// corrupt sequence gives.
#include <sqlite3.h>
#include <unistd.h>

#include <filesystem>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "model_store/avatar/procedural_avatar.h"
#include "model_store/db/store.h"

namespace ave::store {
namespace {

using ::testing::HasSubstr;

class TempFile {
 public:
  TempFile() {
    std::string tmpl = (std::filesystem::temp_directory_path() / "ave_store_avatar_XXXXXX").string();
    dir_ = mkdtemp(tmpl.data()) ? tmpl : "";
  }
  ~TempFile() { std::filesystem::remove_all(dir_); }
  std::string path() const { return dir_ + "/model.db"; }

 private:
  std::string dir_;
};

std::unique_ptr<Store> OpenOrDie(const std::string& path) {
  auto store = Store::Open(path);
  EXPECT_TRUE(store.ok()) << store.status();
  return store.ok() ? std::move(*store) : nullptr;
}

TEST(StoreAvatars, PutListGetRoundTripsEveryFrameExactly) {
  TempFile file;
  const avatar::AvatarSequence walk = avatar::MakeProceduralWalk({}, "walk-a");
  int64_t version = 0;
  {
    auto store = OpenOrDie(file.path());
    ASSERT_TRUE(store);
    EXPECT_EQ(store->SchemaVersion(), Store::LatestSchemaVersion());
    auto v = store->PutAvatarSequence(walk);
    ASSERT_TRUE(v.ok()) << v.status();
    version = *v;
    auto v2 = store->PutAvatarSequence(avatar::MakeProceduralWalk({.frame_count = 1}, "statue"));
    ASSERT_TRUE(v2.ok()) << v2.status();
    EXPECT_GT(*v2, version);
  }
  auto store = OpenOrDie(file.path());  // reopened: persisted
  ASSERT_TRUE(store);
  auto list = store->ListAvatarSequences();
  ASSERT_TRUE(list.ok()) << list.status();
  ASSERT_EQ(list->size(), 2u);
  EXPECT_EQ((*list)[0].name, "statue");  // by name
  EXPECT_EQ((*list)[0].frame_count, 1);
  EXPECT_EQ((*list)[1].name, "walk-a");
  EXPECT_EQ((*list)[1].version, version);
  EXPECT_EQ((*list)[1].frame_count, static_cast<int64_t>(walk.frames.size()));
  EXPECT_EQ((*list)[1].stride_m, walk.stride_m);
  EXPECT_GT((*list)[1].blob_bytes, 0);
  EXPECT_TRUE((*list)[1].blob.empty());
  auto got = store->GetAvatarSequence("walk-a");
  ASSERT_TRUE(got.ok()) << got.status();
  EXPECT_EQ(got->name, walk.name);
  EXPECT_EQ(got->frame_period_s, walk.frame_period_s);
  ASSERT_EQ(got->frames.size(), walk.frames.size());
  for (size_t i = 0; i < walk.frames.size(); ++i) {
    EXPECT_EQ(got->frames[i].positions_m, walk.frames[i].positions_m) << "frame " << i;
    EXPECT_EQ(got->frames[i].uv, walk.frames[i].uv) << "frame " << i;
    EXPECT_EQ(got->frames[i].indices, walk.frames[i].indices) << "frame " << i;
    EXPECT_EQ(got->frames[i].atlas_rgb, walk.frames[i].atlas_rgb) << "frame " << i;
  }
  auto blob = store->GetAvatarSequenceBlob("walk-a");
  ASSERT_TRUE(blob.ok());
  EXPECT_EQ(static_cast<int64_t>(blob->blob.size()), (*list)[1].blob_bytes);
}

TEST(StoreAvatars, TakenNameIsAlreadyExistsAndUnknownIsNotFound) {
  auto store = OpenOrDie(":memory:");
  ASSERT_TRUE(store);
  ASSERT_TRUE(store->PutAvatarSequence(avatar::MakeProceduralWalk()).ok());
  const auto again = store->PutAvatarSequence(avatar::MakeProceduralWalk());
  EXPECT_TRUE(absl::IsAlreadyExists(again.status())) << again.status();
  EXPECT_THAT(again.status().message(), HasSubstr("'procedural-walk'"));
  const auto missing = store->GetAvatarSequence("nobody");
  EXPECT_TRUE(absl::IsNotFound(missing.status())) << missing.status();
  EXPECT_THAT(missing.status().message(), HasSubstr("'nobody'"));
}

TEST(StoreAvatars, BadSequenceIsRejectedNamingTheFieldAndNotStored) {
  auto store = OpenOrDie(":memory:");
  ASSERT_TRUE(store);
  avatar::AvatarSequence bad_name = avatar::MakeProceduralWalk({}, "no spaces allowed");
  EXPECT_THAT(store->PutAvatarSequence(bad_name).status().message(), HasSubstr("name"));
  avatar::AvatarSequence bad_uv = avatar::MakeProceduralWalk();
  bad_uv.frames[2].uv[5].x() = 1.5f;
  const auto s = store->PutAvatarSequence(bad_uv).status();
  EXPECT_TRUE(absl::IsInvalidArgument(s)) << s;
  EXPECT_THAT(s.message(), HasSubstr("frames[2].uv[5]"));
  avatar::AvatarSequence empty = avatar::MakeProceduralWalk();
  empty.frames.clear();
  EXPECT_FALSE(store->PutAvatarSequence(empty).ok());
  auto list = store->ListAvatarSequences();
  ASSERT_TRUE(list.ok());
  EXPECT_TRUE(list->empty());
}

TEST(StoreAvatars, CorruptBlobIsDataLossNamingTheRow) {
  TempFile file;
  auto store = OpenOrDie(file.path());
  ASSERT_TRUE(store);
  ASSERT_TRUE(store->PutAvatarSequence(avatar::MakeProceduralWalk({}, "walk")).ok());
  sqlite3* raw = nullptr;
  ASSERT_EQ(sqlite3_open(file.path().c_str(), &raw), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(raw, "UPDATE avatar_sequences SET blob = substr(blob, 1, length(blob) - 7)", nullptr, nullptr,
                         nullptr),
            SQLITE_OK);
  sqlite3_close(raw);
  const auto s = store->GetAvatarSequence("walk").status();
  EXPECT_TRUE(absl::IsDataLoss(s)) << s;
  EXPECT_THAT(s.message(), HasSubstr("avatar_sequences row 'walk'"));
}

}  // namespace
}  // namespace ave::store
