#include "model_store/lidar/point_cloud_io.h"

#include <algorithm>
#include <bit>
#include <cctype>
#include <cmath>
#include <cstring>
#include <sstream>
#include <vector>

#include "model_store/lidar/las_rewrite.h"
#include "model_store/lidar/read_file.h"

namespace ave::model {
namespace {

// PLY scalar types and their sizes.
int PlyTypeSize(const std::string& t) {
  if (t == "char" || t == "uchar" || t == "int8" || t == "uint8") return 1;
  if (t == "short" || t == "ushort" || t == "int16" || t == "uint16") return 2;
  if (t == "int" || t == "uint" || t == "int32" || t == "uint32" || t == "float" || t == "float32") return 4;
  if (t == "double" || t == "float64") return 8;
  return 0;
}

double PlyValue(const char* p, const std::string& t, bool swap) {
  char b[8];
  const int n = PlyTypeSize(t);
  std::memcpy(b, p, n);
  if (swap) std::reverse(b, b + n);
  auto as = [&b]<typename T>(T) { T v; std::memcpy(&v, b, sizeof(T)); return static_cast<double>(v); };
  if (t == "char" || t == "int8") return as(int8_t{});
  if (t == "uchar" || t == "uint8") return as(uint8_t{});
  if (t == "short" || t == "int16") return as(int16_t{});
  if (t == "ushort" || t == "uint16") return as(uint16_t{});
  if (t == "int" || t == "int32") return as(int32_t{});
  if (t == "uint" || t == "uint32") return as(uint32_t{});
  if (t == "float" || t == "float32") return as(float{});
  return as(double{});
}

}  // namespace

CloudBuilder::CloudBuilder(double unit_to_metres, std::string unit_name) {
  cloud_.unit_to_metres = unit_to_metres;
  cloud_.unit_name = std::move(unit_name);
}

int64_t CloudBuilder::Add(const Eigen::Vector3d& p_in_file_units) {
  const Eigen::Vector3d p = p_in_file_units * cloud_.unit_to_metres;
  if (!p.allFinite()) {
    ++cloud_.rejected_non_finite;
    return -1;
  }
  if (!have_origin_) {
    cloud_.origin = p.array().round();
    have_origin_ = true;
  }
  const Eigen::Vector3d local = p - cloud_.origin;
  if (local.cwiseAbs().maxCoeff() > 1e7) {  // float would lose metres: not one survey
    ++cloud_.rejected_non_finite;
    return -1;
  }
  cloud_.xyz.push_back(local.cast<float>());
  return static_cast<int64_t>(cloud_.xyz.size()) - 1;
}

absl::StatusOr<PointCloud> ParsePly(std::string_view bytes, const std::string& name, const CloudReadOptions& options) {
  if (bytes.substr(0, 4) != "ply\n" && bytes.substr(0, 5) != "ply\r\n") return absl::InvalidArgumentError(name + ": byte offset 0: not a PLY file");
  const size_t end = bytes.find("end_header");
  if (end == std::string_view::npos) return absl::InvalidArgumentError(name + ": no end_header line");
  const size_t body = bytes.find('\n', end);
  if (body == std::string_view::npos) return absl::InvalidArgumentError(name + ": byte offset " + std::to_string(end) + ": truncated header");
  std::istringstream header{std::string(bytes.substr(0, end))};
  std::string line, format;
  struct Element {
    std::string name;
    size_t count = 0;
    std::vector<std::pair<std::string, std::string>> props;  // (type, name); list properties unsupported
    bool has_list = false;
  };
  std::vector<Element> elements;
  while (std::getline(header, line)) {
    std::istringstream ls(line);
    std::string word;
    ls >> word;
    if (word == "format") {
      ls >> format;
    } else if (word == "element") {
      Element e;
      ls >> e.name >> e.count;
      elements.push_back(e);
    } else if (word == "property" && !elements.empty()) {
      std::string type, prop;
      ls >> type;
      if (type == "list") {
        elements.back().has_list = true;
        continue;
      }
      ls >> prop;
      if (PlyTypeSize(type) == 0) return absl::InvalidArgumentError(name + ": unknown PLY property type '" + type + "'");
      elements.back().props.emplace_back(type, prop);
    }
  }
  if (format != "ascii" && format != "binary_little_endian" && format != "binary_big_endian") {
    return absl::InvalidArgumentError(name + ": unknown PLY format '" + format + "'");
  }
  if (elements.empty() || elements.front().name != "vertex") return absl::InvalidArgumentError(name + ": the first PLY element must be 'vertex'");
  const Element& v = elements.front();
  if (v.has_list) return absl::InvalidArgumentError(name + ": list properties on 'vertex' are not supported");
  int ix = -1, iy = -1, iz = -1, ii = -1, ic = -1;
  for (size_t k = 0; k < v.props.size(); ++k) {
    const std::string& n = v.props[k].second;
    if (n == "x") ix = static_cast<int>(k);
    if (n == "y") iy = static_cast<int>(k);
    if (n == "z") iz = static_cast<int>(k);
    if (n == "intensity" || n == "scalar_intensity") ii = static_cast<int>(k);
    if (n == "classification" || n == "scalar_classification") ic = static_cast<int>(k);
  }
  if (ix < 0 || iy < 0 || iz < 0) return absl::InvalidArgumentError(name + ": PLY vertex element lacks x, y or z");

  CloudBuilder builder(options.unit_to_metres.value_or(1.0), options.unit_to_metres ? "override" : "metre");
  std::vector<double> values(v.props.size());
  auto add = [&]() {
    if (builder.Add({values[ix], values[iy], values[iz]}) < 0) return;
    PointCloud& c = builder.cloud();
    if (ii >= 0) c.intensity.push_back(static_cast<uint16_t>(FieldInRange(values[ii], 65535.0)));
    if (ic >= 0) c.classification.push_back(static_cast<uint8_t>(FieldInRange(values[ic], 255.0)));
  };
  size_t at = body + 1;
  if (format == "ascii") {
    std::istringstream text{std::string(bytes.substr(at))};
    for (size_t k = 0; k < v.count; ++k) {
      for (double& x : values) {
        std::string token;
        if (!(text >> token)) return absl::InvalidArgumentError(name + ": vertex " + std::to_string(k) + " of " + std::to_string(v.count) + ": truncated");
        char* parsed_end = nullptr;
        x = std::strtod(token.c_str(), &parsed_end);  // accepts nan / inf, which Add() rejects and counts
        if (parsed_end == token.c_str() || *parsed_end != '\0') {
          return absl::InvalidArgumentError(name + ": vertex " + std::to_string(k) + ": not a number '" + token.substr(0, 40) + "'");
        }
      }
      add();
    }
  } else {
    const bool swap = (format == "binary_big_endian") == (std::endian::native == std::endian::little);
    size_t stride = 0;
    for (const auto& [type, prop] : v.props) stride += PlyTypeSize(type);
    if (v.count > (bytes.size() - at) / std::max<size_t>(stride, 1)) {
      return absl::InvalidArgumentError(name + ": byte offset " + std::to_string(bytes.size()) + ": truncated: " +
                                        std::to_string(v.count) + " vertices of " + std::to_string(stride) + " bytes declared from byte " +
                                        std::to_string(at));
    }
    for (size_t k = 0; k < v.count; ++k) {
      size_t off = at + k * stride;
      for (size_t j = 0; j < v.props.size(); ++j) {
        values[j] = PlyValue(bytes.data() + off, v.props[j].first, swap);
        off += PlyTypeSize(v.props[j].first);
      }
      add();
    }
  }
  return builder.Take();
}

absl::StatusOr<PointCloud> ReadPointCloud(const std::string& path, const CloudReadOptions& options) {
  const std::string ext = LowerExtension(path);
  if (ext == "las") return ReadLas(path, LasReadOptions{options.unit_to_metres});
  if (ext == "pcd") {
    absl::StatusOr<PointCloud> cloud = ReadPcd(path, options);
    if (cloud.ok()) {
      cloud->source.path = path;
      cloud->source.format = "pcd";
    }
    return cloud;
  }
  if (ext == "ply") {
    absl::StatusOr<std::string> bytes = ReadWholeFile(path);
    if (!bytes.ok()) return bytes.status();
    absl::StatusOr<PointCloud> cloud = ParsePly(*bytes, path, options);
    if (cloud.ok()) cloud->source = {path, "ply", bytes->size(), Fingerprint64(*bytes)};
    return cloud;
  }
  if (ext == "laz") return absl::InvalidArgumentError(path + ": compressed LAZ is not supported; decompress to LAS first");
  return absl::InvalidArgumentError(path + ": unknown point cloud extension '." + ext + "' (las, ply, pcd)");
}

absl::StatusOr<std::string> WriteClassifiedCloud(const PointCloud& cloud, const std::vector<uint8_t>& classification,
                                                 const std::string& out_path) {
  if (LowerExtension(out_path) != "las") {
    return absl::InvalidArgumentError(out_path + ": classified points are written as LAS; name the output *.las");
  }
  if (cloud.source.format == "las") {
    LasReclassifyStats stats;
    if (absl::Status s = WriteReclassifiedLas(cloud, classification, out_path, &stats); !s.ok()) return s;
    return cloud.source.path + " rewritten to " + out_path + ": " + std::to_string(stats.changed) + " of " +
           std::to_string(stats.records) + " point classes changed, every other byte kept";
  }
  if (absl::Status s = WriteLas(cloud, classification, out_path); !s.ok()) return s;
  return out_path + ": new LAS 1.4 file (point format 6, metres) from the " +
         (cloud.source.format.empty() ? std::string("in-memory") : cloud.source.format) + " input";
}

}  // namespace ave::model
