#include "model_store/db/mesh_blob.h"

#include <bit>
#include <cmath>
#include <cstring>

#include "absl/status/status.h"
#include "model_store/common/le_bytes.h"

namespace ave::store {
namespace {

constexpr char kMagic[4] = {'A', 'V', 'E', 'M'};

using bytes::PutF32;
using bytes::PutF64;
using bytes::PutLe;
using Reader = bytes::LeReader;

}  // namespace

std::string CheckMesh(const TriangleMesh& m) {
  const size_t n = m.positions.size();
  if (!m.origin.allFinite()) return "origin must be finite";
  if (n > UINT32_MAX) return "too many positions";
  if (!m.normals.empty() && m.normals.size() != n) return "normals must be empty or one per position";
  if (!m.colors.empty() && m.colors.size() != n) return "colors must be empty or one per position";
  if (m.indices.size() % 3 != 0) return "indices must come in threes";
  const size_t t = m.TriangleCount();
  if (!m.triangle_material.empty() && m.triangle_material.size() != t)
    return "triangle_material must be empty or one per triangle";
  if (!m.triangle_object.empty() && m.triangle_object.size() != t)
    return "triangle_object must be empty or one per triangle";
  for (size_t i = 0; i < m.indices.size(); ++i) {
    if (m.indices[i] >= n) return "indices[" + std::to_string(i) + "] = " + std::to_string(m.indices[i]) +
                                  " is out of range (" + std::to_string(n) + " positions)";
  }
  for (SurfaceMaterial s : m.triangle_material) {
    if (static_cast<uint8_t>(s) > static_cast<uint8_t>(SurfaceMaterial::kVegetation)) return "unknown triangle_material";
  }
  return {};
}

absl::StatusOr<std::string> EncodeMesh(const TriangleMesh& m, std::string_view context) {
  if (std::string why = CheckMesh(m); !why.empty()) return absl::InvalidArgumentError(std::string(context) + ": " + why);
  std::string out(kMagic, 4);
  out.reserve(4 + 4 + 6 * 8 + 3 * 8 + 36 * m.positions.size() + 4 * m.indices.size() + 5 * m.TriangleCount());
  PutLe<uint32_t>(out, kMeshBlobVersion);
  for (size_t c : {m.positions.size(), m.normals.size(), m.colors.size(), m.indices.size(), m.triangle_material.size(),
                   m.triangle_object.size()}) {
    PutLe<uint64_t>(out, c);
  }
  for (int i = 0; i < 3; ++i) PutF64(out, m.origin[i]);
  for (const auto* arr : {&m.positions, &m.normals, &m.colors}) {
    for (const Eigen::Vector3f& v : *arr) {
      for (int i = 0; i < 3; ++i) PutF32(out, v[i]);
    }
  }
  for (uint32_t i : m.indices) PutLe<uint32_t>(out, i);
  for (SurfaceMaterial s : m.triangle_material) out.push_back(static_cast<char>(s));
  for (int32_t o : m.triangle_object) PutLe<uint32_t>(out, static_cast<uint32_t>(o));
  return out;
}

absl::StatusOr<TriangleMesh> DecodeMesh(std::string_view blob, std::string_view context) {
  auto loss = [&](const std::string& why) { return absl::DataLossError(std::string(context) + ": mesh blob " + why); };
  if (blob.size() < 8 || std::memcmp(blob.data(), kMagic, 4) != 0) return loss("does not start with magic \"AVEM\"");
  Reader r(blob.substr(4));
  uint32_t version = 0;
  r.Get(version);
  if (version != kMeshBlobVersion)
    return loss("has format version " + std::to_string(version) + ", this build reads " +
                std::to_string(kMeshBlobVersion));
  uint64_t np, nn, nc, ni, nm, no;
  if (!(r.Get(np) && r.Get(nn) && r.Get(nc) && r.Get(ni) && r.Get(nm) && r.Get(no))) return loss("is truncated (header)");
  // Bound each count by the bytes left before multiplying, so corrupt counts cannot overflow.
  const uint64_t left = r.remaining();
  if (np > left || nn > left || nc > left || ni > left || nm > left || no > left)
    return loss("has counts larger than the blob");
  if ((nn != 0 && nn != np) || (nc != 0 && nc != np) || ni % 3 != 0 || (nm != 0 && nm != ni / 3) ||
      (no != 0 && no != ni / 3))
    return loss("has inconsistent counts (positions " + std::to_string(np) + ", normals " + std::to_string(nn) +
                ", colors " + std::to_string(nc) + ", indices " + std::to_string(ni) + ", materials " +
                std::to_string(nm) + ", objects " + std::to_string(no) + ")");
  const uint64_t expected = 24 + 12 * (np + nn + nc) + 4 * ni + nm + 4 * no;
  if (left != expected)
    return loss("has " + std::to_string(left) + " payload bytes, counts imply " + std::to_string(expected) +
                (left < expected ? " (truncated)" : " (trailing bytes)"));
  TriangleMesh m;
  for (int i = 0; i < 3; ++i) r.GetF64(m.origin[i]);
  for (auto [arr, count] : {std::pair{&m.positions, np}, std::pair{&m.normals, nn}, std::pair{&m.colors, nc}}) {
    arr->resize(count);
    for (Eigen::Vector3f& v : *arr) {
      for (int i = 0; i < 3; ++i) r.GetF32(v[i]);
    }
  }
  m.indices.resize(ni);
  for (uint32_t& i : m.indices) {
    r.Get(i);
    if (i >= np) return loss("has index " + std::to_string(i) + " out of range (" + std::to_string(np) + " positions)");
  }
  m.triangle_material.resize(nm);
  for (SurfaceMaterial& s : m.triangle_material) {
    uint8_t u = 0;
    r.Get(u);
    if (u > static_cast<uint8_t>(SurfaceMaterial::kVegetation)) return loss("has unknown material " + std::to_string(u));
    s = static_cast<SurfaceMaterial>(u);
  }
  m.triangle_object.resize(no);
  for (int32_t& o : m.triangle_object) {
    uint32_t u = 0;
    r.Get(u);
    o = static_cast<int32_t>(u);
  }
  if (!m.origin.allFinite()) return loss("has a non-finite origin");
  return m;
}

}  // namespace ave::store
