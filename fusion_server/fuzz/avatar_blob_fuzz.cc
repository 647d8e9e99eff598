// libFuzzer target: the avatar sequence blob (issue 17), the one binary form of a .avseq file
// (`ave-admin put-avatar`, `ave-viewer --avseq`), a PutAvatarSequence upload and a store row. A
// decoded sequence passed CheckAvatarSequence, so it must re-encode, and re-encoding must give the
// same bytes back (the form has one encoding); a refusal must say why.
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "model_store/avatar/avatar_blob.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view blob(reinterpret_cast<const char*>(data), size);
  absl::StatusOr<ave::avatar::AvatarSequence> sequence = ave::avatar::DecodeAvatarSequence(blob, "fuzz");
  if (!sequence.ok()) {
    if (sequence.status().message().empty()) __builtin_trap();
    return 0;
  }
  absl::StatusOr<std::string> again = ave::avatar::EncodeAvatarSequence(*sequence, "fuzz");
  if (!again.ok()) __builtin_trap();
  if (*again != blob) __builtin_trap();
  return 0;
}
