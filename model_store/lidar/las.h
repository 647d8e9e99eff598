#pragma once
// ASPRS LAS 1.2-1.4 reader and writer (MISSION part A, AVE §4.1 input): uncompressed point data
// record formats 0-10 (4, 5, 9 and 10 carry wave packet descriptors, read past), scale/offset honoured, positions returned under a double-precision
// local origin so survey coordinates near 1e6-1e7 m keep millimetres.
//
// Linear unit: the file's CRS decides (OGC WKT VLR `UNIT[...]` / `LENGTHUNIT[...]`, or the GeoTIFF
// GeoKeyDirectory VLR's ProjLinearUnitsGeoKey 3076 / VerticalUnitsGeoKey 4099); coordinates come out
// in metres. `LasReadOptions::unit_to_metres` overrides it (the `--units` flag).
//
// Every rejected file gets an InvalidArgument/DataLoss status naming the file and the byte offset
// of the field that is wrong: truncated header or VLR, a point count or record length that does
// not fit the file, an unknown point format, a zero or non-finite scale.
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>
#include "absl/status/status.h"
#include "absl/status/statusor.h"

#include "model_store/lidar/point_cloud.h"

namespace ave::model {

struct LasReadOptions {
  std::optional<double> unit_to_metres;  // overrides the CRS unit (e.g. 0.3048 for feet)
};

// What the header said (for summaries and for writing a file back in the same shape).
struct LasHeaderInfo {
  uint8_t version_minor = 0;  // 2, 3 or 4 (major is always 1)
  uint8_t point_format = 0;
  uint16_t record_length = 0;
  uint64_t point_count = 0;
  Eigen::Vector3d scale = Eigen::Vector3d::Zero(), offset = Eigen::Vector3d::Zero();  // file units
  std::string unit_source;  // "wkt", "geotiff", "override" or "default"
};

// Where things are in a LAS file, after every header check ParseLas makes (the rewriter in
// las_rewrite.h patches records in place from it).
struct LasLayout {
  LasHeaderInfo info;
  uint16_t header_size = 0;
  uint32_t point_offset = 0;    // first point record
  uint32_t vlr_count = 0;
  uint64_t evlr_start = 0;      // 0: none (or LAS < 1.4)
  size_t vlrs_end = 0;          // first byte after the last VLR (<= point_offset)
};
// Checks the header and VLR chain of a whole LAS file held in memory; errors as ParseLas.
absl::StatusOr<LasLayout> ParseLasLayout(std::string_view bytes, const std::string& name);
// Bytes of the standard fields of a point data record format (0-10); 0 = unknown.
uint16_t LasBaseRecordLength(int format);

// Parses a whole LAS file held in memory; `name` is used in error messages.
absl::StatusOr<PointCloud> ParseLas(std::string_view bytes, const std::string& name, const LasReadOptions& options = {},
                                    LasHeaderInfo* info = nullptr);
absl::StatusOr<PointCloud> ReadLas(const std::string& path, const LasReadOptions& options = {},
                                   LasHeaderInfo* info = nullptr);

// Linear unit named by an OGC WKT string (WKT1 UNIT["US survey foot",0.3048006096012192] or WKT2
// LENGTHUNIT[...]): metres per unit and its name; nullopt when the text names no linear unit.
std::optional<std::pair<double, std::string>> LinearUnitFromWkt(std::string_view wkt);
// Metres per unit of an EPSG linear unit code (9001 metre, 9002 foot, 9003 US survey foot, ...).
std::optional<std::pair<double, std::string>> LinearUnitFromEpsg(int code);

struct LasWriteOptions {
  uint8_t version_minor = 4;   // 2, 3 or 4
  uint8_t point_format = 6;    // 0-10 (wave packet and colour fields written as zeros)
  uint16_t extra_bytes = 0;    // appended to each record (zeros), to exercise record_length
  double scale = 0.001;        // file units per integer step
  double unit_to_metres = 1;   // the file's unit: coordinates are written divided by it
  std::string wkt;             // non-empty: an OGC WKT VLR (record 2112) is written
  std::optional<int> geotiff_linear_unit;  // EPSG unit code: a GeoKeyDirectory VLR (34735)
};

// Writes `cloud` (world = origin + xyz, metres) as a NEW uncompressed LAS file: for clouds that
// did not come from a LAS file (PLY, PCD, synthetic). A LAS input is rewritten with
// ReclassifyLas (las_rewrite.h), which keeps every byte but the classification. `classification` overrides
// the cloud's own classes when non-empty (one per point). Attributes the cloud lacks are zero.
absl::Status WriteLas(const PointCloud& cloud, const std::vector<uint8_t>& classification, const std::string& path,
                      const LasWriteOptions& options = {});
absl::StatusOr<std::string> EncodeLas(const PointCloud& cloud, const std::vector<uint8_t>& classification,
                                      const LasWriteOptions& options = {});

}  // namespace ave::model
