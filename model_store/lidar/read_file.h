#pragma once
// Whole-file reads and writes with errors that name the path (shared by the LiDAR readers and the
// terrain exporters).
#include <cstdint>
#include <string>
#include <string_view>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace ave::model {

absl::StatusOr<std::string> ReadWholeFile(const std::string& path);
absl::Status WriteWholeFile(const std::string& path, const std::string& bytes);
// The file name's extension after the last dot, lower-case ("" when none): picks the format.
std::string LowerExtension(const std::string& path);
// A 64-bit hash of a whole file's bytes (not cryptographic; ~GB/s): tells a rewriter that the
// file it read earlier has changed since (PointCloud::Source).
uint64_t Fingerprint64(std::string_view bytes);

}  // namespace ave::model
