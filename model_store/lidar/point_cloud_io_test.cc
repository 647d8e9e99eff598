#include "model_store/lidar/point_cloud_io.h"

#include <cstdio>
#include <cstring>
#include <fstream>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "model_store/lidar/read_file.h"

namespace ave::model {
namespace {

using ::testing::HasSubstr;

TEST(Ply, AsciiRejectsAndCountsNonFinitePoints) {
  const std::string ply =
      "ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\nproperty float z\n"
      "property uchar intensity\nend_header\n"
      "1 2 3 10\nnan 2 3 11\n4 inf 6 12\n7 8 9 13\n1 1 -inf 14\n";
  absl::StatusOr<PointCloud> cloud = ParsePly(ply, "a.ply");
  ASSERT_TRUE(cloud.ok()) << cloud.status();
  EXPECT_EQ(cloud->size(), 2u);
  EXPECT_EQ(cloud->rejected_non_finite, 3u);
  ASSERT_EQ(cloud->intensity.size(), 2u);
  EXPECT_EQ(cloud->intensity[1], 13);
  EXPECT_EQ(cloud->origin + cloud->xyz[1].cast<double>(), Eigen::Vector3d(7, 8, 9));
}

// A float intensity or class that is NaN, negative or too large becomes 0 or the field's largest
// value (the fuzz smoke's finding: NaN cast to an integer is undefined behaviour).
TEST(Ply, NanAndOutOfRangeIntensitiesAndClassesAreClamped) {
  const std::string ply =
      "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
      "property float intensity\nproperty float classification\nend_header\n"
      "1 2 3 nan nan\n1 2 4 -5 -1\n1 2 5 70000 300\n1 2 6 12.5 6\n";
  absl::StatusOr<PointCloud> cloud = ParsePly(ply, "c.ply");
  ASSERT_TRUE(cloud.ok()) << cloud.status();
  ASSERT_EQ(cloud->size(), 4u);
  EXPECT_EQ(cloud->intensity, (std::vector<uint16_t>{0, 0, 65535, 12}));
  EXPECT_EQ(cloud->classification, (std::vector<uint8_t>{0, 0, 255, 6}));
}

TEST(Ply, BinaryDoublesNear1e7KeepMillimetres) {
  std::string ply = "ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty double x\nproperty double y\nproperty double z\nend_header\n";
  const double pts[6] = {4512345.678, 12345678.901, 250.004, 4512346.679, 12345679.902, 251.005};
  ply.append(reinterpret_cast<const char*>(pts), sizeof(pts));
  absl::StatusOr<PointCloud> cloud = ParsePly(ply, "b.ply");
  ASSERT_TRUE(cloud.ok()) << cloud.status();
  ASSERT_EQ(cloud->size(), 2u);
  const Eigen::Vector3d p1 = cloud->origin + cloud->xyz[1].cast<double>();
  EXPECT_NEAR(p1.x(), 4512346.679, 1e-4);
  EXPECT_NEAR(p1.y(), 12345679.902, 1e-4);
  // Truncated: one vertex short.
  absl::Status cut = ParsePly(ply.substr(0, ply.size() - 8), "c.ply").status();
  EXPECT_THAT(std::string(cut.message()), HasSubstr("c.ply: byte offset"));
}

// Issue 14: every header mistake and every body mistake names the file.
TEST(Ply, BadHeadersAndBodiesNameTheFile) {
  const std::string head = "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n";
  struct Case {
    std::string bytes;
    const char* names;
  };
  for (const Case& c : std::vector<Case>{
           {"", "d.ply: byte offset 0: not a PLY file"},
           {"PLY\n", "d.ply: byte offset 0: not a PLY file"},
           {"ply\nformat ascii 1.0\nelement vertex 1\n", "d.ply: no end_header line"},
           {"ply\nformat ascii 1.0\nend_header", "d.ply: byte offset"},
           {"ply\nformat utf8 1.0\nelement vertex 1\nproperty float x\nend_header\n", "d.ply: unknown PLY format 'utf8'"},
           {"ply\nformat ascii 1.0\nelement vertex 1\nproperty half x\nend_header\n", "d.ply: unknown PLY property type 'half'"},
           {"ply\nformat ascii 1.0\nelement face 1\nend_header\n", "d.ply: the first PLY element must be 'vertex'"},
           {"ply\nformat ascii 1.0\nelement vertex 1\nproperty list uchar int i\nproperty float x\nend_header\n",
            "d.ply: list properties"},
           {"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n1 2\n",
            "d.ply: PLY vertex element lacks x, y or z"},
           {head + "1 2 3\n", "d.ply: vertex 1 of 2: truncated"},
           {head + "1 2 3\n4 five 6\n", "d.ply: vertex 1: not a number 'five'"},
           {head + "1 2 3\n4 5 6e\n", "d.ply: vertex 1: not a number '6e'"},
           {"ply\nformat binary_little_endian 1.0\nelement vertex 4000000000\nproperty double x\nproperty double y\n"
            "property double z\nend_header\n" + std::string(48, '\0'),
            "d.ply: byte offset"},
       }) {
    SCOPED_TRACE(c.bytes.substr(0, 60));
    EXPECT_THAT(std::string(ParsePly(c.bytes, "d.ply").status().message()), HasSubstr(c.names));
  }
  EXPECT_THAT(std::string(ReadPointCloud("/nonexistent-dir/x.ply").status().message()), HasSubstr("/nonexistent-dir/x.ply"));
}

TEST(PointCloudIo, DispatchesByExtensionAndNamesUnknownOnes) {
  EXPECT_THAT(std::string(ReadPointCloud("/tmp/x.xyz").status().message()), HasSubstr("unknown point cloud extension"));
  EXPECT_THAT(std::string(ReadPointCloud("/tmp/x.laz").status().message()), HasSubstr("LAZ"));
}

TEST(PointCloudIo, ReadsPcdThroughPcl) {
  if (!HavePcdSupport()) GTEST_SKIP() << "built without PCL";
  const std::string path = ::testing::TempDir() + "/ave_cloud.pcd";
  ASSERT_TRUE(WriteWholeFile(path,
                             "VERSION .7\nFIELDS x y z intensity\nSIZE 8 8 8 4\nTYPE F F F F\nCOUNT 1 1 1 1\n"
                             "WIDTH 3\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 3\nDATA ascii\n"
                             "384500.125 3768200.5 85.25 7\nnan 0 0 1\n384501.125 3768201.5 86.25 9\n")
                  .ok());
  absl::StatusOr<PointCloud> cloud = ReadPointCloud(path);
  ASSERT_TRUE(cloud.ok()) << cloud.status();
  ASSERT_EQ(cloud->size(), 2u);
  EXPECT_EQ(cloud->rejected_non_finite, 1u);
  EXPECT_NEAR((cloud->origin + cloud->xyz[1].cast<double>()).y(), 3768201.5, 1e-4);
  std::remove(path.c_str());
}

TEST(PointCloudIo, BadPcdFilesNameTheFile) {
  if (!HavePcdSupport()) GTEST_SKIP() << "built without PCL";
  const std::string path = ::testing::TempDir() + "/ave_bad_cloud.pcd";
  for (const std::string& text : {std::string("not a point cloud at all\n"), std::string(""),
                                  std::string("VERSION .7\nFIELDS a b\nSIZE 4 4\nTYPE F F\nCOUNT 1 1\nWIDTH 1\nHEIGHT 1\n"
                                              "VIEWPOINT 0 0 0 1 0 0 0\nPOINTS 1\nDATA ascii\n1 2\n"),
                                  std::string("VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 0\n"
                                              "HEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 0\nDATA ascii\n"),
                                  std::string("VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 2\n"
                                              "HEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 2\nDATA ascii\n1 2 3\n"),
                                  std::string("VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 1000\n"
                                              "HEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 1000\nDATA binary\n\x01\x02"),
                                  // SIZE 2 with TYPE F: PCL lays the field out 2 bytes wide; reading
                                  // it as a float ran past the point (ave_fuzz_point_cloud).
                                  std::string("VERSION 0.7\nFIELDS x y z intensity\nSIZE 4 4 4 2\nTYPE F F F F\n"
                                              "COUNT 1 1 1 1\nWIDTH 2\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 2\n"
                                              "DATA ascii\n1 2 3 4\n5 6 7 8\n"),
                                  // COUNT 0: PCL sized its buffer from a wrapped point size (4 GiB).
                                  std::string("VERSION 0.7\nFIELDS x y z\nSIZE 8 8 8\nTYPE F F F\nCOUNT 2 1 0\n"
                                              "WIDTH 2\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 2\nDATA ascii\n1 2 3 4\n"),
                                  // WIDTH x HEIGHT (what PCL reads) disagreeing with POINTS.
                                  std::string("VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
                                              "WIDTH 3000000\nHEIGHT 1000\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 1\nDATA ascii\n1 2 3\n"),
                                  // Binary data whose first bytes spell a header keyword: PCL read
                                  // on past DATA, re-laid its fields and crashed (ave_fuzz_point_cloud, CI).
                                  std::string("FIELDS x y z\nSIZE 8 8 8\nTYPE F F F\nWIDTH 2\nPOINTS 2\nDATA binary\n"
                                              "COLUMNS.") + std::string(40, '\x01')}) {
    SCOPED_TRACE(text.substr(0, 40));
    ASSERT_TRUE(WriteWholeFile(path, text).ok());
    absl::StatusOr<PointCloud> cloud = ReadPointCloud(path);
    EXPECT_FALSE(cloud.ok());
    EXPECT_THAT(std::string(cloud.status().message()), HasSubstr(path));
  }
  EXPECT_THAT(std::string(ReadPointCloud("/nonexistent-dir/x.pcd").status().message()), HasSubstr("/nonexistent-dir/x.pcd"));
  std::remove(path.c_str());
}

}  // namespace
}  // namespace ave::model
