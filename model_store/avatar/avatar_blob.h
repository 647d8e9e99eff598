#pragma once
// The one binary form of an AvatarSequence: the `.avseq` file the studio writes and the blob the
// store holds (issue 17). All fields little-endian:
//   "AVEA" | u32 format version (1) | u32 name bytes | name (UTF-8) | f64 frame_period_s
//   | f64 stride_m | u32 frame count | per frame: u64 positions | u64 indices | u32 atlas_width
//   | u32 atlas_height | f32 positions[3n] | f32 normals[3n] | f32 uv[2n] | u32 indices
//   | u8 atlas_rgb[atlas_width * atlas_height * 3]
// Normals and uv are one per position (the contract in avatar_sequence.h).
#include <string>
#include <string_view>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "model_store/avatar/avatar_sequence.h"

namespace ave::avatar {

inline constexpr uint32_t kAvatarBlobVersion = 1;
inline constexpr int kMaxAtlasSide = 16384;

// Empty when the sequence may be stored and drawn; otherwise the first inconsistency, naming the
// frame and field (e.g. "frames[3].uv[17] is outside [0, 1]").
std::string CheckAvatarSequence(const AvatarSequence& sequence);

// InvalidArgument prefixed by `context` when CheckAvatarSequence fails.
absl::StatusOr<std::string> EncodeAvatarSequence(const AvatarSequence& sequence, std::string_view context);

// DataLoss naming `context` (a file path, "avatar_sequences row 'walk'") on a wrong magic or
// version, truncation, trailing bytes, counts larger than the blob, or a decoded sequence that
// fails CheckAvatarSequence.
absl::StatusOr<AvatarSequence> DecodeAvatarSequence(std::string_view blob, std::string_view context);

// File forms of the two above; errors name the path.
absl::Status WriteAvatarSequenceFile(const std::string& path, const AvatarSequence& sequence);
absl::StatusOr<AvatarSequence> ReadAvatarSequenceFile(const std::string& path);

}  // namespace ave::avatar
