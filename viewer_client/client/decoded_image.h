#pragma once
// A camera frame as the viewer shows it: the JPEG from the server decoded to RGBA (issue 14:
// through model_store/image's checked decoder, since the bytes come over the network).
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/statusor.h"

namespace ave::viewer {

struct DecodedImage {
  int width = 0;
  int height = 0;
  std::vector<uint8_t> rgba;  // top row first
};

// Decodes a JPEG at 1/`reduction` scale (1, 2, 4 or 8) into RGBA: width and height are the
// JPEG header's divided by `reduction` and rounded up, rgba holds width * height * 4 bytes.
// Errors say why (not a JPEG, truncated, over 64 Mpx, what OpenCV refused).
absl::StatusOr<std::shared_ptr<const DecodedImage>> DecodeJpegFrame(const std::string& jpeg, int reduction = 1);

// The same, null on any error.
std::shared_ptr<const DecodedImage> DecodeJpeg(const std::string& jpeg, int reduction = 1);

}  // namespace ave::viewer
