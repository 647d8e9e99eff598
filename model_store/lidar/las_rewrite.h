#pragma once
// Rewriting a user's LAS file with new point classes (issue 14): `ave-model classify` must give
// back the survey it was handed, not a new file. Every byte is copied from the source — header,
// VLRs and EVLRs (the CRS as WKT or GeoTIFF keys), bytes between them, every point record (raw
// int32 X/Y/Z under the file's own scale, offset and unit, intensity, returns, flags, scan angle,
// user data, point source id, GPS time, RGB, NIR, wave packets, extra bytes) — and only the
// classification is patched in place:
//   formats 0-5:  bits 0-4 of record byte 15 (bits 5-7, synthetic / key-point / withheld, kept);
//   formats 6-10: record byte 16 (the classification flags and scanner channel in byte 15 kept).
// The header's generating software (bytes 58-89) is set to "AVE ave-model"; nothing else in it
// changes (GUID, system id, creation date, global encoding, counts by return and bounds stay
// right because no position or return changes).
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

#include "model_store/lidar/point_cloud.h"

namespace ave::model {

inline constexpr size_t kLasGeneratingSoftwareOffset = 58;  // 32 bytes, NUL-padded
inline constexpr char kLasGeneratingSoftware[] = "AVE ave-model";

struct LasReclassifyStats {
  uint64_t records = 0;  // point records in the file
  uint64_t patched = 0;  // records given a class; the rest (dropped by the reader) keep theirs
  uint64_t changed = 0;  // records whose class now differs from the source's
  size_t class_byte = 0;  // offset of the class in a record: 15 (5 bits) or 16
};

// `classification[k]` goes to file record `record_index[k]` (empty: record k, and then there is
// one class per record, or none at all when the reader kept no point). Refused, naming `name` and the byte offset or point: a source the LAS
// reader refuses, a class count or record index that does not match the file, a class above 31
// for formats 0-5.
absl::StatusOr<std::string> ReclassifyLas(std::string_view source, const std::string& name,
                                          const std::vector<uint8_t>& classification,
                                          const std::vector<uint64_t>& record_index = {},
                                          LasReclassifyStats* stats = nullptr);

// The same, patching `bytes` where it lies (no second copy of a large survey in memory); on error
// `bytes` is left as it was.
absl::Status ReclassifyLasInPlace(std::string& bytes, const std::string& name, const std::vector<uint8_t>& classification,
                                  const std::vector<uint64_t>& record_index = {}, LasReclassifyStats* stats = nullptr);

// Re-reads `cloud.source.path` (the LAS file `cloud` was read from by ReadLas), refuses when it
// changed since (size or fingerprint), and writes it to `out_path` reclassified (through a
// temporary file renamed into place, so out_path may be the source itself).
absl::Status WriteReclassifiedLas(const PointCloud& cloud, const std::vector<uint8_t>& classification,
                                  const std::string& out_path, LasReclassifyStats* stats = nullptr);

}  // namespace ave::model
