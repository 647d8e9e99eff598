#pragma once
// Reading any supported point cloud file into a PointCloud (MISSION part A): LAS (las.h), PLY
// (ascii / binary little- or big-endian, vertex x y z as float or double, optional intensity and
// classification), PCD (through PCL, in pcd_reader.cc only). Points with NaN/inf coordinates
// are dropped and counted in PointCloud::rejected_non_finite.
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/statusor.h"

#include "model_store/lidar/las.h"
#include "model_store/lidar/point_cloud.h"

namespace ave::model {

struct CloudReadOptions {
  std::optional<double> unit_to_metres;  // overrides the unit the file declares (LAS) or metres
};

// By extension (case-insensitive): .las, .ply, .pcd. The unit used is in cloud.unit_name.
absl::StatusOr<PointCloud> ReadPointCloud(const std::string& path, const CloudReadOptions& options = {});

// Writes the classes computed for `cloud` (one per point) to `out_path`, which must end in .las.
// A cloud read from a LAS file: that file, re-read and rewritten with only its classification
// changed (las_rewrite.h: same version, format, scale, offset, unit, VLRs/EVLRs and every other
// record byte; refused if the file changed since it was read). A cloud from PLY or PCD: a new
// LAS 1.4 file, point format 6, metres, scale 1 mm, no CRS VLR (those inputs carry none we
// read), positions and the attributes the reader kept. Returns one line saying which was done.
absl::StatusOr<std::string> WriteClassifiedCloud(const PointCloud& cloud, const std::vector<uint8_t>& classification,
                                                 const std::string& out_path);

absl::StatusOr<PointCloud> ParsePly(std::string_view bytes, const std::string& name, const CloudReadOptions& options = {});
// PCD through PCL; Unimplemented when this build has no PCL.
absl::StatusOr<PointCloud> ReadPcd(const std::string& path, const CloudReadOptions& options = {});
bool HavePcdSupport();

// A file's intensity or class value as the cloud's integer field: clamped to [0, hi], and 0 where
// the file says NaN (a cast of NaN to an integer is undefined; the fuzz smoke found a PLY with one).
inline double FieldInRange(double v, double hi) { return v >= 0 ? (v <= hi ? v : hi) : 0.0; }

// Turns world positions (metres, double) into a cloud under a whole-metre local origin taken
// from the first finite point; NaN/inf points are dropped and counted. Used by the PLY and PCD
// readers and by tests that build clouds far from zero.
class CloudBuilder {
 public:
  explicit CloudBuilder(double unit_to_metres = 1.0, std::string unit_name = "metre");
  // Returns the index of the new point, or -1 when it was rejected.
  int64_t Add(const Eigen::Vector3d& p_in_file_units);
  PointCloud& cloud() { return cloud_; }
  PointCloud Take() { return std::move(cloud_); }

 private:
  PointCloud cloud_;
  bool have_origin_ = false;
};

}  // namespace ave::model
