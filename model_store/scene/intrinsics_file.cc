#include "model_store/scene/intrinsics_file.h"

#include <charconv>
#include <cstdio>
#include <fstream>
#include <sstream>

#include "absl/strings/str_cat.h"
#include "model_store/scene/yaml_fields.h"

namespace ave::calib {

absl::StatusOr<PinholeIntrinsics> ParseIntrinsicsYaml(const std::string& text, const std::string& label) {
  namespace y = scene::yaml;
  try {
    const YAML::Node root = y::ParseYamlText(text);
    const y::Map m(root, "intrinsics");
    m.AllowOnly({"width", "height", "fx", "fy", "cx", "cy", "distortion", "rms_px", "images_used"});
    PinholeIntrinsics k;
    k.width = m.IntIn("width", y::kRequired, 1, 100000);
    k.height = m.IntIn("height", y::kRequired, 1, 100000);
    k.fx = m.PositiveUpTo("fx", y::kRequired);
    k.fy = m.PositiveUpTo("fy", y::kRequired);
    k.cx = m.Number("cx");
    k.cy = m.Number("cy");
    if (m.Has("distortion")) {
      const std::vector<double> d = m.Numbers("distortion", 5, 5);
      for (size_t i = 0; i < 5; ++i) k.distortion[i] = d[i];
    }
    if (const std::string why = k.Check(); !why.empty()) y::Fail(root, "intrinsics", why);
    return k;
  } catch (const y::FieldError& e) {
    return absl::InvalidArgumentError(y::FormatFieldError(label, e));
  }
}

absl::StatusOr<PinholeIntrinsics> ReadIntrinsicsFile(const std::string& path) {
  std::ifstream in(path);
  if (!in) return absl::NotFoundError(absl::StrCat("cannot open intrinsics file ", path));
  std::stringstream text;
  text << in.rdbuf();
  return ParseIntrinsicsYaml(text.str(), path);
}

absl::Status WriteIntrinsicsFile(const std::string& path, const PinholeIntrinsics& k, double rms_px, int images_used) {
  std::ofstream out(path);
  if (!out) return absl::InternalError(absl::StrCat("cannot write ", path));
  // Shortest text that reads back to the same double (std::to_chars): a calibration written and
  // read again is bit-identical (checked by ave_fuzz_intrinsics_file), and stays readable.
  auto num = [](double v) {
    char buf[32];
    const std::to_chars_result r = std::to_chars(buf, buf + sizeof buf, v);
    return std::string(buf, r.ptr);
  };
  out << "# Camera intrinsics (Zhang's method, ave-calibrate); pixel centres at integers (OpenCV).\n"
      << "width: " << k.width << "\nheight: " << k.height << "\nfx: " << num(k.fx) << "\nfy: " << num(k.fy)
      << "\ncx: " << num(k.cx) << "\ncy: " << num(k.cy) << "\ndistortion: [" << num(k.distortion[0]) << ", "
      << num(k.distortion[1]) << ", " << num(k.distortion[2]) << ", " << num(k.distortion[3]) << ", "
      << num(k.distortion[4]) << "]\n";
  if (rms_px >= 0) out << "rms_px: " << rms_px << "\n";
  if (images_used >= 0) out << "images_used: " << images_used << "\n";
  out.flush();
  if (!out) return absl::InternalError(absl::StrCat("write failed: ", path));
  return absl::OkStatus();
}

}  // namespace ave::calib
