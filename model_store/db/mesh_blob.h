#pragma once
// Binary encoding of TriangleMesh for the static_models table. All fields little-endian:
//   "AVEM" | u32 format version (1) | u64 counts: positions, normals, colors, indices,
//   triangle_material, triangle_object | f64 origin[3] | f32 positions[3n] | f32 normals[3n]
//   | f32 colors[3n] | u32 indices | u8 triangle_material | i32 triangle_object
// normals/colors are empty or one per position; material/object empty or one per triangle.
#include <cstdint>
#include <string>
#include <string_view>

#include "absl/status/statusor.h"
#include "model_store/geometry/mesh.h"

namespace ave::store {

inline constexpr uint32_t kMeshBlobVersion = 1;

// Empty when the mesh may be stored; otherwise what is inconsistent.
std::string CheckMesh(const TriangleMesh& mesh);

// InvalidArgument (prefixed by `context`) when CheckMesh fails.
absl::StatusOr<std::string> EncodeMesh(const TriangleMesh& mesh, std::string_view context);

// DataLoss naming `context` (e.g. "static_models version 3") on a wrong magic or version,
// a truncated or oversized blob, inconsistent counts or out-of-range indices and materials.
absl::StatusOr<TriangleMesh> DecodeMesh(std::string_view blob, std::string_view context);

}  // namespace ave::store
