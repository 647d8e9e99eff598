#include "sensor_agent/stream/metadata_buffer.h"

#include <unistd.h>

#include <filesystem>

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

}  // namespace
}  // namespace ave
