#include "model_store/terrain/mesh_export.h"

#include <algorithm>
#include <cstring>
#include <sstream>

#include <nlohmann/json.hpp>

#include "model_store/lidar/read_file.h"

namespace ave::model {
namespace {

template <typename T>
void Append(std::string& out, const T& v) {
  out.append(reinterpret_cast<const char*>(&v), sizeof(T));
}

std::string OriginText(const TriangleMesh& mesh) {
  std::ostringstream s;
  s.precision(17);
  s << mesh.origin.x() << ' ' << mesh.origin.y() << ' ' << mesh.origin.z();
  return s.str();
}

absl::Status CheckMesh(const TriangleMesh& mesh) {
  if (mesh.indices.size() % 3 != 0) return absl::InvalidArgumentError("mesh index count is not a multiple of 3");
  for (uint32_t i : mesh.indices) {
    if (i >= mesh.positions.size()) return absl::InvalidArgumentError("mesh index " + std::to_string(i) + " out of range");
  }
  return absl::OkStatus();
}

std::string EncodePly(const TriangleMesh& mesh) {
  const bool normals = mesh.normals.size() == mesh.positions.size();
  const bool colors = mesh.colors.size() == mesh.positions.size();
  std::string out = "ply\nformat binary_little_endian 1.0\ncomment origin " + OriginText(mesh) +
                    "\nelement vertex " + std::to_string(mesh.positions.size()) +
                    "\nproperty float x\nproperty float y\nproperty float z\n";
  if (normals) out += "property float nx\nproperty float ny\nproperty float nz\n";
  if (colors) out += "property uchar red\nproperty uchar green\nproperty uchar blue\n";
  out += "element face " + std::to_string(mesh.TriangleCount()) + "\nproperty list uchar uint vertex_indices\nend_header\n";
  for (size_t i = 0; i < mesh.positions.size(); ++i) {
    for (int k = 0; k < 3; ++k) Append(out, mesh.positions[i][k]);
    if (normals) for (int k = 0; k < 3; ++k) Append(out, mesh.normals[i][k]);
    if (colors) for (int k = 0; k < 3; ++k) Append(out, static_cast<uint8_t>(std::clamp(mesh.colors[i][k], 0.f, 1.f) * 255 + 0.5f));
  }
  for (size_t t = 0; t < mesh.TriangleCount(); ++t) {
    Append(out, uint8_t{3});
    for (int k = 0; k < 3; ++k) Append(out, mesh.indices[3 * t + k]);
  }
  return out;
}

std::string EncodeObj(const TriangleMesh& mesh) {
  std::ostringstream s;
  s << "# ave-model mesh; positions in metres relative to the origin below\n# origin " << OriginText(mesh) << "\n";
  for (const auto& p : mesh.positions) s << "v " << p.x() << ' ' << p.y() << ' ' << p.z() << '\n';
  const bool normals = mesh.normals.size() == mesh.positions.size();
  if (normals) for (const auto& n : mesh.normals) s << "vn " << n.x() << ' ' << n.y() << ' ' << n.z() << '\n';
  for (size_t t = 0; t < mesh.TriangleCount(); ++t) {
    s << 'f';
    for (int k = 0; k < 3; ++k) {
      const uint32_t i = mesh.indices[3 * t + k] + 1;
      s << ' ' << i;
      if (normals) s << "//" << i;
    }
    s << '\n';
  }
  return s.str();
}

std::string Base64(const std::string& in) {
  static const char* kTable = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((in.size() + 2) / 3 * 4);
  for (size_t i = 0; i < in.size(); i += 3) {
    uint32_t v = static_cast<uint8_t>(in[i]) << 16;
    if (i + 1 < in.size()) v |= static_cast<uint8_t>(in[i + 1]) << 8;
    if (i + 2 < in.size()) v |= static_cast<uint8_t>(in[i + 2]);
    out += kTable[(v >> 18) & 63];
    out += kTable[(v >> 12) & 63];
    out += i + 1 < in.size() ? kTable[(v >> 6) & 63] : '=';
    out += i + 2 < in.size() ? kTable[v & 63] : '=';
  }
  return out;
}

}  // namespace

absl::StatusOr<std::string> EncodeGltf(const TriangleMesh& mesh, bool binary) {
  if (absl::Status s = CheckMesh(mesh); !s.ok()) return s;
  if (mesh.positions.empty()) return absl::InvalidArgumentError("glTF: the mesh has no vertices");
  using nlohmann::json;
  std::string bin;
  json views = json::array(), accessors = json::array(), attributes = json::object();
  auto add_vec3 = [&](const std::vector<Eigen::Vector3f>& v, const char* name, bool bounds) {
    const size_t offset = bin.size();
    Eigen::Vector3f lo = v[0], hi = v[0];
    for (const auto& p : v) {
      for (int k = 0; k < 3; ++k) Append(bin, p[k]);
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    }
    views.push_back({{"buffer", 0}, {"byteOffset", offset}, {"byteLength", bin.size() - offset}, {"target", 34962}});
    json a = {{"bufferView", views.size() - 1}, {"componentType", 5126}, {"count", v.size()}, {"type", "VEC3"}};
    if (bounds) {
      a["min"] = {lo.x(), lo.y(), lo.z()};
      a["max"] = {hi.x(), hi.y(), hi.z()};
    }
    accessors.push_back(a);
    attributes[name] = accessors.size() - 1;
  };
  add_vec3(mesh.positions, "POSITION", true);
  if (mesh.normals.size() == mesh.positions.size()) add_vec3(mesh.normals, "NORMAL", false);
  if (mesh.colors.size() == mesh.positions.size()) add_vec3(mesh.colors, "COLOR_0", false);
  const size_t index_offset = bin.size();
  for (uint32_t i : mesh.indices) Append(bin, i);
  views.push_back({{"buffer", 0}, {"byteOffset", index_offset}, {"byteLength", bin.size() - index_offset}, {"target", 34963}});
  accessors.push_back({{"bufferView", views.size() - 1}, {"componentType", 5125}, {"count", mesh.indices.size()}, {"type", "SCALAR"}});
  json buffer = {{"byteLength", bin.size()}};
  if (!binary) buffer["uri"] = "data:application/octet-stream;base64," + Base64(bin);
  // glTF is y-up: the node rotates the local east-north-up frame (-90 deg about x).
  const json doc = {
      {"asset", {{"version", "2.0"}, {"generator", "ave-model"}, {"extras", {{"origin", {mesh.origin.x(), mesh.origin.y(), mesh.origin.z()}}}}}},
      {"scene", 0},
      {"scenes", {{{"nodes", {0}}}}},
      {"nodes", {{{"mesh", 0}, {"rotation", {-0.7071067811865476, 0, 0, 0.7071067811865476}}}}},
      {"meshes", {{{"primitives", {{{"attributes", attributes}, {"indices", accessors.size() - 1}, {"mode", 4}}}}}}},
      {"buffers", {buffer}},
      {"bufferViews", views},
      {"accessors", accessors},
  };
  std::string text = doc.dump();
  if (!binary) return text;
  while (text.size() % 4) text += ' ';
  while (bin.size() % 4) bin += '\0';
  std::string out;
  Append(out, uint32_t{0x46546C67});  // "glTF"
  Append(out, uint32_t{2});
  Append(out, static_cast<uint32_t>(12 + 8 + text.size() + 8 + bin.size()));
  Append(out, static_cast<uint32_t>(text.size()));
  Append(out, uint32_t{0x4E4F534A});  // JSON
  out += text;
  Append(out, static_cast<uint32_t>(bin.size()));
  Append(out, uint32_t{0x004E4942});  // BIN
  out += bin;
  return out;
}

absl::Status WriteMesh(const TriangleMesh& mesh, const std::string& path) {
  if (absl::Status s = CheckMesh(mesh); !s.ok()) return absl::InvalidArgumentError(path + ": " + std::string(s.message()));
  const std::string ext = LowerExtension(path);
  std::string bytes;
  if (ext == "ply") {
    bytes = EncodePly(mesh);
  } else if (ext == "obj") {
    bytes = EncodeObj(mesh);
  } else if (ext == "gltf" || ext == "glb") {
    absl::StatusOr<std::string> gltf = EncodeGltf(mesh, ext == "glb");
    if (!gltf.ok()) return absl::InvalidArgumentError(path + ": " + std::string(gltf.status().message()));
    bytes = std::move(*gltf);
  } else {
    return absl::InvalidArgumentError(path + ": unknown mesh extension '." + ext + "' (ply, obj, gltf, glb)");
  }
  return WriteWholeFile(path, bytes);
}

}  // namespace ave::model
