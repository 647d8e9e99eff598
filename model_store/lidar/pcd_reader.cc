// PCD through PCL: the only file of model_store that includes PCL headers (BUILD_NOTES.md: keep
// them out of widely included headers). Coordinates are read as stored (float32 or float64), so a
// double-precision PCD keeps large world coordinates exact.
#include <algorithm>
#include <charconv>
#include <cstring>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <vector>

#include "model_store/lidar/point_cloud_io.h"

#ifdef AVE_HAVE_PCL
#include <pcl/PCLPointCloud2.h>
#include <pcl/common/io.h>
#include <pcl/io/pcd_io.h>
#endif

namespace ave::model {

#ifdef AVE_HAVE_PCL
namespace {

// PCL 1.13's PCDReader::read dereferences bad memory on some malformed headers (found while
// writing issue 14's bad-input tests: a text file that is not a PCD crashed `ave-model build`).
// The header is checked here first: the PCD 0.7 keywords up to DATA, x/y/z among the fields,
// FIELDS/SIZE/TYPE/COUNT of one length, a point count, and for binary data enough bytes.
absl::Status CheckPcdHeader(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::NotFoundError(path + ": cannot open");
  std::map<std::string, std::vector<std::string>> keys;
  std::string line;
  int lines = 0;
  while (std::getline(in, line) && lines++ < 64) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty() || line[0] == '#') continue;
    std::istringstream words(line);
    std::string key, word;
    words >> key;
    static const std::set<std::string> kKeys = {"VERSION", "FIELDS", "SIZE", "TYPE", "COUNT", "WIDTH",
                                                "HEIGHT", "VIEWPOINT", "POINTS", "DATA"};
    if (!kKeys.count(key)) {
      return absl::InvalidArgumentError(path + ": header line " + std::to_string(lines) + ": not a PCD header keyword '" +
                                        key.substr(0, 40) + "'");
    }
    std::vector<std::string>& values = keys[key];
    while (words >> word) values.push_back(word);
    if (key == "DATA") break;
  }
  for (const char* required : {"FIELDS", "SIZE", "TYPE", "WIDTH", "POINTS", "DATA"}) {
    if (!keys.count(required)) return absl::InvalidArgumentError(path + ": PCD header lacks " + required);
  }
  const std::vector<std::string>& fields = keys["FIELDS"];
  const size_t n_fields = fields.size();
  if (keys["SIZE"].size() != n_fields || keys["TYPE"].size() != n_fields ||
      (keys.count("COUNT") && keys["COUNT"].size() != n_fields)) {
    return absl::InvalidArgumentError(path + ": PCD header: FIELDS, SIZE, TYPE and COUNT differ in length");
  }
  for (const char* axis : {"x", "y", "z"}) {
    if (std::find(fields.begin(), fields.end(), axis) == fields.end()) {
      return absl::InvalidArgumentError(path + ": PCD lacks an x, y or z field");
    }
  }
  auto number = [&](const std::string& text, uint64_t max, const char* what) -> absl::StatusOr<uint64_t> {
    uint64_t v = 0;
    const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
    if (ec != std::errc() || end != text.data() + text.size() || v > max) {
      return absl::InvalidArgumentError(path + ": PCD header: " + what + " '" + text.substr(0, 40) + "' is not a count up to " +
                                        std::to_string(max));
    }
    return v;
  };
  size_t point_bytes = 0;
  for (size_t i = 0; i < n_fields; ++i) {
    absl::StatusOr<uint64_t> size = number(keys["SIZE"][i], 8, "SIZE");
    if (!size.ok()) return size.status();
    absl::StatusOr<uint64_t> count = keys.count("COUNT") ? number(keys["COUNT"][i], 1 << 16, "COUNT") : uint64_t{1};
    if (!count.ok()) return count.status();
    // A field of COUNT 0 made PCL size its buffer from a wrapped-around point size (a 4 GiB
    // allocation, ave_fuzz_point_cloud); SIZE must be one PCL lays out for its TYPE.
    if (*count == 0) return absl::InvalidArgumentError(path + ": PCD header: COUNT of field '" + fields[i].substr(0, 40) + "' is 0");
    const std::string& type = keys["TYPE"][i];
    const bool size_fits_type = (type == "F" && (*size == 4 || *size == 8)) ||
                                ((type == "I" || type == "U") && (*size == 1 || *size == 2 || *size == 4));
    if (!size_fits_type) {
      return absl::InvalidArgumentError(path + ": PCD header: field '" + fields[i].substr(0, 40) + "' has TYPE '" +
                                        type.substr(0, 8) + "' with SIZE " + std::to_string(*size) +
                                        " (F takes 4 or 8, I and U 1, 2 or 4)");
    }
    point_bytes += *size * *count;
  }
  if (keys["POINTS"].size() != 1) return absl::InvalidArgumentError(path + ": PCD header: POINTS takes one value");
  absl::StatusOr<uint64_t> points = number(keys["POINTS"][0], uint64_t{1} << 32, "POINTS");
  if (!points.ok()) return points.status();
  if (*points == 0) return absl::InvalidArgumentError(path + ": PCD holds no points (POINTS 0)");
  // PCL sizes its buffer from WIDTH x HEIGHT, not POINTS: they must agree.
  if (keys["WIDTH"].size() != 1 || (keys.count("HEIGHT") && keys["HEIGHT"].size() != 1))
    return absl::InvalidArgumentError(path + ": PCD header: WIDTH and HEIGHT take one value each");
  absl::StatusOr<uint64_t> width = number(keys["WIDTH"][0], uint64_t{1} << 32, "WIDTH");
  if (!width.ok()) return width.status();
  absl::StatusOr<uint64_t> height = keys.count("HEIGHT") ? number(keys["HEIGHT"][0], uint64_t{1} << 32, "HEIGHT") : uint64_t{1};
  if (!height.ok()) return height.status();
  if (*width * *height != *points) {
    return absl::InvalidArgumentError(path + ": PCD header: WIDTH x HEIGHT = " + std::to_string(*width) + " x " +
                                      std::to_string(*height) + " is not POINTS " + std::to_string(*points));
  }
  const std::string data = keys["DATA"].empty() ? "" : keys["DATA"][0];
  if (data != "ascii" && data != "binary" && data != "binary_compressed") {
    return absl::InvalidArgumentError(path + ": PCD header: DATA must be ascii, binary or binary_compressed, not '" +
                                      data.substr(0, 40) + "'");
  }
  // PCL's header loop does not stop at DATA: it reads on while a line is empty, a comment or
  // VERSION, and a line whose first word starts with a header keyword is taken as header again.
  // Binary data that begins with such bytes ("COLUMNS...", found by ave_fuzz_point_cloud) made PCL
  // re-lay its fields over a buffer sized for the first layout and crash; refused here.
  const std::streamoff body = in.tellg();
  for (std::string next; std::getline(in, next);) {
    if (next.empty()) continue;
    std::istringstream words(next);
    std::string first;
    words >> first;
    if (first.rfind('#', 0) == 0 || first.rfind("VERSION", 0) == 0) continue;
    for (const char* keyword : {"FIELDS", "COLUMNS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT", "VIEWPOINT", "POINTS", "DATA"}) {
      if (first.rfind(keyword, 0) == 0) {
        return absl::InvalidArgumentError(path + ": PCD data begins with the header keyword " + keyword +
                                          " (PCL would read it as header, not as points)");
      }
    }
    break;
  }
  in.clear();
  if (data == "binary") {
    in.seekg(0, std::ios::end);
    const std::streamoff file_bytes = in.tellg();
    if (body < 0 || file_bytes < 0 || static_cast<uint64_t>(file_bytes - body) < *points * point_bytes) {
      return absl::InvalidArgumentError(path + ": PCD data shorter than its header says (" + std::to_string(*points) +
                                        " points of " + std::to_string(point_bytes) + " bytes)");
    }
  }
  return absl::OkStatus();
}

