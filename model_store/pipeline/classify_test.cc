// Issue 14: `ave-model classify` on a survey gives the same file back with only the classification
// changed — every format, CRS in feet or metres, VLRs and an EVLR — through the library function
// the command uses and once through the ave-model binary itself. The inputs are synthetic LAS
// files written byte by byte (las_synthetic.h) with random values in every non-position field.
#include <unistd.h>

#include <cstdlib>
#include <filesystem>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "model_store/lidar/las_synthetic.h"
#include "model_store/lidar/read_file.h"
#include "model_store/pipeline/static_model.h"

namespace ave::model {
namespace {

using ::testing::HasSubstr;

class TempDir {
 public:
  TempDir() : path_(::testing::TempDir() + "/ave_classify_" + std::to_string(::getpid()) + "_" + std::to_string(next_++)) {
    std::filesystem::create_directories(path_);
  }
  ~TempDir() { std::filesystem::remove_all(path_); }
  std::string operator/(const std::string& name) const { return path_ + "/" + name; }

 private:
  static inline int next_ = 0;
  std::string path_;
};

struct ClassifyCase {
  int version_minor, format;
  bool feet = false, evlr = false;
};

class Classify : public ::testing::TestWithParam<ClassifyCase> {};

TEST_P(Classify, OnlyTheClassificationChangesAndGroundIsFound) {
  const ClassifyCase c = GetParam();
  SyntheticLasSpec spec{.version_minor = c.version_minor, .format = c.format, .points = 3000, .seed = 7u + c.format,
                        .feet = c.feet, .evlr = c.evlr, .extent = c.feet ? 90.0 : 40.0};
  std::vector<bool> terrain;
  const std::string in_bytes = MakeSyntheticLas(spec, &terrain);
  const TempDir dir;
  const std::string in = dir / "survey.las", out = dir / "classified.las";
  ASSERT_TRUE(WriteWholeFile(in, in_bytes).ok());

  absl::StatusOr<ClassifiedFile> done = ClassifyPointCloudFile(in, out, {}, StaticModelOptions{});
  ASSERT_TRUE(done.ok()) << done.status();
  EXPECT_EQ(done->cloud.unit_to_metres, c.feet ? 0.3048 : 1.0);
  absl::StatusOr<std::string> out_bytes = ReadWholeFile(out);
  ASSERT_TRUE(out_bytes.ok());
  const LasRewriteDiff diff = CompareLasExceptClasses(in_bytes, *out_bytes);
  ASSERT_TRUE(diff.same_size);
  EXPECT_EQ(diff.differing, 0u) << "first at byte " << diff.first_difference;
  EXPECT_EQ(diff.classes_after, done->model.point_class);
  RecordProperty("bytes_compared", std::to_string(diff.compared));

  // The classification did change, and where the synthetic terrain is, ground (2) was found.
  const LasRewriteDiff before = CompareLasExceptClasses(in_bytes, in_bytes);
  size_t changed = 0, terrain_points = 0, terrain_ground = 0, roof_points = 0, roof_ground = 0;
  for (size_t k = 0; k < diff.classes_after.size(); ++k) {
    changed += diff.classes_after[k] != before.classes_after[k];
    (terrain[k] ? terrain_points : roof_points) += 1;
    (terrain[k] ? terrain_ground : roof_ground) += diff.classes_after[k] == 2;
  }
  RecordProperty("classes_changed", std::to_string(changed));
  RecordProperty("terrain_ground", std::to_string(terrain_ground) + "/" + std::to_string(terrain_points));
  RecordProperty("roof_ground", std::to_string(roof_ground) + "/" + std::to_string(roof_points));
  EXPECT_GT(changed, diff.classes_after.size() / 2);
  EXPECT_GE(terrain_ground, 0.9 * terrain_points);
  EXPECT_LE(roof_ground, 0.1 * roof_points);
}

INSTANTIATE_TEST_SUITE_P(Formats, Classify,
                         ::testing::Values(ClassifyCase{2, 0}, ClassifyCase{2, 1}, ClassifyCase{2, 2}, ClassifyCase{2, 3},
                                           ClassifyCase{2, 3, true}, ClassifyCase{4, 6}, ClassifyCase{4, 7}, ClassifyCase{4, 8},
                                           ClassifyCase{4, 6, false, true}, ClassifyCase{4, 7, true, true}));

// The binary: `ave-model classify` writes exactly what the library function writes.
TEST(ClassifyCommand, TheBinaryGivesTheSurveyBackWithOnlyItsClassesChanged) {
  const std::string in_bytes = MakeSyntheticLas({.version_minor = 2, .format = 3, .points = 3000, .feet = true, .extent = 90});
  const TempDir dir;
  const std::string in = dir / "oregon_ft.las", out = dir / "by_binary.las", lib_out = dir / "by_library.las";
  ASSERT_TRUE(WriteWholeFile(in, in_bytes).ok());
  const std::string command = std::string(AVE_MODEL_BIN) + " classify --quiet --input " + in + " --out " + out + " >" + (dir / "stdout") +
                              " 2>" + (dir / "stderr");
  ASSERT_EQ(std::system(command.c_str()), 0) << *ReadWholeFile(dir / "stderr");
  EXPECT_THAT(*ReadWholeFile(dir / "stderr"), HasSubstr("every other byte kept"));
  EXPECT_THAT(*ReadWholeFile(dir / "stdout"), HasSubstr("\"points\":3000"));
  absl::StatusOr<std::string> out_bytes = ReadWholeFile(out);
  ASSERT_TRUE(out_bytes.ok());
  const LasRewriteDiff diff = CompareLasExceptClasses(in_bytes, *out_bytes);
  ASSERT_TRUE(diff.same_size);
  EXPECT_EQ(diff.differing, 0u) << "first at byte " << diff.first_difference;
  ASSERT_TRUE(ClassifyPointCloudFile(in, lib_out, {}, StaticModelOptions{}).ok());
  EXPECT_TRUE(*ReadWholeFile(lib_out) == *out_bytes);

  // A bad output name is refused before anything is written, naming it.
  const std::string bad = std::string(AVE_MODEL_BIN) + " classify --quiet --input " + in + " --out " + (dir / "x.ply") + " 2>" + (dir / "err2");
  EXPECT_NE(std::system(bad.c_str()), 0);
  EXPECT_THAT(*ReadWholeFile(dir / "err2"), HasSubstr("x.ply"));
  EXPECT_FALSE(std::filesystem::exists(dir / "x.ply"));
}

}  // namespace
}  // namespace ave::model
