// libFuzzer target (issue 14): untrusted image bytes through the product's decode entry points,
// not bare OpenCV. Byte 0:
//   bits 0-1  entry: 0 the viewer's DecodeJpegFrame (a streamed camera frame), 1 image::DecodeImage
//             in colour (the clip export), 2 DecodeImage in grey, 3 image::ReadImageFile from a
//             file (ave-calibrate: grey; ave-studio: colour, by bit 4)
//   bits 2-3  JPEG reduction 1, 2, 4 or 8 (entries 0-2)
//   bit 5     small limits (256 per side, 16,384 pixels) instead of the product's (16,384, 64 Mpx)
// the rest is the image. Checks beyond "no crash": a refusal has a message (a file's starts with
// its path); an accepted image has a readable JPEG/PNG header within the limits, the header's
// size divided by the reduction (rounded up; or its transpose after an EXIF rotation), the asked
// type (CV_8UC3 / CV_8UC1), continuous; the viewer's frame is RGBA of width x height x 4 bytes and
// comes from a JPEG. OpenCV and its codecs are Debian's, uninstrumented; an allocation over
// -malloc_limit_mb (= -rss_limit_mb) is a finding, so a header that lies about its size counts.
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>
#include <string_view>

#include <opencv2/core.hpp>

#include "model_store/image/image_decode.h"
#include "viewer_client/client/decoded_image.h"

namespace {

[[noreturn]] void Fail(const std::string& what) {
  std::fprintf(stderr, "image_decode_fuzz: %s\n", what.c_str());
  std::abort();
}

std::string TempPath() {
  static const std::string path = [] {
    const char* dir = std::getenv("TMPDIR");
    return std::string(dir && *dir ? dir : "/tmp") + "/ave_fuzz_image_" + std::to_string(::getpid()) + ".img";
  }();
  return path;
}

void CheckImage(std::string_view bytes, const cv::Mat& m, ave::image::Channels channels, int reduction,
                const ave::image::DecodeLimits& limits) {
  const absl::StatusOr<ave::image::ImageHeader> header = ave::image::PeekImageHeader(bytes);
  if (!header.ok()) Fail("accepted bytes whose header does not read: " + std::string(header.status().message()));
  if (header->width < 1 || header->height < 1 || header->width > limits.max_side || header->height > limits.max_side ||
      int64_t{header->width} * header->height > limits.max_pixels) {
    Fail("accepted a header outside the limits: " + std::to_string(header->width) + "x" + std::to_string(header->height));
  }
  const int w = (header->width + reduction - 1) / reduction, h = (header->height + reduction - 1) / reduction;
  if (!((m.cols == w && m.rows == h) || (m.cols == h && m.rows == w))) {
    Fail("decoded " + std::to_string(m.cols) + "x" + std::to_string(m.rows) + ", header " + std::to_string(header->width) + "x" +
         std::to_string(header->height) + " at 1/" + std::to_string(reduction));
  }
  if (m.type() != (channels == ave::image::Channels::kColor ? CV_8UC3 : CV_8UC1)) Fail("wrong Mat type " + std::to_string(m.type()));
  if (!m.isContinuous()) Fail("decoded Mat is not continuous");
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  const uint8_t mode = data[0];
  const std::string_view bytes(reinterpret_cast<const char*>(data + 1), size - 1);
  const int entry = mode & 3;
  const int reduction = 1 << ((mode >> 2) & 3);
  ave::image::DecodeLimits limits;
  if (mode & 0x20) {
    limits.max_side = 256;
    limits.max_pixels = 16384;
  }
  if (entry == 0) {
    // The viewer uses the product's limits (its own code path has no other).
    const std::string jpeg(bytes);
    const absl::StatusOr<std::shared_ptr<const ave::viewer::DecodedImage>> frame = ave::viewer::DecodeJpegFrame(jpeg, reduction);
    if (!frame.ok()) {
      if (frame.status().message().empty()) Fail("viewer: a refusal without a message");
      if (ave::viewer::DecodeJpeg(jpeg, reduction) != nullptr) Fail("viewer: DecodeJpeg accepted what DecodeJpegFrame refused");
      return 0;
    }
    const ave::viewer::DecodedImage& image = **frame;
    const absl::StatusOr<ave::image::ImageHeader> header = ave::image::PeekImageHeader(bytes);
    if (!header.ok() || header->format != ave::image::ImageFormat::kJpeg) Fail("viewer: accepted a frame that is not a JPEG");
    const int w = (header->width + reduction - 1) / reduction, h = (header->height + reduction - 1) / reduction;
    if (!((image.width == w && image.height == h) || (image.width == h && image.height == w))) {
      Fail("viewer: frame " + std::to_string(image.width) + "x" + std::to_string(image.height) + " for a " +
           std::to_string(header->width) + "x" + std::to_string(header->height) + " JPEG at 1/" + std::to_string(reduction));
    }
    if (image.rgba.size() != size_t(image.width) * image.height * 4) Fail("viewer: RGBA buffer of the wrong size");
    return 0;
  }
  if (entry == 1 || entry == 2) {
    const ave::image::Channels channels = entry == 1 ? ave::image::Channels::kColor : ave::image::Channels::kGray;
    const absl::StatusOr<cv::Mat> m = ave::image::DecodeImage(bytes, channels, reduction, limits);
    if (!m.ok()) {
      if (m.status().message().empty()) Fail("DecodeImage: a refusal without a message");
      return 0;
    }
    CheckImage(bytes, *m, channels, reduction, limits);
    return 0;
  }
  const ave::image::Channels channels = (mode & 0x10) ? ave::image::Channels::kColor : ave::image::Channels::kGray;
  const std::string path = TempPath();
  {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    if (!out) Fail("cannot write " + path);
  }
  const absl::StatusOr<cv::Mat> m = ave::image::ReadImageFile(path, channels, limits);
  std::remove(path.c_str());
  if (!m.ok()) {
    if (m.status().message().rfind(path + ": ", 0) != 0) Fail("ReadImageFile: the error does not start with the path: " + std::string(m.status().message()));
    return 0;
  }
  CheckImage(bytes, *m, channels, 1, limits);
  return 0;
}