const pcl::PCLPointField* FindField(const pcl::PCLPointCloud2& blob, const std::string& name) {
  for (const auto& f : blob.fields) {
    if (f.name == name) return &f;
  }
  return nullptr;
}

double FieldValue(const uint8_t* p, const pcl::PCLPointField& f) {
  auto as = [p]<typename T>(T) { T v; std::memcpy(&v, p, sizeof(T)); return static_cast<double>(v); };
  switch (f.datatype) {
    case pcl::PCLPointField::INT8: return as(int8_t{});
    case pcl::PCLPointField::UINT8: return as(uint8_t{});
    case pcl::PCLPointField::INT16: return as(int16_t{});
    case pcl::PCLPointField::UINT16: return as(uint16_t{});
    case pcl::PCLPointField::INT32: return as(int32_t{});
    case pcl::PCLPointField::UINT32: return as(uint32_t{});
    case pcl::PCLPointField::FLOAT64: return as(double{});
    default: return as(float{});
  }
}

}  // namespace

bool HavePcdSupport() { return true; }

absl::StatusOr<PointCloud> ReadPcd(const std::string& path, const CloudReadOptions& options) {
  if (absl::Status s = CheckPcdHeader(path); !s.ok()) return s;
  pcl::PCLPointCloud2 blob;
  pcl::PCDReader reader;
  if (reader.read(path, blob) < 0) return absl::InvalidArgumentError(path + ": PCL could not read this PCD file");
  const pcl::PCLPointField* fx = FindField(blob, "x");
  const pcl::PCLPointField* fy = FindField(blob, "y");
  const pcl::PCLPointField* fz = FindField(blob, "z");
  if (!fx || !fy || !fz) return absl::InvalidArgumentError(path + ": PCD lacks an x, y or z field");
  const pcl::PCLPointField* fi = FindField(blob, "intensity");
  // A SIZE that does not match its TYPE (e.g. "SIZE 2" with "TYPE F") gives a field PCL lays out
  // narrower than the value it stands for: refused, never read past the point (found by
  // ave_fuzz_point_cloud).
  for (const pcl::PCLPointField* f : {fx, fy, fz, fi}) {
    if (f == nullptr) continue;
    const int bytes = pcl::getFieldSize(f->datatype);
    if (bytes == 0 || f->datatype > pcl::PCLPointField::FLOAT64)
      return absl::InvalidArgumentError(path + ": PCD field '" + f->name + "' has a SIZE and TYPE pair this reader does not take");
    if (static_cast<uint64_t>(f->offset) + static_cast<uint64_t>(bytes) > blob.point_step)
      return absl::InvalidArgumentError(path + ": PCD field '" + f->name + "' (" + std::to_string(bytes) +
                                        " bytes at offset " + std::to_string(f->offset) + ") does not fit its " +
                                        std::to_string(blob.point_step) + "-byte point; its SIZE does not match its TYPE");
  }
  const size_t n = static_cast<size_t>(blob.width) * blob.height;
  if (blob.data.size() < n * blob.point_step) return absl::InvalidArgumentError(path + ": PCD data shorter than its header says");
  CloudBuilder builder(options.unit_to_metres.value_or(1.0), options.unit_to_metres ? "override" : "metre");
  for (size_t k = 0; k < n; ++k) {
    const uint8_t* p = blob.data.data() + k * blob.point_step;
    if (builder.Add({FieldValue(p + fx->offset, *fx), FieldValue(p + fy->offset, *fy), FieldValue(p + fz->offset, *fz)}) < 0) continue;
    if (fi) builder.cloud().intensity.push_back(static_cast<uint16_t>(FieldInRange(FieldValue(p + fi->offset, *fi), 65535.0)));
  }
  return builder.Take();
}

#else

bool HavePcdSupport() { return false; }

absl::StatusOr<PointCloud> ReadPcd(const std::string& path, const CloudReadOptions&) {
  return absl::UnimplementedError(path + ": this build has no PCL, so PCD files cannot be read");
}

#endif

}  // namespace ave::model
