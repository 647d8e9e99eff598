// libFuzzer target: the model store's static-mesh blob decoder (data read back from SQLite, which
// a damaged or hostile file controls). A decoded mesh must re-encode (it passed CheckMesh).
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "model_store/db/mesh_blob.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view blob(reinterpret_cast<const char*>(data), size);
  absl::StatusOr<ave::TriangleMesh> mesh = ave::store::DecodeMesh(blob, "fuzz");
  if (mesh.ok() && !ave::store::EncodeMesh(*mesh, "fuzz").ok()) __builtin_trap();
  return 0;
}
