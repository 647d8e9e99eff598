#include "model_store/avatar/avatar_blob.h"

#include <cstdio>
#include <filesystem>
#include <fstream>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace ave::avatar {
namespace {

using ::testing::HasSubstr;

// Two frames of a tetrahedron with a 2x1 atlas each (different shapes per frame, as the studio's
// re-meshed frames are).
AvatarSequence TwoFrameSequence() {
  AvatarSequence s;
  s.name = "studio-walk";
  s.frame_period_s = 0.1;
  s.stride_m = 1.3;
  for (int k = 0; k < 2; ++k) {
    AvatarFrame f;
    const float h = 1.7f + 0.05f * static_cast<float>(k);
    f.positions_m = {{0, 0, 0}, {0.3f, 0, 0}, {0, 0.3f, 0}, {0.1f, 0.1f, h}};
    f.normals = {{0, 0, -1}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
    f.uv = {{0, 0}, {1, 0}, {0, 1}, {0.5f, 0.5f}};
    f.indices = {0, 2, 1, 0, 1, 3, 1, 2, 3, 2, 0, 3};
    f.atlas_width = 2;
    f.atlas_height = 1;
    f.atlas_rgb = {10, 20, 30, static_cast<uint8_t>(40 + k), 50, 60};
    s.frames.push_back(f);
  }
  return s;
}

TEST(AvatarBlob, RoundTripsEveryField) {
  const AvatarSequence s = TwoFrameSequence();
  absl::StatusOr<std::string> blob = EncodeAvatarSequence(s, "test");
  ASSERT_TRUE(blob.ok()) << blob.status();
  absl::StatusOr<AvatarSequence> back = DecodeAvatarSequence(*blob, "test");
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(back->name, s.name);
  EXPECT_EQ(back->frame_period_s, s.frame_period_s);
  EXPECT_EQ(back->stride_m, s.stride_m);
  ASSERT_EQ(back->frames.size(), 2u);
  for (size_t k = 0; k < 2; ++k) {
    EXPECT_EQ(back->frames[k].positions_m, s.frames[k].positions_m);
    EXPECT_EQ(back->frames[k].normals, s.frames[k].normals);
    EXPECT_EQ(back->frames[k].uv, s.frames[k].uv);
    EXPECT_EQ(back->frames[k].indices, s.frames[k].indices);
    EXPECT_EQ(back->frames[k].atlas_rgb, s.frames[k].atlas_rgb);
  }
  EXPECT_NEAR(back->SpeedMps(), 1.3 / 0.2, 1e-12);
}

TEST(AvatarBlob, OneFrameIsAStatue) {
  AvatarSequence s = TwoFrameSequence();
  s.frames.resize(1);
  s.stride_m = 0;
  absl::StatusOr<AvatarSequence> back = DecodeAvatarSequence(*EncodeAvatarSequence(s, "t"), "t");
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(back->frames.size(), 1u);
  EXPECT_EQ(back->SpeedMps(), 0.0);
}

TEST(AvatarBlob, RefusesInconsistentSequencesNamingTheField) {
  AvatarSequence s = TwoFrameSequence();
  s.frames[1].uv[3] = {1.5f, 0};
  EXPECT_THAT(CheckAvatarSequence(s), HasSubstr("frames[1].uv[3]"));
  s = TwoFrameSequence();
  s.frames[0].indices[4] = 9;
  EXPECT_THAT(CheckAvatarSequence(s), HasSubstr("frames[0].indices[4] = 9"));
  s = TwoFrameSequence();
  s.frames[0].atlas_rgb.pop_back();
  EXPECT_THAT(CheckAvatarSequence(s), HasSubstr("frames[0].atlas_rgb"));
  s = TwoFrameSequence();
  s.frame_period_s = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THAT(CheckAvatarSequence(s), HasSubstr("frame_period_s"));
  s = TwoFrameSequence();
  s.frames.clear();
  EXPECT_THAT(CheckAvatarSequence(s), HasSubstr("frames is empty"));
  s = TwoFrameSequence();
  s.frames[0].positions_m[2].x() = std::numeric_limits<float>::infinity();
  absl::StatusOr<std::string> blob = EncodeAvatarSequence(s, "walk.avseq");
  ASSERT_FALSE(blob.ok());
  EXPECT_THAT(blob.status().message(), HasSubstr("walk.avseq"));
  EXPECT_THAT(blob.status().message(), HasSubstr("frames[0].positions_m[2]"));
}

TEST(AvatarBlob, EveryTruncationAndCorruptCountIsDataLoss) {
  const std::string blob = *EncodeAvatarSequence(TwoFrameSequence(), "t");
  for (size_t n = 0; n < blob.size(); ++n) {
    absl::StatusOr<AvatarSequence> r = DecodeAvatarSequence(std::string_view(blob).substr(0, n), "row 'walk'");
    ASSERT_FALSE(r.ok()) << "prefix of " << n << " bytes decoded";
    EXPECT_EQ(r.status().code(), absl::StatusCode::kDataLoss);
    EXPECT_THAT(r.status().message(), HasSubstr("row 'walk'"));
  }
  EXPECT_FALSE(DecodeAvatarSequence(blob + "x", "t").ok());
  // Frame count claiming 2^32-1 frames, and a vertex count of 2^63: refused before allocating.
  std::string huge = blob;
  const size_t frame_count_at = 4 + 4 + 4 + 11 + 16;
  huge[frame_count_at] = huge[frame_count_at + 1] = huge[frame_count_at + 2] = huge[frame_count_at + 3] = '\xff';
  EXPECT_FALSE(DecodeAvatarSequence(huge, "t").ok());
  huge = blob;
  huge[frame_count_at + 4 + 7] = '\x80';
  EXPECT_FALSE(DecodeAvatarSequence(huge, "t").ok());
  std::string wrong_version = blob;
  wrong_version[4] = 9;
  EXPECT_THAT(DecodeAvatarSequence(wrong_version, "t").status().message(), HasSubstr("format version 9"));
}

TEST(AvatarBlob, FileRoundTripAndErrorsNameThePath) {
  const std::string dir = ::testing::TempDir();
  const std::string path = dir + "/walk.avseq";
  ASSERT_TRUE(WriteAvatarSequenceFile(path, TwoFrameSequence()).ok());
  absl::StatusOr<AvatarSequence> back = ReadAvatarSequenceFile(path);
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(back->frames.size(), 2u);
  EXPECT_FALSE(std::filesystem::exists(path + ".part"));
  std::ofstream(dir + "/bad.avseq") << "AVEAgarbage";
  absl::StatusOr<AvatarSequence> bad = ReadAvatarSequenceFile(dir + "/bad.avseq");
  ASSERT_FALSE(bad.ok());
  EXPECT_THAT(bad.status().message(), HasSubstr("bad.avseq"));
  EXPECT_THAT(ReadAvatarSequenceFile(dir + "/missing.avseq").status().message(), HasSubstr("missing.avseq"));
}

}  // namespace
}  // namespace ave::avatar
