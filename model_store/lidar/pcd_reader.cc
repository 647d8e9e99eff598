// PCD through PCL: the only file of model_store that includes PCL headers (BUILD_NOTES.md: keep
// them out of widely included headers). Coordinates are read as stored (float32 or float64), so a
// double-precision PCD keeps large world coordinates exact.
#include <algorithm>
#include <cstring>

#include "model_store/lidar/point_cloud_io.h"

#ifdef AVE_HAVE_PCL
#include <pcl/PCLPointCloud2.h>
#include <pcl/io/pcd_io.h>
#endif

namespace ave::model {

#ifdef AVE_HAVE_PCL
namespace {

const pcl::PCLPointField* FindField(const pcl::PCLPointCloud2& blob, const std::string& name) {
  for (const auto& f : blob.fields) {
    if (f.name == name) return &f;
  }
  return nullptr;
}

double FieldValue(const uint8_t* p, const pcl::PCLPointField& f) {
  auto as = [p]<typename T>(T) { T v; std::memcpy(&v, p, sizeof(T)); return static_cast<double>(v); };
  switch (f.datatype) {
    case pcl::PCLPointField::INT8: return as(int8_t{});
    case pcl::PCLPointField::UINT8: return as(uint8_t{});
    case pcl::PCLPointField::INT16: return as(int16_t{});
    case pcl::PCLPointField::UINT16: return as(uint16_t{});
    case pcl::PCLPointField::INT32: return as(int32_t{});
    case pcl::PCLPointField::UINT32: return as(uint32_t{});
    case pcl::PCLPointField::FLOAT64: return as(double{});
    default: return as(float{});
  }
}

}  // namespace

bool HavePcdSupport() { return true; }

absl::StatusOr<PointCloud> ReadPcd(const std::string& path, const CloudReadOptions& options) {
  pcl::PCLPointCloud2 blob;
  pcl::PCDReader reader;
  if (reader.read(path, blob) < 0) return absl::InvalidArgumentError(path + ": PCL could not read this PCD file");
  const pcl::PCLPointField* fx = FindField(blob, "x");
  const pcl::PCLPointField* fy = FindField(blob, "y");
  const pcl::PCLPointField* fz = FindField(blob, "z");
  if (!fx || !fy || !fz) return absl::InvalidArgumentError(path + ": PCD lacks an x, y or z field");
  const pcl::PCLPointField* fi = FindField(blob, "intensity");
  const size_t n = static_cast<size_t>(blob.width) * blob.height;
  if (blob.data.size() < n * blob.point_step) return absl::InvalidArgumentError(path + ": PCD data shorter than its header says");
  CloudBuilder builder(options.unit_to_metres.value_or(1.0), options.unit_to_metres ? "override" : "metre");
  for (size_t k = 0; k < n; ++k) {
    const uint8_t* p = blob.data.data() + k * blob.point_step;
    if (builder.Add({FieldValue(p + fx->offset, *fx), FieldValue(p + fy->offset, *fy), FieldValue(p + fz->offset, *fz)}) < 0) continue;
    if (fi) builder.cloud().intensity.push_back(static_cast<uint16_t>(std::clamp(FieldValue(p + fi->offset, *fi), 0.0, 65535.0)));
  }
  return builder.Take();
}

#else

bool HavePcdSupport() { return false; }

absl::StatusOr<PointCloud> ReadPcd(const std::string& path, const CloudReadOptions&) {
  return absl::UnimplementedError(path + ": this build has no PCL, so PCD files cannot be read");
}

#endif

}  // namespace ave::model
