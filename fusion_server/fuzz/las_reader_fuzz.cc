// libFuzzer target: the LAS 1.2-1.4 reader (model_store/lidar/las.h), which reads survey files from
// outside (issue 8 asked for it; issue 4 wrote the reader), and the rewriter behind `ave-model
// classify` (las_rewrite.h, issue 14). Every input must either be refused with a status or give a
// cloud whose attributes match its size and whose positions are finite. An accepted file must:
//  - be rewritten with new classes, byte for byte equal to the input except the generating
//    software and the classification bits (checked by CompareLasExceptClasses, which reads the
//    layout straight from the header, not through the reader), and read back to the same origin,
//    positions (bit for bit), record mapping and the new classes;
//  - encode back to a new LAS file (the PLY/PCD path) and parse again to the same point count.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>

#include "model_store/lidar/las.h"
#include "model_store/lidar/las_rewrite.h"
#include "model_store/lidar/las_synthetic.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  ave::model::LasHeaderInfo info;
  absl::StatusOr<ave::model::PointCloud> cloud = ave::model::ParseLas(bytes, "fuzz.las", {}, &info);
  if (!cloud.ok()) return 0;
  if (cloud->classification.size() != cloud->size() || cloud->intensity.size() != cloud->size()) __builtin_trap();
  if (!cloud->record_index.empty() && cloud->record_index.size() != cloud->size()) __builtin_trap();
  if (!cloud->origin.allFinite()) __builtin_trap();
  for (const auto& p : cloud->xyz) {
    if (!p.allFinite()) __builtin_trap();
  }

  // The rewriter: whatever the reader accepts comes back with only the classification changed.
  std::vector<uint8_t> classes(cloud->size());
  const uint8_t mask = info.point_format >= 6 ? 0xFF : 0x1F;
  for (size_t k = 0; k < classes.size(); ++k) classes[k] = static_cast<uint8_t>((k * 37 + size) & mask);
  ave::model::LasReclassifyStats stats;
  absl::StatusOr<std::string> rewritten = ave::model::ReclassifyLas(bytes, "fuzz.las", classes, cloud->record_index, &stats);
  if (!rewritten.ok() || stats.patched != cloud->size()) __builtin_trap();
  const std::string input(bytes);
  const ave::model::LasRewriteDiff diff = ave::model::CompareLasExceptClasses(input, *rewritten);
  if (!diff.same_size || diff.differing != 0 || diff.classes_after.size() != info.point_count) __builtin_trap();
  for (size_t k = 0; k < classes.size(); ++k) {
    const uint64_t r = cloud->record_index.empty() ? k : cloud->record_index[k];
    if (diff.classes_after[r] != classes[k]) __builtin_trap();
  }
  ave::model::LasHeaderInfo back_info;
  absl::StatusOr<ave::model::PointCloud> back = ave::model::ParseLas(*rewritten, "fuzz-rewritten.las", {}, &back_info);
  if (!back.ok() || back->size() != cloud->size() || back->origin != cloud->origin || back->xyz != cloud->xyz ||
      back->record_index != cloud->record_index || back->classification != classes ||
      back->gps_time.size() != cloud->gps_time.size() ||  // bit for bit: a GPS time may be NaN
      (!cloud->gps_time.empty() && std::memcmp(back->gps_time.data(), cloud->gps_time.data(), cloud->gps_time.size() * sizeof(double)) != 0) ||
      back_info.scale != info.scale || back_info.offset != info.offset || back_info.record_length != info.record_length) {
    __builtin_trap();
  }

  // Re-encode at a scale coarse enough for any accepted coordinate (|local| <= 1e7 m).
  ave::model::LasWriteOptions options;
  options.scale = 0.01;
  absl::StatusOr<std::string> again = ave::model::EncodeLas(*cloud, {}, options);
  if (!again.ok()) return 0;  // a unit override or extreme origin may not fit: refused, not a crash
  absl::StatusOr<ave::model::PointCloud> reparsed = ave::model::ParseLas(*again, "fuzz-again.las");
  if (!reparsed.ok() || reparsed->size() != cloud->size()) __builtin_trap();
  return 0;
}
