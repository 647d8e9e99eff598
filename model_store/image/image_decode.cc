#include "model_store/image/image_decode.h"
#include "model_store/image/jpeg_header.h"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <system_error>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace ave::image {
namespace {

constexpr size_t kMaxImageBytes = size_t{256} << 20;

uint8_t At(std::string_view b, size_t i) { return static_cast<uint8_t>(b[i]); }

absl::StatusOr<ImageHeader> PeekJpeg(std::string_view b) {
  absl::StatusOr<JpegFrameHeader> sof = FindJpegFrameHeader(b);
  if (!sof.ok()) return sof.status();
  ImageHeader h;
  h.format = ImageFormat::kJpeg;
  h.width = sof->width;
  h.height = sof->height;
  return h;
}

absl::StatusOr<ImageHeader> PeekPng(std::string_view b) {
  // Signature (8), IHDR length (4) and type (4), width (4), height (4): big-endian.
  if (b.size() < 24) return absl::InvalidArgumentError(absl::StrCat("truncated PNG: ", b.size(), " bytes, no IHDR chunk"));
  if (b.substr(12, 4) != "IHDR") return absl::InvalidArgumentError("corrupt PNG: the first chunk is not IHDR");
  const auto be32 = [&](size_t i) {
    return (uint32_t{At(b, i)} << 24) | (uint32_t{At(b, i + 1)} << 16) | (uint32_t{At(b, i + 2)} << 8) | At(b, i + 3);
  };
  const uint32_t w = be32(16), h = be32(20);
  if (w > 0x7FFFFFFFu || h > 0x7FFFFFFFu) {
    return absl::InvalidArgumentError(absl::StrCat("corrupt PNG: dimensions ", w, "x", h, " beyond 2^31-1"));
  }
  ImageHeader header;
  header.format = ImageFormat::kPng;
  header.width = static_cast<int>(w);
  header.height = static_cast<int>(h);
  return header;
}

const char* Name(ImageFormat f) { return f == ImageFormat::kJpeg ? "JPEG" : "PNG"; }

int Flags(Channels channels, int reduction) {
  const bool color = channels == Channels::kColor;
  switch (reduction) {
    case 2: return color ? cv::IMREAD_REDUCED_COLOR_2 : cv::IMREAD_REDUCED_GRAYSCALE_2;
    case 4: return color ? cv::IMREAD_REDUCED_COLOR_4 : cv::IMREAD_REDUCED_GRAYSCALE_4;
    case 8: return color ? cv::IMREAD_REDUCED_COLOR_8 : cv::IMREAD_REDUCED_GRAYSCALE_8;
    default: return color ? cv::IMREAD_COLOR : cv::IMREAD_GRAYSCALE;
  }
}

}  // namespace

absl::StatusOr<ImageHeader> PeekImageHeader(std::string_view b) {
  static constexpr char kPngSignature[] = "\x89PNG\r\n\x1a\n";
  if (b.size() >= 3 && At(b, 0) == 0xFF && At(b, 1) == 0xD8 && At(b, 2) == 0xFF) return PeekJpeg(b);
  if (b.size() >= 8 && b.substr(0, 8) == std::string_view(kPngSignature, 8)) return PeekPng(b);
  std::string first;
  for (size_t i = 0; i < std::min<size_t>(b.size(), 4); ++i) absl::StrAppend(&first, i ? " " : "", absl::Hex(At(b, i), absl::kZeroPad2));
  return absl::InvalidArgumentError(b.empty() ? std::string("not a JPEG or PNG image (0 bytes)")
                                              : absl::StrCat("not a JPEG or PNG image (first bytes ", first, ")"));
}

absl::StatusOr<cv::Mat> DecodeImage(std::string_view bytes, Channels channels, int reduction, const DecodeLimits& limits) {
  if (reduction != 1 && reduction != 2 && reduction != 4 && reduction != 8) {
    return absl::InvalidArgumentError(absl::StrCat("image reduction ", reduction, " is not 1, 2, 4 or 8"));
  }
  if (bytes.size() > kMaxImageBytes) {
    return absl::InvalidArgumentError(absl::StrCat("image of ", bytes.size(), " bytes (at most ", kMaxImageBytes, ")"));
  }
  absl::StatusOr<ImageHeader> header = PeekImageHeader(bytes);
  if (!header.ok()) return header.status();
  const char* name = Name(header->format);
  if (header->width <= 0 || header->height <= 0 || header->width > limits.max_side || header->height > limits.max_side ||
      int64_t{header->width} * header->height > limits.max_pixels) {
    return absl::InvalidArgumentError(absl::StrCat(name, " dimensions ", header->width, "x", header->height, " outside 1..",
                                                   limits.max_side, " per side or over ", limits.max_pixels, " pixels"));
  }
  if (reduction != 1 && header->format != ImageFormat::kJpeg) {
    return absl::InvalidArgumentError(absl::StrCat("image reduction ", reduction, " is for JPEG only, not ", name));
  }
  const int want_w = (header->width + reduction - 1) / reduction;
  const int want_h = (header->height + reduction - 1) / reduction;
  cv::Mat image;
  try {
    const cv::Mat raw(1, static_cast<int>(bytes.size()), CV_8UC1, const_cast<char*>(bytes.data()));
    image = cv::imdecode(raw, Flags(channels, reduction));
  } catch (const cv::Exception& e) {
    return absl::InvalidArgumentError(absl::StrCat(name, " ", header->width, "x", header->height, ": OpenCV: ", e.err));
  } catch (const std::exception& e) {
    return absl::ResourceExhaustedError(absl::StrCat(name, " ", header->width, "x", header->height, ": ", e.what()));
  }
  if (image.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(name, " ", header->width, "x", header->height,
                                                   ": OpenCV could not decode it (corrupt or unsupported data)"));
  }
  const int want_type = channels == Channels::kColor ? CV_8UC3 : CV_8UC1;
  const bool size_ok = (image.cols == want_w && image.rows == want_h) || (image.cols == want_h && image.rows == want_w);
  if (!size_ok || image.type() != want_type || !image.isContinuous()) {
    return absl::InvalidArgumentError(absl::StrCat(name, " header says ", header->width, "x", header->height, " (", want_w, "x",
                                                   want_h, " at 1/", reduction, ") but OpenCV decoded ", image.cols, "x",
                                                   image.rows, " with ", image.channels(), " channels"));
  }
  return image;
}

absl::StatusOr<cv::Mat> ReadImageFile(const std::string& path, Channels channels, const DecodeLimits& limits) {
  std::error_code ec;
  if (std::filesystem::exists(path, ec) && !std::filesystem::is_regular_file(path, ec)) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": not a regular file"));
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::NotFoundError(absl::StrCat(path, ": cannot open: ", std::strerror(errno)));
  std::string bytes;
  char buffer[1 << 16];
  while (in.read(buffer, sizeof buffer) || in.gcount() > 0) {
    bytes.append(buffer, static_cast<size_t>(in.gcount()));
    if (bytes.size() > kMaxImageBytes) {
      return absl::InvalidArgumentError(absl::StrCat(path, ": larger than ", kMaxImageBytes, " bytes: not an image we read"));
    }
  }
  if (in.bad()) return absl::DataLossError(absl::StrCat(path, ": read error"));
  absl::StatusOr<cv::Mat> image = DecodeImage(bytes, channels, 1, limits);
  if (!image.ok()) return absl::Status(image.status().code(), absl::StrCat(path, ": ", image.status().message()));
  return image;
}

}  // namespace ave::image
