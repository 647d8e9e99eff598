#include "sensor_agent/lidar/velodyne_calibration.h"

#include <cmath>
#include <fstream>
#include <optional>
#include <set>
#include <sstream>

#include <yaml-cpp/yaml.h>

#include "absl/strings/str_cat.h"

namespace ave::lidar {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDegToRad = kPi / 180;

VelodyneModel ModelForLaserCount(size_t n) {
  switch (n) {
    case 16: return VelodyneModel::kVlp16;
    case 32: return VelodyneModel::kHdl32e;
    case 64: return VelodyneModel::kHdl64e;
    default: return VelodyneModel::kUnknown;
  }
}

absl::StatusOr<std::string> ReadText(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::NotFoundError(absl::StrCat(path, ": cannot open calibration file"));
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

// The text between <tag> and </tag> at or after `from`, before `end`; nullopt when absent.
std::optional<std::string> TagText(const std::string& text, const std::string& tag, size_t from, size_t end) {
  const std::string open = "<" + tag + ">", close = "</" + tag + ">";
  const size_t a = text.find(open, from);
  if (a == std::string::npos || a >= end) return std::nullopt;
  const size_t b = text.find(close, a);
  if (b == std::string::npos || b > end) return std::nullopt;
  return text.substr(a + open.size(), b - a - open.size());
}

bool ParseDouble(const std::string& s, double& v) {
  std::istringstream in(s);
  in >> v;
  return !in.fail() && std::isfinite(v);
}

}  // namespace

const char* VelodyneModelName(VelodyneModel model) {
  switch (model) {
    case VelodyneModel::kHdl64e: return "HDL-64E";
    case VelodyneModel::kHdl32e: return "HDL-32E";
    case VelodyneModel::kVlp16: return "VLP-16";
    default: return "unknown";
  }
}

int VelodyneLaserCount(VelodyneModel model) {
  switch (model) {
    case VelodyneModel::kHdl64e: return 64;
    case VelodyneModel::kHdl32e: return 32;
    case VelodyneModel::kVlp16: return 16;
    default: return 0;
  }
}

std::string VelodyneCalibration::Check() const {
  if (lasers.empty() || lasers.size() > 64) return absl::StrCat("lasers: ", lasers.size(), " lasers, expected 1 to 64");
  if (!(distance_resolution_m > 0 && distance_resolution_m < 1)) return "distance_resolution_m must be in (0, 1)";
  for (size_t i = 0; i < lasers.size(); ++i) {
    const LaserCalibration& l = lasers[i];
    if (!std::isfinite(l.vert_correction_rad) || std::abs(l.vert_correction_rad) > kPi / 2) {
      return absl::StrCat("lasers[", i, "].vert_correction must be finite, within ±90°");
    }
    if (!std::isfinite(l.rot_correction_rad) || std::abs(l.rot_correction_rad) > 2 * kPi) {
      return absl::StrCat("lasers[", i, "].rot_correction must be finite, within ±360°");
    }
    for (double v : {l.dist_correction_m, l.vert_offset_m, l.horiz_offset_m}) {
      if (!std::isfinite(v) || std::abs(v) > 10) return absl::StrCat("lasers[", i, "]: offsets must be finite, within ±10 m");
    }
  }
  return {};
}

VelodyneCalibration DefaultVelodyneCalibration(VelodyneModel model) {
  VelodyneCalibration c;
  c.model = model;
  switch (model) {
    case VelodyneModel::kVlp16: {
      // VLP-16 user manual: laser id -> vertical angle (degrees), interleaved.
      static constexpr double kVlp16Deg[16] = {-15, 1, -13, 3, -11, 5, -9, 7, -7, 9, -5, 11, -3, 13, -1, 15};
      for (double deg : kVlp16Deg) c.lasers.push_back({.vert_correction_rad = deg * kDegToRad});
      c.source = "built-in VLP-16";
      break;
    }
    case VelodyneModel::kHdl32e: {
      // HDL-32E user manual: laser id -> vertical angle (degrees).
      static constexpr double kHdl32Deg[32] = {-30.67, -9.33, -29.33, -8.00, -28.00, -6.67, -26.67, -5.33,
                                               -25.33, -4.00, -24.00, -2.67, -22.67, -1.33, -21.33, 0.00,
                                               -20.00, 1.33,  -18.67, 2.67,  -17.33, 4.00,  -16.00, 5.33,
                                               -14.67, 6.67,  -13.33, 8.00,  -12.00, 9.33,  -10.67, 10.67};
      for (double deg : kHdl32Deg) c.lasers.push_back({.vert_correction_rad = deg * kDegToRad});
      c.source = "built-in HDL-32E";
      break;
    }
    case VelodyneModel::kHdl64e:
      c = SimulatorVelodyneCalibration(64, 2.0, -24.8);
      c.source = "built-in HDL-64E (the simulator's layout: no db.xml)";
      break;
    default:
      break;
  }
  return c;
}

VelodyneCalibration SimulatorVelodyneCalibration(int rings, double fov_up_deg, double fov_down_deg) {
  VelodyneCalibration c;
  c.model = ModelForLaserCount(static_cast<size_t>(rings)) == VelodyneModel::kHdl64e ? VelodyneModel::kHdl64e
                                                                                     : VelodyneModel::kUnknown;
  for (int r = 0; r < rings; ++r) {
    const double deg = rings == 1 ? fov_up_deg : fov_up_deg - r * (fov_up_deg - fov_down_deg) / (rings - 1);
    c.lasers.push_back({.vert_correction_rad = deg * kDegToRad});
  }
  c.source = absl::StrCat("simulator layout (", rings, " rings, ", fov_up_deg, "° to ", fov_down_deg, "°)");
  return c;
}

absl::StatusOr<VelodyneCalibration> ParseVelodyneDbXml(const std::string& text, const std::string& name) {
  VelodyneCalibration c;
  c.source = name;
  const size_t npos = std::string::npos;
  if (auto lsb = TagText(text, "distLSB_", 0, npos)) {
    double v;
    if (!ParseDouble(*lsb, v)) return absl::InvalidArgumentError(absl::StrCat(name, ": distLSB_ '", *lsb, "' is not a number"));
    c.distance_resolution_m = v * 0.01;
  }
  std::vector<std::optional<LaserCalibration>> by_id;
  size_t at = 0;
  for (int item = 0;; ++item) {
    const size_t px = text.find("<px", at);
    if (px == npos) break;
    const size_t end = text.find("</px>", px);
    if (end == npos) return absl::InvalidArgumentError(absl::StrCat(name, ": points_ item ", item, ": <px> is not closed"));
    at = end + 5;
    auto field = [&](const char* tag, double& v) -> absl::Status {
      const std::optional<std::string> s = TagText(text, tag, px, end);
      if (!s) return absl::InvalidArgumentError(absl::StrCat(name, ": points_ item ", item, ": missing ", tag));
      if (!ParseDouble(*s, v)) return absl::InvalidArgumentError(absl::StrCat(name, ": points_ item ", item, ": ", tag, " '", *s, "' is not a number"));
      return absl::OkStatus();
    };
    double id = 0, rot = 0, vert = 0, dist = 0, voff = 0, hoff = 0;
    for (auto [tag, v] : {std::pair<const char*, double*>{"id_", &id}, {"rotCorrection_", &rot}, {"vertCorrection_", &vert},
                          {"distCorrection_", &dist}, {"vertOffsetCorrection_", &voff}, {"horizOffsetCorrection_", &hoff}}) {
      if (absl::Status s = field(tag, *v); !s.ok()) return s;
    }
    if (id < 0 || id >= 64 || id != std::floor(id)) {
      return absl::InvalidArgumentError(absl::StrCat(name, ": points_ item ", item, ": id_ ", id, " is not a laser id in [0, 63]"));
    }
    const size_t i = static_cast<size_t>(id);
    if (by_id.size() <= i) by_id.resize(i + 1);
    if (by_id[i]) return absl::InvalidArgumentError(absl::StrCat(name, ": points_ item ", item, ": laser id_ ", i, " appears twice"));
    by_id[i] = LaserCalibration{.vert_correction_rad = vert * kDegToRad,
                                .rot_correction_rad = rot * kDegToRad,
                                .dist_correction_m = dist * 0.01,
                                .vert_offset_m = voff * 0.01,
                                .horiz_offset_m = hoff * 0.01};
  }
  if (by_id.empty()) return absl::InvalidArgumentError(absl::StrCat(name, ": no points_ items (<px>): not a Velodyne db.xml"));
  for (size_t i = 0; i < by_id.size(); ++i) {
    if (!by_id[i]) return absl::InvalidArgumentError(absl::StrCat(name, ": laser id ", i, " is missing (ids up to ", by_id.size() - 1, ")"));
    c.lasers.push_back(*by_id[i]);
  }
  c.model = ModelForLaserCount(c.lasers.size());
  if (const std::string why = c.Check(); !why.empty()) return absl::InvalidArgumentError(absl::StrCat(name, ": ", why));
  return c;
}

absl::StatusOr<VelodyneCalibration> ParseVelodyneYaml(const std::string& text, const std::string& name) {
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    return absl::InvalidArgumentError(absl::StrCat(name, ":", e.mark.line + 1, ": ", e.msg));
  }
  if (!root.IsMap() || !root["lasers"] || !root["lasers"].IsSequence()) {
    return absl::InvalidArgumentError(absl::StrCat(name, ": lasers: expected a sequence (ROS velodyne calibration YAML)"));
  }
  VelodyneCalibration c;
  c.source = name;
  try {
    if (root["distance_resolution"]) c.distance_resolution_m = root["distance_resolution"].as<double>();
    const YAML::Node lasers = root["lasers"];
    std::vector<std::optional<LaserCalibration>> by_id(lasers.size());
    for (size_t k = 0; k < lasers.size(); ++k) {
      const YAML::Node l = lasers[k];
      const std::string where = absl::StrCat(name, ":", l.Mark().line + 1, ": lasers[", k, "]");
      if (!l.IsMap() || !l["laser_id"] || !l["vert_correction"]) {
        return absl::InvalidArgumentError(absl::StrCat(where, ": needs laser_id and vert_correction"));
      }
      const int id = l["laser_id"].as<int>();
      if (id < 0 || static_cast<size_t>(id) >= lasers.size()) {
        return absl::InvalidArgumentError(absl::StrCat(where, ".laser_id: ", id, " is outside [0, ", lasers.size() - 1, "]"));
      }
      if (by_id[id]) return absl::InvalidArgumentError(absl::StrCat(where, ".laser_id: ", id, " appears twice"));
      auto get = [&](const char* key) { return l[key] ? l[key].as<double>() : 0.0; };
      by_id[id] = LaserCalibration{.vert_correction_rad = get("vert_correction"),
                                   .rot_correction_rad = get("rot_correction"),
                                   .dist_correction_m = get("dist_correction"),
                                   .vert_offset_m = get("vert_offset_correction"),
                                   .horiz_offset_m = get("horiz_offset_correction")};
    }
    for (auto& l : by_id) c.lasers.push_back(*l);  // every slot filled: ids are unique and in range
    if (root["num_lasers"] && root["num_lasers"].as<int>() != static_cast<int>(c.lasers.size())) {
      return absl::InvalidArgumentError(absl::StrCat(name, ": num_lasers ", root["num_lasers"].as<int>(), " but ", c.lasers.size(), " lasers listed"));
    }
  } catch (const YAML::Exception& e) {
    return absl::InvalidArgumentError(absl::StrCat(name, ":", e.mark.line + 1, ": ", e.msg));
  }
  c.model = ModelForLaserCount(c.lasers.size());
  if (const std::string why = c.Check(); !why.empty()) return absl::InvalidArgumentError(absl::StrCat(name, ": ", why));
  return c;
}

absl::StatusOr<VelodyneCalibration> ReadVelodyneDbXml(const std::string& path) {
  absl::StatusOr<std::string> text = ReadText(path);
  if (!text.ok()) return text.status();
  return ParseVelodyneDbXml(*text, path);
}

absl::StatusOr<VelodyneCalibration> ReadVelodyneYaml(const std::string& path) {
  absl::StatusOr<std::string> text = ReadText(path);
  if (!text.ok()) return text.status();
  return ParseVelodyneYaml(*text, path);
}

absl::StatusOr<VelodyneCalibration> ReadVelodyneCalibration(const std::string& path) {
  auto ends = [&](const std::string& ext) { return path.size() >= ext.size() && path.compare(path.size() - ext.size(), ext.size(), ext) == 0; };
  if (ends(".xml")) return ReadVelodyneDbXml(path);
  if (ends(".yaml") || ends(".yml")) return ReadVelodyneYaml(path);
  return absl::InvalidArgumentError(absl::StrCat(path, ": calibration must be a Velodyne db.xml (.xml) or a ROS velodyne YAML (.yaml)"));
}

}  // namespace ave::lidar
