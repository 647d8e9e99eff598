#include "model_store/image/image_decode.h"

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

namespace ave::image {
namespace {

std::string Encode(const std::string& ext, int width, int height) {
  cv::Mat m(height, width, CV_8UC3);
  cv::randu(m, cv::Scalar::all(0), cv::Scalar::all(255));
  std::vector<uchar> out;
  EXPECT_TRUE(cv::imencode(ext, m, out));
  return std::string(out.begin(), out.end());
}

// A PNG signature and IHDR chunk declaring width x height, then nothing.
std::string PngHeader(uint32_t width, uint32_t height) {
  std::string s("\x89PNG\r\n\x1a\n", 8);
  s += std::string("\0\0\0\x0dIHDR", 8);
  for (uint32_t v : {width, height}) {
    for (int shift = 24; shift >= 0; shift -= 8) s += static_cast<char>((v >> shift) & 0xFF);
  }
  s += std::string("\x08\x02\0\0\0\0\0\0\0", 9);  // depth 8, RGB, CRC (not checked here)
  return s;
}

TEST(ImageDecode, JpegAndPngDecodeToTheirHeadersSizeInTheAskedChannels) {
  for (const std::string ext : {".jpg", ".png"}) {
    const std::string bytes = Encode(ext, 37, 21);
    const absl::StatusOr<ImageHeader> header = PeekImageHeader(bytes);
    ASSERT_TRUE(header.ok()) << header.status();
    EXPECT_EQ(header->width, 37);
    EXPECT_EQ(header->height, 21);
    EXPECT_EQ(header->format, ext == ".jpg" ? ImageFormat::kJpeg : ImageFormat::kPng);
    const absl::StatusOr<cv::Mat> color = DecodeImage(bytes, Channels::kColor);
    ASSERT_TRUE(color.ok()) << color.status();
    EXPECT_EQ(color->type(), CV_8UC3);
    EXPECT_EQ(color->size(), cv::Size(37, 21));
    const absl::StatusOr<cv::Mat> gray = DecodeImage(bytes, Channels::kGray);
    ASSERT_TRUE(gray.ok()) << gray.status();
    EXPECT_EQ(gray->type(), CV_8UC1);
    EXPECT_EQ(gray->size(), cv::Size(37, 21));
  }
}

TEST(ImageDecode, JpegReductionRoundsUpAndIsRefusedForPng) {
  const std::string jpeg = Encode(".jpg", 37, 21);
  for (int r : {2, 4, 8}) {
    const absl::StatusOr<cv::Mat> m = DecodeImage(jpeg, Channels::kColor, r);
    ASSERT_TRUE(m.ok()) << m.status();
    EXPECT_EQ(m->size(), cv::Size((37 + r - 1) / r, (21 + r - 1) / r)) << r;
  }
  EXPECT_FALSE(DecodeImage(jpeg, Channels::kColor, 3).ok());
  const absl::StatusOr<cv::Mat> png = DecodeImage(Encode(".png", 8, 8), Channels::kColor, 2);
  ASSERT_FALSE(png.ok());
  EXPECT_NE(png.status().message().find("JPEG only"), std::string::npos) << png.status();
}

TEST(ImageDecode, RefusalsSayWhy) {
  const auto message = [](std::string_view bytes) {
    const absl::StatusOr<cv::Mat> m = DecodeImage(bytes, Channels::kColor);
    EXPECT_FALSE(m.ok());
    return m.ok() ? std::string() : std::string(m.status().message());
  };
  EXPECT_EQ(message(""), "not a JPEG or PNG image (0 bytes)");
  EXPECT_EQ(message("GIF89a......"), "not a JPEG or PNG image (first bytes 47 49 46 38)");
  const std::string jpeg = Encode(".jpg", 16, 16);
  EXPECT_NE(message(jpeg.substr(0, 10)).find("truncated JPEG"), std::string::npos);
  // The header is intact, the entropy-coded data is not there: libjpeg's or our message, never a crash.
  const std::string body_cut = jpeg.substr(0, jpeg.size() / 2);
  (void)DecodeImage(body_cut, Channels::kColor);
  EXPECT_NE(message(Encode(".png", 8, 8).substr(0, 20)).find("truncated PNG"), std::string::npos);
}

TEST(ImageDecode, HugeDeclaredDimensionsAreRefusedBeforeOpenCvAllocates) {
  // 30000 x 30000 (900 Mpx, 2.7 GB as BGR) declared in the IHDR: OpenCV's own limit (2^30
  // pixels) lets it through, and a 69-byte PNG with an IDAT chunk makes cv::imdecode allocate
  // 2,700,000,000 bytes (seen under a 1.5 GB ulimit: "Failed to allocate 2700000000 bytes").
  const absl::StatusOr<cv::Mat> png = DecodeImage(PngHeader(30000, 30000), Channels::kColor);
  ASSERT_FALSE(png.ok());
  EXPECT_EQ(png.status().message(), "PNG dimensions 30000x30000 outside 1..16384 per side or over 67108864 pixels");
  const absl::StatusOr<cv::Mat> zero = DecodeImage(PngHeader(0, 5), Channels::kColor);
  ASSERT_FALSE(zero.ok());
  EXPECT_NE(zero.status().message().find("PNG dimensions 0x5"), std::string::npos);
  DecodeLimits small;
  small.max_side = 32;
  small.max_pixels = 500;
  const absl::StatusOr<cv::Mat> over = DecodeImage(Encode(".jpg", 30, 30), Channels::kColor, 1, small);
  ASSERT_FALSE(over.ok());
  EXPECT_NE(over.status().message().find("over 500 pixels"), std::string::npos) << over.status();
}

TEST(ImageDecode, FilesAreNamedInEveryError) {
  const std::filesystem::path dir = std::filesystem::path(testing::TempDir()) / "ave_image_decode_test";
  std::filesystem::create_directories(dir);
  const std::string good = (dir / "good.png").string(), bad = (dir / "bad.png").string();
  std::ofstream(good, std::ios::binary) << Encode(".png", 12, 7);
  std::ofstream(bad, std::ios::binary) << "not an image";
  const absl::StatusOr<cv::Mat> m = ReadImageFile(good, Channels::kGray);
  ASSERT_TRUE(m.ok()) << m.status();
  EXPECT_EQ(m->size(), cv::Size(12, 7));
  EXPECT_EQ(ReadImageFile(bad, Channels::kColor).status().message(), bad + ": not a JPEG or PNG image (first bytes 6e 6f 74 20)");
  const std::string missing = (dir / "missing.png").string();
  EXPECT_EQ(ReadImageFile(missing, Channels::kColor).status().message(), missing + ": cannot open: No such file or directory");
  EXPECT_EQ(ReadImageFile(dir.string(), Channels::kColor).status().message(), dir.string() + ": not a regular file");
}

}  // namespace
}  // namespace ave::image
