#pragma once
// Decoding image bytes that come from outside (issue 14): the viewer's streamed JPEG frames,
// ave-calibrate's chessboard photos, ave-studio's colour and mask images, the frames an export
// re-encodes. OpenCV decodes; this wrapper reads the dimensions from the JPEG or PNG header
// first and refuses what is not JPEG/PNG or is larger than the limits before OpenCV allocates
// anything, and checks that what OpenCV gives back has the size the header promised. Include it
// only from .cc files that already use OpenCV (it pulls in cv::Mat).
#include <cstdint>
#include <string>
#include <string_view>

#include <opencv2/core/mat.hpp>

#include "absl/status/statusor.h"
#include "model_store/image/jpeg_header.h"

namespace ave::image {

enum class ImageFormat { kJpeg, kPng };

struct ImageHeader {
  ImageFormat format = ImageFormat::kJpeg;
  int width = 0;
  int height = 0;
};

struct DecodeLimits {
  int max_side = kMaxImageSide;          // the server's limits too (fusion_server/core/validation.cc)
  int64_t max_pixels = kMaxImagePixels;
};

enum class Channels { kColor, kGray };  // CV_8UC3 (BGR) or CV_8UC1

// Width and height from a JPEG's first frame header (SOFn) or a PNG's IHDR chunk. Errors say
// what is wrong ("not a JPEG or PNG image (first bytes 47 49 46 38)", "truncated JPEG: ...").
absl::StatusOr<ImageHeader> PeekImageHeader(std::string_view bytes);

// Decodes `bytes` (JPEG or PNG) into a continuous CV_8UC3 (kColor) or CV_8UC1 (kGray) Mat.
// `reduction` 1, 2, 4 or 8 asks libjpeg for a 1/reduction image (JPEG only; ceil(side/reduction)
// per side). The result is exactly the header's size (reduced), or its transpose when an EXIF
// orientation turned the image; anything else is an error, as are images over `limits`.
absl::StatusOr<cv::Mat> DecodeImage(std::string_view bytes, Channels channels, int reduction = 1,
                                    const DecodeLimits& limits = {});

// Reads the file at `path` (at most 256 MiB) and decodes it as DecodeImage does; every error
// starts with the path.
absl::StatusOr<cv::Mat> ReadImageFile(const std::string& path, Channels channels, const DecodeLimits& limits = {});

}  // namespace ave::image
