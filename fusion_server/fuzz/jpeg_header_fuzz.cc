// libFuzzer target: the JPEG header walk the server runs on every frame before forwarding it
// (issue 8). Any input must give a Status, never a crash, a read out of bounds or UB.
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "fusion_server/core/validation.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  absl::StatusOr<ave::JpegInfo> info = ave::ParseJpegHeader(bytes);
  if (info.ok() && (info->width <= 0 || info->height <= 0)) __builtin_trap();  // the contract
  return 0;
}
