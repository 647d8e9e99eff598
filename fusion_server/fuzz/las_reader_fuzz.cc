// libFuzzer target: the LAS 1.2-1.4 reader (model_store/lidar/las.h), which reads survey files from
// outside (issue 8 asked for it; issue 4 wrote the reader). Every input must either be refused
// with a status or give a cloud whose attributes match its size and whose positions are finite;
// an accepted cloud must encode back to LAS and parse again to the same number of points.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "model_store/lidar/las.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  absl::StatusOr<ave::model::PointCloud> cloud = ave::model::ParseLas(bytes, "fuzz.las");
  if (!cloud.ok()) return 0;
  if (cloud->classification.size() != cloud->size() || cloud->intensity.size() != cloud->size()) __builtin_trap();
  if (!cloud->origin.allFinite()) __builtin_trap();
  for (const auto& p : cloud->xyz) {
    if (!p.allFinite()) __builtin_trap();
  }
  // Re-encode at a scale coarse enough for any accepted coordinate (|local| <= 1e7 m).
  ave::model::LasWriteOptions options;
  options.scale = 0.01;
  absl::StatusOr<std::string> again = ave::model::EncodeLas(*cloud, {}, options);
  if (!again.ok()) return 0;  // a unit override or extreme origin may not fit: refused, not a crash
  absl::StatusOr<ave::model::PointCloud> back = ave::model::ParseLas(*again, "fuzz-again.las");
  if (!back.ok() || back->size() != cloud->size()) __builtin_trap();
  return 0;
}
