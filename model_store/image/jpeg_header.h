// Walks a JPEG's marker segments to its frame header (SOF) without decoding anything: the one
// header walk shared by the server's frame validation and the image decoder's size check. Header
// only (absl), so the server core uses it without linking OpenCV.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string_view>

#include "absl/status/statusor.h"
#include "absl/strings/str_cat.h"

namespace ave::image {

// The largest image accepted from outside, by the server (frames) and every decoder: a side and a
// pixel count (64 Mpx: 192 MiB as BGR).
inline constexpr int kMaxImageSide = 16384;
inline constexpr int64_t kMaxImagePixels = int64_t{64} << 20;

struct JpegFrameHeader {
  int width = 0;
  int height = 0;
  int components = 0;
  bool progressive = false;
  size_t offset = 0;  // byte offset of the SOF marker
};

// `b` must start with the SOI marker (FF D8); the caller checks that (and the EOI, if it cares).
// Errors name the byte offset where the walk failed.
inline absl::StatusOr<JpegFrameHeader> FindJpegFrameHeader(std::string_view b) {
  const auto byte = [&](size_t i) { return static_cast<uint8_t>(b[i]); };
  size_t pos = 2;
  while (pos + 4 <= b.size()) {
    if (byte(pos) != 0xFF) return absl::InvalidArgumentError(absl::StrCat("corrupt JPEG: expected a marker at byte ", pos));
    const uint8_t marker = byte(pos + 1);
    if (marker == 0xFF) {  // fill byte
      ++pos;
      continue;
    }
    if (marker == 0xD8 || marker == 0x01 || (marker >= 0xD0 && marker <= 0xD7)) {  // no length
      pos += 2;
      continue;
    }
    if (marker == 0xD9 || marker == 0xDA) {  // EOI or start of scan before any SOF
      return absl::InvalidArgumentError(absl::StrCat("corrupt JPEG: no frame header (SOF) before byte ", pos));
    }
    const size_t length = (size_t{byte(pos + 2)} << 8) | byte(pos + 3);
    if (length < 2 || pos + 2 + length > b.size()) {
      return absl::InvalidArgumentError(absl::StrCat("truncated JPEG: segment 0xFF", absl::Hex(marker, absl::kZeroPad2),
                                                     " at byte ", pos, " runs past the end (", b.size(), " bytes)"));
    }
    const bool is_sof = marker >= 0xC0 && marker <= 0xCF && marker != 0xC4 && marker != 0xC8 && marker != 0xCC;
    if (is_sof) {
      if (length < 8) return absl::InvalidArgumentError(absl::StrCat("corrupt JPEG: short frame header at byte ", pos));
      JpegFrameHeader h;
      h.height = (int{byte(pos + 5)} << 8) | byte(pos + 6);
      h.width = (int{byte(pos + 7)} << 8) | byte(pos + 8);
      h.components = byte(pos + 9);
      h.progressive = marker == 0xC2 || marker == 0xC6 || marker == 0xCA || marker == 0xCE;
      h.offset = pos;
      return h;
    }
    pos += 2 + length;
  }
  return absl::InvalidArgumentError(absl::StrCat("truncated JPEG: no frame header (SOF) in ", b.size(), " bytes"));
}

}  // namespace ave::image
