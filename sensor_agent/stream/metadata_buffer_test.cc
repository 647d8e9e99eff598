#include "sensor_agent/stream/metadata_buffer.h"

#include <unistd.h>

#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>

namespace ave {
namespace {

v1::SensorFrame Record(uint64_t seq) {
  v1::SensorFrame f;
  f.set_sequence(seq);
  f.set_capture_time_ns(static_cast<int64_t>(seq) * 1000);
  f.mutable_pose()->mutable_position()->set_x(static_cast<double>(seq));
  f.set_jpeg("image bytes that must not be kept");
  return f;
}

std::vector<uint64_t> Drain(MetadataBuffer& buffer) {
  std::vector<uint64_t> out;
  for (;;) {
    auto r = buffer.Pop();
    EXPECT_TRUE(r.ok()) << r.status();
    if (!r.ok() || !r->has_value()) return out;
    EXPECT_TRUE((*r)->jpeg().empty());
    EXPECT_TRUE((*r)->metadata_only());
    out.push_back((*r)->sequence());
  }
}

TEST(MetadataBuffer, LongOutageSpillsToDiskAndReplaysInOrder) {
  const std::string path =
      (std::filesystem::temp_directory_path() / ("ave_meta_" + std::to_string(::getpid()))).string();
  std::vector<uint64_t> expected;
  {
    MetadataBuffer buffer({.max_in_memory = 10, .spill_path = path, .max_spilled = 1000});
    for (uint64_t s = 1; s <= 500; ++s) {
      buffer.Push(Record(s));
      expected.push_back(s);
    }
    EXPECT_EQ(buffer.size(), 500u);
    EXPECT_EQ(buffer.spilled(), 490u);
    EXPECT_TRUE(std::filesystem::exists(path));
    // A failed send puts the record back at the head.
    auto first = buffer.Pop();
    ASSERT_TRUE(first.ok() && first->has_value());
    buffer.Unpop(**first);
    EXPECT_EQ(Drain(buffer), expected);
    EXPECT_EQ(buffer.dropped(), 0u);
    EXPECT_FALSE(std::filesystem::exists(path));  // drained: the file is gone
    // A second outage works the same.
    for (uint64_t s = 501; s <= 530; ++s) buffer.Push(Record(s));
    EXPECT_EQ(Drain(buffer).size(), 30u);
  }
  EXPECT_FALSE(std::filesystem::exists(path));
}

TEST(MetadataBuffer, IsBoundedAndCountsWhatItDrops) {
  MetadataBuffer buffer({.max_in_memory = 5, .spill_path = "", .max_spilled = 0});
  for (uint64_t s = 1; s <= 8; ++s) buffer.Push(Record(s));
  EXPECT_EQ(buffer.size(), 5u);
  EXPECT_EQ(buffer.dropped(), 3u);
  EXPECT_EQ(Drain(buffer), (std::vector<uint64_t>{1, 2, 3, 4, 5}));  // the oldest are kept, in order
}

// Issue 14: the spill file is read back; a corrupt length (here 4 GiB) is refused naming the file,
// without allocating it, and what it held is counted as lost.
TEST(MetadataBuffer, CorruptSpillFileIsDataLossNamingTheFile) {
  const std::string path =
      (std::filesystem::temp_directory_path() / ("ave_meta_bad_" + std::to_string(::getpid()))).string();
  MetadataBuffer buffer({.max_in_memory = 1, .spill_path = path, .max_spilled = 100});
  for (uint64_t s = 1; s <= 4; ++s) buffer.Push(Record(s));
  ASSERT_EQ(buffer.spilled(), 3u);
  {
    std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
    const char huge[4] = {'\xff', '\xff', '\xff', '\xff'};
    f.write(huge, 4);
  }
  auto first = buffer.Pop();
  ASSERT_TRUE(first.ok() && first->has_value());
  EXPECT_EQ((*first)->sequence(), 1u);  // from memory
  auto bad = buffer.Pop();
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), absl::StatusCode::kDataLoss);
  EXPECT_NE(std::string(bad.status().message()).find(path), std::string::npos) << bad.status();
  EXPECT_EQ(buffer.dropped(), 3u);
  auto after = buffer.Pop();
  ASSERT_TRUE(after.ok());
  EXPECT_FALSE(after->has_value());
}

}  // namespace
}  // namespace ave
