// libFuzzer target: scenario files are outside input (an operator's or a vendor's YAML). Whatever
// the bytes, LoadSceneText returns a scene or an error naming file/line/field — it never crashes,
// and a scene it accepts can be meshed with every index in range.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>

#include "model_store/scene/campus.h"
#include "model_store/scene/scene_file.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size > (1 << 14)) return 0;
  const std::string text(reinterpret_cast<const char*>(data), size);
  absl::StatusOr<ave::scene::SyntheticCampus> scene = ave::scene::LoadSceneText(text, "fuzz.yaml");
  if (!scene.ok()) {
    if (scene.status().message().empty()) std::abort();  // every refusal must say why
    return 0;
  }
  if (scene->half_extent_m > 400 || scene->buildings.size() > 200) return 0;  // keep each run small
  const ave::TriangleMesh mesh = ave::scene::BuildStaticMesh(*scene, 16.0);
  for (uint32_t i : mesh.indices)
    if (i >= mesh.positions.size()) std::abort();
  return 0;
}
