#include "model_store/lidar/las_rewrite.h"

#include <unistd.h>

#include <cstring>
#include <filesystem>
#include <system_error>

#include "model_store/lidar/las.h"
#include "model_store/lidar/read_file.h"

namespace ave::model {

absl::StatusOr<std::string> ReclassifyLas(std::string_view source, const std::string& name,
                                          const std::vector<uint8_t>& classification,
                                          const std::vector<uint64_t>& record_index, LasReclassifyStats* stats) {
  std::string out(source);
  if (absl::Status s = ReclassifyLasInPlace(out, name, classification, record_index, stats); !s.ok()) return s;
  return out;
}

absl::Status ReclassifyLasInPlace(std::string& out, const std::string& name, const std::vector<uint8_t>& classification,
                                  const std::vector<uint64_t>& record_index, LasReclassifyStats* stats_out) {
  absl::StatusOr<LasLayout> layout = ParseLasLayout(out, name);
  if (!layout.ok()) return layout.status();
  const LasHeaderInfo& info = layout->info;
  const uint64_t records = info.point_count;
  // No classes at all is a cloud with no point kept (the reader dropped every record): nothing to
  // patch, whatever the index says (found by the fuzzer: every record out of range).
  if (record_index.empty() ? !classification.empty() && classification.size() != records
                           : record_index.size() != classification.size()) {
    return absl::InvalidArgumentError(name + ": " + std::to_string(classification.size()) + " classes for " +
                                      (record_index.empty() ? std::to_string(records) + " point records"
                                                            : std::to_string(record_index.size()) + " record indices"));
  }
  const bool extended = info.point_format >= 6;
  LasReclassifyStats stats;
  stats.records = records;
  stats.class_byte = extended ? 16 : 15;
  // Check everything first, so a refused rewrite leaves `out` as it was.
  uint64_t previous = 0;
  for (size_t k = 0; k < classification.size(); ++k) {
    const uint64_t r = record_index.empty() ? k : record_index[k];
    if (!record_index.empty() && (r >= records || (k > 0 && r <= previous))) {
      return absl::InvalidArgumentError(name + ": point " + std::to_string(k) + " maps to record " + std::to_string(r) +
                                        " (the file holds " + std::to_string(records) + "; indices must increase)");
    }
    previous = r;
    if (!extended && classification[k] > 31) {
      return absl::InvalidArgumentError(name + ": byte offset " +
                                        std::to_string(layout->point_offset + r * info.record_length + stats.class_byte) + ": point " +
                                        std::to_string(k) + " (record " + std::to_string(r) + "): class " +
                                        std::to_string(classification[k]) + " does not fit the 5 bits of point format " +
                                        std::to_string(info.point_format) + " (0-31)");
    }
  }
  std::memset(out.data() + kLasGeneratingSoftwareOffset, 0, 32);  // inside the 227+ header bytes checked
  std::memcpy(out.data() + kLasGeneratingSoftwareOffset, kLasGeneratingSoftware, sizeof(kLasGeneratingSoftware) - 1);
  for (size_t k = 0; k < classification.size(); ++k) {
    const uint64_t r = record_index.empty() ? k : record_index[k];
    const size_t at = layout->point_offset + r * info.record_length + stats.class_byte;
    const uint8_t old_byte = static_cast<uint8_t>(out[at]);
    // Formats 0-5: the synthetic / key-point / withheld flags in bits 5-7 stay.
    const uint8_t new_byte = extended ? classification[k] : static_cast<uint8_t>((old_byte & 0xE0) | classification[k]);
    stats.changed += new_byte != old_byte;
    out[at] = static_cast<char>(new_byte);
  }
  stats.patched = classification.size();
  if (stats_out) *stats_out = stats;
  return absl::OkStatus();
}

absl::Status WriteReclassifiedLas(const PointCloud& cloud, const std::vector<uint8_t>& classification, const std::string& out_path,
                                  LasReclassifyStats* stats) {
  const PointCloud::Source& src = cloud.source;
  if (src.format != "las" || src.path.empty()) {
    return absl::FailedPreconditionError(out_path + ": the points were not read from a LAS file, so there is none to rewrite");
  }
  if (classification.size() != cloud.size()) {
    return absl::InvalidArgumentError(src.path + ": " + std::to_string(classification.size()) + " classes for " +
                                      std::to_string(cloud.size()) + " points read");
  }
  absl::StatusOr<std::string> bytes = ReadWholeFile(src.path);
  if (!bytes.ok()) return bytes.status();
  if (bytes->size() != src.size_bytes || Fingerprint64(*bytes) != src.fingerprint) {
    return absl::FailedPreconditionError(src.path + ": changed since it was read (" + std::to_string(src.size_bytes) + " bytes then, " +
                                         std::to_string(bytes->size()) + " now" +
                                         (bytes->size() == src.size_bytes ? ", different content" : "") +
                                         "): not writing " + out_path + "; classify it again");
  }
  if (absl::Status s = ReclassifyLasInPlace(*bytes, src.path, classification, cloud.record_index, stats); !s.ok()) return s;
  const std::string tmp = out_path + ".ave-tmp-" + std::to_string(::getpid());
  if (absl::Status s = WriteWholeFile(tmp, *bytes); !s.ok()) {
    std::error_code ignored;
    std::filesystem::remove(tmp, ignored);
    return s;
  }
  std::error_code ec;
  std::filesystem::rename(tmp, out_path, ec);
  if (ec) {
    const std::string why = ec.message();
    std::filesystem::remove(tmp, ec);
    return absl::PermissionDeniedError(out_path + ": cannot move the written file into place: " + why);
  }
  return absl::OkStatus();
}

}  // namespace ave::model
