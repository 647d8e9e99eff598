#include "model_store/lidar/las.h"

#include <cstring>
#include <random>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace ave::model {
namespace {

using ::testing::HasSubstr;

// A small cloud far from zero: world = origin + xyz.
PointCloud MakeCloud(const Eigen::Vector3d& origin, int n = 50) {
  PointCloud cloud;
  cloud.origin = origin;
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(-50, 50);
  for (int i = 0; i < n; ++i) {
    cloud.xyz.emplace_back(u(rng), u(rng), u(rng) * 0.2f);
    cloud.intensity.push_back(static_cast<uint16_t>(100 * i));
    cloud.classification.push_back(static_cast<uint8_t>(i % 7));
    cloud.point_source_id.push_back(static_cast<uint16_t>(i));
    cloud.return_number.push_back(1);
    cloud.number_of_returns.push_back(2);
    cloud.gps_time.push_back(1000.25 + i);
  }
  return cloud;
}

struct FormatCase {
  int version_minor, format;
  double origin_scale;  // 1e6 or 1e7 m
};

class LasRoundTrip : public ::testing::TestWithParam<FormatCase> {};

TEST_P(LasRoundTrip, PositionsAndAttributesSurviveFarFromZero) {
  const FormatCase c = GetParam();
  const Eigen::Vector3d origin(3.5 * c.origin_scale / 10 + 0.25, c.origin_scale + 0.5, 120.0);
  const PointCloud cloud = MakeCloud(origin);
  LasWriteOptions w;
  w.version_minor = static_cast<uint8_t>(c.version_minor);
  w.point_format = static_cast<uint8_t>(c.format);
  absl::StatusOr<std::string> bytes = EncodeLas(cloud, {}, w);
  ASSERT_TRUE(bytes.ok()) << bytes.status();
  LasHeaderInfo info;
  absl::StatusOr<PointCloud> read = ParseLas(*bytes, "mem.las", {}, &info);
  ASSERT_TRUE(read.ok()) << read.status();
  EXPECT_EQ(info.point_format, c.format);
  EXPECT_EQ(info.version_minor, c.version_minor);
  ASSERT_EQ(read->size(), cloud.size());
  for (size_t i = 0; i < cloud.size(); ++i) {
    const Eigen::Vector3d want = cloud.origin + cloud.xyz[i].cast<double>();
    const Eigen::Vector3d got = read->origin + read->xyz[i].cast<double>();
    EXPECT_LT((want - got).cwiseAbs().maxCoeff(), 6e-4) << "point " << i;  // scale 1 mm
    // Local coordinates stay small (the origin absorbs the 1e6-1e7 m).
    EXPECT_LT(read->xyz[i].cwiseAbs().maxCoeff(), 100.f);
    EXPECT_EQ(read->intensity[i], cloud.intensity[i]);
    EXPECT_EQ(read->classification[i], cloud.classification[i]);
    EXPECT_EQ(read->point_source_id[i], cloud.point_source_id[i]);
    EXPECT_EQ(read->return_number[i], 1);
    EXPECT_EQ(read->number_of_returns[i], 2);
    if (c.format != 0 && c.format != 2) {
      EXPECT_EQ(read->gps_time[i], cloud.gps_time[i]);
    }
  }
  EXPECT_EQ(read->unit_name, "metre");
}

INSTANTIATE_TEST_SUITE_P(Formats, LasRoundTrip,
                         ::testing::Values(FormatCase{2, 0, 1e6}, FormatCase{2, 1, 1e6}, FormatCase{3, 2, 1e6},
                                           FormatCase{3, 3, 1e7}, FormatCase{4, 1, 1e7}, FormatCase{4, 6, 1e6},
                                           FormatCase{4, 7, 1e7}, FormatCase{4, 8, 1e7}));

TEST(Las, ExtraBytesPerRecordAreSkipped) {
  const PointCloud cloud = MakeCloud({1e6, 2e6, 0});
  LasWriteOptions w;
  w.extra_bytes = 9;
  absl::StatusOr<PointCloud> read = ParseLas(*EncodeLas(cloud, {}, w), "x.las");
  ASSERT_TRUE(read.ok()) << read.status();
  ASSERT_EQ(read->size(), cloud.size());
  EXPECT_EQ(read->gps_time.back(), cloud.gps_time.back());
}

TEST(Las, WktUsSurveyFeetBecomeMetres) {
  const PointCloud cloud = MakeCloud({6e6 * 0.3048, 2e6 * 0.3048, 30});
  LasWriteOptions w;
  const double ft = 1200.0 / 3937.0;
  w.unit_to_metres = ft;
  w.wkt = "PROJCS[\"NAD83 / California zone 5 (ftUS)\",GEOGCS[\"NAD83\",DATUM[\"North_American_Datum_1983\"],"
          "UNIT[\"degree\",0.0174532925199433]],PROJECTION[\"Lambert_Conformal_Conic_2SP\"],"
          "UNIT[\"US survey foot\",0.304800609601219,AUTHORITY[\"EPSG\",\"9003\"]]]";
  LasHeaderInfo info;
  absl::StatusOr<PointCloud> read = ParseLas(*EncodeLas(cloud, {}, w), "ft.las", {}, &info);
  ASSERT_TRUE(read.ok()) << read.status();
  EXPECT_EQ(info.unit_source, "wkt");
  EXPECT_EQ(read->unit_name, "US survey foot");
  EXPECT_NEAR(read->unit_to_metres, ft, 1e-12);
  for (size_t i = 0; i < cloud.size(); ++i) {
    EXPECT_LT(((read->origin + read->xyz[i].cast<double>()) - (cloud.origin + cloud.xyz[i].cast<double>())).norm(), 1e-3);
  }
}

TEST(Las, GeoTiffFootKeyBecomesMetresAndOverrideWins) {
  const PointCloud cloud = MakeCloud({1e6, 1e6, 0});
  LasWriteOptions w;
  w.unit_to_metres = 0.3048;
  w.geotiff_linear_unit = 9002;
  const std::string bytes = *EncodeLas(cloud, {}, w);
  LasHeaderInfo info;
  absl::StatusOr<PointCloud> read = ParseLas(bytes, "ft.las", {}, &info);
  ASSERT_TRUE(read.ok()) << read.status();
  EXPECT_EQ(info.unit_source, "geotiff");
  EXPECT_EQ(read->unit_name, "foot");
  EXPECT_LT(((read->origin + read->xyz[3].cast<double>()) - (cloud.origin + cloud.xyz[3].cast<double>())).norm(), 1e-3);
  // --units metre: the numbers are taken as metres, so distances grow by 1/0.3048.
  absl::StatusOr<PointCloud> forced = ParseLas(bytes, "ft.las", LasReadOptions{1.0}, &info);
  ASSERT_TRUE(forced.ok());
  EXPECT_EQ(info.unit_source, "override");
  EXPECT_NEAR((forced->xyz[3] - forced->xyz[4]).norm(), (cloud.xyz[3] - cloud.xyz[4]).norm() / 0.3048, 1e-2);
}

TEST(Las, LinearUnitFromWktSkipsAngularUnits) {
  EXPECT_FALSE(LinearUnitFromWkt("GEOGCS[\"WGS 84\",UNIT[\"degree\",0.0174532925199433]]").has_value());
  auto unit = LinearUnitFromWkt("PROJCRS[\"x\",BASEGEOGCRS[\"y\",ANGLEUNIT[\"degree\",0.01745]],LENGTHUNIT[\"foot\",0.3048]]");
  ASSERT_TRUE(unit.has_value());
  EXPECT_DOUBLE_EQ(unit->first, 0.3048);
}

// --- bad files: each error names the file and a byte offset ---

std::string GoodFile() { return *EncodeLas(MakeCloud({5e5, 4e6, 10}, 20), {}, {}); }

TEST(LasErrors, TruncatedPointDataNamesFileAndOffset) {
  std::string b = GoodFile();
  b.resize(b.size() - 7);
  absl::Status s = ParseLas(b, "cut.las").status();
  EXPECT_THAT(std::string(s.message()), HasSubstr("cut.las: byte offset " + std::to_string(b.size())));
  EXPECT_THAT(std::string(s.message()), HasSubstr("truncated"));
}

TEST(LasErrors, TruncatedHeader) {
  std::string b = GoodFile().substr(0, 100);
  absl::Status s = ParseLas(b, "h.las").status();
  EXPECT_THAT(std::string(s.message()), HasSubstr("h.las: byte offset 100: truncated header"));
}

TEST(LasErrors, PointCountLies) {
  std::string b = GoodFile();
  uint64_t more = 21, fewer = 18;
  std::string up = b, down = b;
  std::memcpy(up.data() + 247, &more, 8);
  std::memcpy(down.data() + 247, &fewer, 8);
  EXPECT_THAT(std::string(ParseLas(up, "up.las").status().message()), HasSubstr("declares 21 points"));
  EXPECT_THAT(std::string(ParseLas(down, "down.las").status().message()), HasSubstr("declares 18 points but 20 records"));
}

TEST(LasErrors, RecordLengthAndFormat) {
  std::string b = GoodFile();
  std::string short_record = b, unknown = b, laz = b;
  const uint16_t len = 20;
  std::memcpy(short_record.data() + 105, &len, 2);
  EXPECT_THAT(std::string(ParseLas(short_record, "r.las").status().message()), HasSubstr("r.las: byte offset 105"));
  unknown[104] = 11;
  EXPECT_THAT(std::string(ParseLas(unknown, "f.las").status().message()),
              HasSubstr("f.las: byte offset 104: unknown or unsupported point data record format 11"));
  laz[104] = static_cast<char>(0x86);
  EXPECT_THAT(std::string(ParseLas(laz, "z.las").status().message()), HasSubstr("LAZ"));
}

TEST(LasErrors, ZeroScaleAndBadSignature) {
  std::string b = GoodFile();
  std::string zero = b;
  const double z = 0;
  std::memcpy(zero.data() + 139, &z, 8);
  EXPECT_THAT(std::string(ParseLas(zero, "s.las").status().message()), HasSubstr("byte offset 139"));
  EXPECT_THAT(std::string(ParseLas("PK\x03\x04 not a las", "zip.las").status().message()), HasSubstr("not a LAS file"));
  EXPECT_THAT(std::string(ReadLas("/nonexistent/x.las").status().message()), HasSubstr("/nonexistent/x.las"));
}

// Found by the fuzzer: finite header fields whose origin overflows once scaled by the linear unit
// are refused with the file's name, not accepted with an infinite origin.
TEST(LasErrors, OriginThatOverflowsIsRefused) {
  LasReadOptions options;
  options.unit_to_metres = 1e305;  // x offset ~5e5 units: 5e310 m
  const absl::Status s = ParseLas(GoodFile(), "huge.las", options).status();
  EXPECT_FALSE(s.ok());
  EXPECT_THAT(std::string(s.message()), HasSubstr("huge.las: the local origin"));
}

}  // namespace
}  // namespace ave::model
