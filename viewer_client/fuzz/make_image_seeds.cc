// Writes the seeds of ave_fuzz_image_decode (viewer_client/fuzz/corpus/image_decode): small JPEG
// and PNG images as OpenCV writes them, each behind the mode bytes that send it down each entry
// point. Not a fuzzer; built with the fuzz targets.   ave_make_image_seeds viewer_client/fuzz/corpus
#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s CORPUS_DIR\n", argv[0]);
    return 2;
  }
  const std::string dir = std::string(argv[1]) + "/image_decode/";
  cv::Mat color(24, 40, CV_8UC3), gray(17, 9, CV_8UC1), alpha(12, 12, CV_8UC4), deep(10, 6, CV_16UC3);
  cv::RNG rng(14);
  rng.fill(color, cv::RNG::UNIFORM, 0, 255);
  rng.fill(gray, cv::RNG::UNIFORM, 0, 255);
  rng.fill(alpha, cv::RNG::UNIFORM, 0, 255);
  rng.fill(deep, cv::RNG::UNIFORM, 0, 65535);
  struct Seed {
    std::string name, ext;
    cv::Mat image;
    std::vector<int> params;
    std::vector<unsigned char> modes;
  };
  const std::vector<Seed> seeds = {
      {"jpeg_color", ".jpg", color, {cv::IMWRITE_JPEG_QUALITY, 50}, {0x00, 0x04, 0x0c, 0x01, 0x06, 0x13, 0x21}},
      {"jpeg_gray", ".jpg", gray, {cv::IMWRITE_JPEG_QUALITY, 50}, {0x00, 0x08, 0x02, 0x03}},
      {"jpeg_progressive", ".jpg", color, {cv::IMWRITE_JPEG_PROGRESSIVE, 1, cv::IMWRITE_JPEG_QUALITY, 40}, {0x00, 0x05}},
      {"png_color", ".png", color, {cv::IMWRITE_PNG_COMPRESSION, 9}, {0x01, 0x02, 0x13, 0x00, 0x05}},
      {"png_gray", ".png", gray, {}, {0x02, 0x03}},
      {"png_alpha", ".png", alpha, {}, {0x01, 0x13}},
      {"png_16bit", ".png", deep, {}, {0x01, 0x02}},
  };
  for (const Seed& s : seeds) {
    std::vector<unsigned char> bytes;
    if (!cv::imencode(s.ext, s.image, bytes, s.params)) {
      std::fprintf(stderr, "cannot encode %s\n", s.name.c_str());
      return 1;
    }
    for (unsigned char mode : s.modes) {
      char suffix[8];
      std::snprintf(suffix, sizeof suffix, "_%02x", mode);
      std::ofstream out(dir + s.name + suffix, std::ios::binary);
      out.put(static_cast<char>(mode));
      out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
      if (!out) {
        std::fprintf(stderr, "cannot write %s%s%s\n", dir.c_str(), s.name.c_str(), suffix);
        return 1;
      }
    }
  }
  return 0;
}
