// Issue 14: a user's LAS file comes back from the rewriter with only its classification changed.
// The sources are written byte by byte by las_synthetic (random values in every field, CRS VLRs,
// an EVLR), not by our writer, so nothing here checks our code against itself.
#include "model_store/lidar/las_rewrite.h"

#include <unistd.h>

#include <cstring>
#include <filesystem>
#include <random>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "model_store/lidar/las.h"
#include "model_store/lidar/las_synthetic.h"
#include "model_store/lidar/point_cloud_io.h"
#include "model_store/lidar/read_file.h"

namespace ave::model {
namespace {

using ::testing::HasSubstr;

struct RewriteCase {
  int version_minor, format;
  bool feet = false, evlr = false;
  uint16_t extra_bytes = 0;
};
std::string CaseName(const ::testing::TestParamInfo<RewriteCase>& p) {
  const RewriteCase& c = p.param;
  return "Las1" + std::to_string(c.version_minor) + "Format" + std::to_string(c.format) + (c.feet ? "Feet" : "") + (c.evlr ? "Evlr" : "") +
         (c.extra_bytes ? "Extra" + std::to_string(c.extra_bytes) : "");
}

// Every byte of `out` equals `in` except the generating software and the classification bits of
// each record; returns the number of bytes compared exactly (header, VLRs, records, EVLRs).
size_t ExpectSameExceptClasses(const std::string& in, const std::string& out, const LasLayout& layout,
                               const std::vector<uint8_t>& classes_by_record) {
  EXPECT_EQ(out.size(), in.size());
  if (out.size() != in.size()) return 0;
  const bool extended = layout.info.point_format >= 6;
  const size_t class_byte = extended ? 16 : 15;
  const size_t len = layout.info.record_length;
  size_t compared = 0, mismatches = 0;
  for (size_t at = 0; at < in.size(); ++at) {
    if (at >= kLasGeneratingSoftwareOffset && at < kLasGeneratingSoftwareOffset + 32) continue;
    if (at >= layout.point_offset && at < layout.point_offset + layout.info.point_count * len &&
        (at - layout.point_offset) % len == class_byte) {
      const size_t r = (at - layout.point_offset) / len;
      const uint8_t got = static_cast<uint8_t>(out[at]), was = static_cast<uint8_t>(in[at]);
      if (extended) {
        EXPECT_EQ(got, classes_by_record[r]) << "record " << r;
      } else {
        EXPECT_EQ(got & 0x1F, classes_by_record[r]) << "record " << r;
        EXPECT_EQ(got & 0xE0, was & 0xE0) << "record " << r << ": synthetic / key-point / withheld flags";
      }
      continue;
    }
    ++compared;
    if (in[at] != out[at] && ++mismatches <= 5) ADD_FAILURE() << "byte " << at << " changed";
  }
  EXPECT_EQ(mismatches, 0u);
  EXPECT_EQ(std::string(out.data() + kLasGeneratingSoftwareOffset), kLasGeneratingSoftware);
  return compared;
}

class LasRewrite : public ::testing::TestWithParam<RewriteCase> {};

TEST_P(LasRewrite, OnlyTheClassificationChanges) {
  const RewriteCase c = GetParam();
  SyntheticLasSpec spec;
  spec.version_minor = c.version_minor;
  spec.format = c.format;
  spec.feet = c.feet;
  spec.evlr = c.evlr;
  spec.extra_bytes = c.extra_bytes;
  spec.points = 500;
  spec.seed = 100 + c.format;
  const std::string in = MakeSyntheticLas(spec);
  absl::StatusOr<LasLayout> layout = ParseLasLayout(in, "in.las");
  ASSERT_TRUE(layout.ok()) << layout.status();
  LasHeaderInfo info;
  absl::StatusOr<PointCloud> cloud = ParseLas(in, "in.las", {}, &info);
  ASSERT_TRUE(cloud.ok()) << cloud.status();
  ASSERT_EQ(cloud->size(), 500u);
  EXPECT_EQ(cloud->unit_to_metres, c.feet ? 0.3048 : 1.0);

  std::mt19937 rng(c.format);
  std::vector<uint8_t> classes(cloud->size());
  for (uint8_t& k : classes) k = static_cast<uint8_t>(rng() % (c.format >= 6 ? 256 : 32));
  LasReclassifyStats stats;
  absl::StatusOr<std::string> out = ReclassifyLas(in, "in.las", classes, cloud->record_index, &stats);
  ASSERT_TRUE(out.ok()) << out.status();
  EXPECT_EQ(stats.records, 500u);
  EXPECT_EQ(stats.patched, 500u);
  EXPECT_GT(stats.changed, 400u);  // random classes: most differ from the random source's
  const size_t compared = ExpectSameExceptClasses(in, *out, *layout, classes);
  EXPECT_EQ(compared, in.size() - 32 - 500);
  RecordProperty("bytes_compared", std::to_string(compared));

  // Read back: the same header, positions bit for bit, the new classes.
  LasHeaderInfo back_info;
  absl::StatusOr<PointCloud> back = ParseLas(*out, "out.las", {}, &back_info);
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(back_info.version_minor, info.version_minor);
  EXPECT_EQ(back_info.point_format, info.point_format);
  EXPECT_EQ(back_info.record_length, info.record_length);
  EXPECT_EQ(back_info.scale, info.scale);
  EXPECT_EQ(back_info.offset, info.offset);
  EXPECT_EQ(back_info.unit_source, info.unit_source);
  EXPECT_EQ(back->origin, cloud->origin);
  EXPECT_EQ(back->xyz, cloud->xyz);
  EXPECT_EQ(back->classification, classes);
  EXPECT_EQ(back->gps_time, cloud->gps_time);
  EXPECT_EQ(back->intensity, cloud->intensity);
}

INSTANTIATE_TEST_SUITE_P(Formats, LasRewrite,
                         ::testing::Values(RewriteCase{2, 0}, RewriteCase{2, 1}, RewriteCase{2, 2}, RewriteCase{2, 3},
                                           RewriteCase{2, 3, true}, RewriteCase{3, 4}, RewriteCase{3, 5, true},
                                           RewriteCase{4, 6}, RewriteCase{4, 7}, RewriteCase{4, 8}, RewriteCase{4, 9},
                                           RewriteCase{4, 10}, RewriteCase{4, 6, true, true}, RewriteCase{4, 8, false, true, 11},
                                           RewriteCase{4, 1, true, true}),
                         CaseName);

TEST(LasRewrite, RecordsTheReaderDroppedKeepTheirClass) {
  SyntheticLasSpec spec;
  spec.points = 300;
  spec.rejected = 4;
  std::vector<bool> rejected;
  const std::string in = MakeSyntheticLas(spec, nullptr, &rejected);
  absl::StatusOr<PointCloud> cloud = ParseLas(in, "in.las");
  ASSERT_TRUE(cloud.ok()) << cloud.status();
  ASSERT_EQ(cloud->size(), 296u);
  ASSERT_EQ(cloud->record_index.size(), 296u);
  std::vector<uint8_t> classes(cloud->size(), 2);
  absl::StatusOr<std::string> out = ReclassifyLas(in, "in.las", classes, cloud->record_index);
  ASSERT_TRUE(out.ok()) << out.status();
  absl::StatusOr<LasLayout> layout = ParseLasLayout(in, "in.las");
  std::vector<uint8_t> by_record(300);
  for (size_t r = 0; r < 300; ++r) by_record[r] = static_cast<uint8_t>(in[layout->point_offset + r * 30 + 16]);
  for (size_t k = 0; k < cloud->size(); ++k) by_record[cloud->record_index[k]] = 2;
  ExpectSameExceptClasses(in, *out, *layout, by_record);
  for (size_t r = 0; r < 300; ++r) {
    if (rejected[r]) {
      EXPECT_EQ(out->substr(layout->point_offset + r * 30, 30), in.substr(layout->point_offset + r * 30, 30));
    }
  }
}

// Found by the fuzzer: a file whose every record the reader drops gives an empty cloud; its
// rewrite patches nothing rather than refusing "0 classes for N records".
TEST(LasRewrite, AFileWithEveryRecordDroppedIsGivenBackUnchanged) {
  const std::string in = MakeSyntheticLas({.points = 3, .rejected = 3});
  absl::StatusOr<PointCloud> cloud = ParseLas(in, "in.las");
  ASSERT_TRUE(cloud.ok()) << cloud.status();
  ASSERT_EQ(cloud->size(), 0u);
  EXPECT_EQ(cloud->rejected_non_finite, 3u);
  LasReclassifyStats stats;
  absl::StatusOr<std::string> out = ReclassifyLas(in, "in.las", {}, cloud->record_index, &stats);
  ASSERT_TRUE(out.ok()) << out.status();
  EXPECT_EQ(stats.patched, 0u);
  EXPECT_EQ(out->substr(90), in.substr(90));
}

TEST(LasRewriteErrors, ClassAbove31InALegacyFormatNamesFileAndOffset) {
  SyntheticLasSpec spec;
  spec.version_minor = 2;
  spec.format = 3;
  spec.points = 10;
  const std::string in = MakeSyntheticLas(spec);
  std::vector<uint8_t> classes(10, 1);
  classes[4] = 40;
  const absl::Status s = ReclassifyLas(in, "old.las", classes).status();
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  const size_t point_offset = *reinterpret_cast<const uint32_t*>(in.data() + 96);
  EXPECT_THAT(std::string(s.message()), HasSubstr("old.las: byte offset " + std::to_string(point_offset + 4 * 34 + 15)));
  EXPECT_THAT(std::string(s.message()), HasSubstr("class 40 does not fit the 5 bits of point format 3"));
  std::string in_place = in;
  EXPECT_FALSE(ReclassifyLasInPlace(in_place, "old.las", classes).ok());
  EXPECT_TRUE(in_place == in);  // refused before any byte was patched
}

TEST(LasRewriteFiles, APlyInputBecomesANewLasFileInMetres) {
  const std::string dir = ::testing::TempDir() + "/ave_las_rewrite_ply_" + std::to_string(::getpid());
  std::filesystem::create_directories(dir);
  const std::string ply = dir + "/scan.ply", las = dir + "/scan.las";
  ASSERT_TRUE(WriteWholeFile(ply, "ply\nformat ascii 1.0\nelement vertex 3\nproperty double x\nproperty double y\n"
                                  "property double z\nproperty uchar classification\nend_header\n"
                                  "500000.5 4000000.25 10 1\n500001 4000001 11 1\n500002 4000002 12 1\n").ok());
  absl::StatusOr<PointCloud> cloud = ReadPointCloud(ply);
  ASSERT_TRUE(cloud.ok()) << cloud.status();
  EXPECT_EQ(cloud->source.format, "ply");
  absl::StatusOr<std::string> done = WriteClassifiedCloud(*cloud, {2, 6, 2}, las);
  ASSERT_TRUE(done.ok()) << done.status();
  EXPECT_THAT(*done, HasSubstr("new LAS 1.4 file (point format 6, metres) from the ply input"));
  LasHeaderInfo info;
  absl::StatusOr<PointCloud> back = ReadLas(las, {}, &info);
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(info.point_format, 6);
  EXPECT_EQ(back->classification, (std::vector<uint8_t>{2, 6, 2}));
  EXPECT_NEAR((back->origin + back->xyz[0].cast<double>() - Eigen::Vector3d(500000.5, 4000000.25, 10)).norm(), 0, 1e-3);
  std::filesystem::remove_all(dir);
}

TEST(LasRewriteErrors, CountsAndIndicesThatDoNotMatchTheFile) {
  const std::string in = MakeSyntheticLas({.points = 10});
  EXPECT_THAT(std::string(ReclassifyLas(in, "a.las", std::vector<uint8_t>(9, 2)).status().message()),
              HasSubstr("a.las: 9 classes for 10 point records"));
  EXPECT_THAT(std::string(ReclassifyLas(in, "b.las", {2, 2}, {3, 3}).status().message()), HasSubstr("b.las: point 1 maps to record 3"));
  EXPECT_THAT(std::string(ReclassifyLas(in, "c.las", {2}, {10}).status().message()), HasSubstr("the file holds 10"));
  EXPECT_THAT(std::string(ReclassifyLas(in.substr(0, 300), "d.las", {}).status().message()), HasSubstr("d.las: byte offset"));
}

TEST(LasRewriteFiles, RefusesASourceThatChangedSinceItWasRead) {
  const std::string dir = ::testing::TempDir() + "/ave_las_rewrite_" + std::to_string(::getpid());
  std::filesystem::create_directories(dir);
  const std::string src = dir + "/survey.las", dst = dir + "/classified.las";
  std::string in = MakeSyntheticLas({.points = 50, .feet = true});
  ASSERT_TRUE(WriteWholeFile(src, in).ok());
  absl::StatusOr<PointCloud> cloud = ReadPointCloud(src);
  ASSERT_TRUE(cloud.ok()) << cloud.status();
  EXPECT_EQ(cloud->source.path, src);
  const std::vector<uint8_t> classes(cloud->size(), 2);
  absl::StatusOr<std::string> done = WriteClassifiedCloud(*cloud, classes, dst);
  ASSERT_TRUE(done.ok()) << done.status();
  EXPECT_THAT(*done, HasSubstr("every other byte kept"));
  EXPECT_EQ(ReadWholeFile(dst)->size(), in.size());

  in[300] ^= 1;  // same size, one bit different
  ASSERT_TRUE(WriteWholeFile(src, in).ok());
  absl::Status s = WriteReclassifiedLas(*cloud, classes, dst);
  EXPECT_EQ(s.code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_THAT(std::string(s.message()), HasSubstr(src + ": changed since it was read"));
  in += "x";
  ASSERT_TRUE(WriteWholeFile(src, in).ok());
  EXPECT_THAT(std::string(WriteReclassifiedLas(*cloud, classes, dst).message()), HasSubstr("bytes then"));

  // Rewriting in place (out = source) goes through a temporary file.
  absl::StatusOr<PointCloud> again = ReadPointCloud(src);
  ASSERT_TRUE(again.ok()) << again.status();
  ASSERT_TRUE(WriteReclassifiedLas(*again, std::vector<uint8_t>(again->size(), 6), src).ok());
  EXPECT_EQ(ReadPointCloud(src)->classification, std::vector<uint8_t>(again->size(), 6));
  EXPECT_FALSE(WriteClassifiedCloud(*again, classes, dir + "/x.ply").ok());
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace ave::model
