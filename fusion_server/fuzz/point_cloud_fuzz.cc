// libFuzzer target: the PLY reader (ASCII, binary little and big endian) and the PCD header check
// that stands before PCL's reader (model_store/lidar/point_cloud_io.h, pcd_reader.cc), both for
// point clouds from outside (`ave-model build --input`). Issue 14 listed them as not fuzzed yet.
// Every input must be refused with a status or give a cloud whose attributes match its size, whose
// positions and origin are finite; the first byte picks the reader, so one corpus serves both.
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <string>
#include <string_view>

#include "model_store/lidar/point_cloud_io.h"

namespace {

void CheckCloud(const absl::StatusOr<ave::model::PointCloud>& cloud) {
  if (!cloud.ok()) {
    if (cloud.status().message().empty()) __builtin_trap();  // every refusal says why
    return;
  }
  const size_t n = cloud->size();
  if (!cloud->intensity.empty() && cloud->intensity.size() != n) __builtin_trap();
  if (!cloud->classification.empty() && cloud->classification.size() != n) __builtin_trap();
  if (!cloud->origin.allFinite()) __builtin_trap();
  for (const auto& p : cloud->xyz) {
    if (!p.allFinite()) __builtin_trap();
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  const std::string_view bytes(reinterpret_cast<const char*>(data) + 1, size - 1);
  if ((data[0] & 1) == 0) {
    CheckCloud(ave::model::ParsePly(bytes, "fuzz.ply"));
    return 0;
  }
  // PCD: the reader takes a path (PCL opens it), so the bytes go through a file of this process.
  static const std::string path = "/tmp/ave_fuzz_pcd_" + std::to_string(::getpid()) + ".pcd";
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (f == nullptr) return 0;
  std::fwrite(bytes.data(), 1, bytes.size(), f);
  std::fclose(f);
  CheckCloud(ave::model::ReadPcd(path));
  return 0;
}
