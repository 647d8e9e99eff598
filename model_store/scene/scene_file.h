#pragma once
// Scenario files, scene part (docs/SCENARIOS.md): terrain, roads, buildings as primitives, trees,
// static objects, cameras and movers read from YAML into a SyntheticCampus. The simulator part of
// the same file (seed, effects, sensors) is read by the simulator's scenario.h (ave_scenario), which
// builds on this. Errors name the file, line and field ("campus.yaml:42: cameras[3].fps: must be > 0").
//
// The bundled scenarios (scenarios/*.yaml next to this file) are compiled into the library, so no
// executable needs files at run time.
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/statusor.h"
#include "model_store/scene/campus.h"

namespace ave::scene {

// Parses the scene part of a scenario document; the simulator keys (seed, effects, sensors) are
// accepted and ignored here. `file_name` only labels errors.
absl::StatusOr<SyntheticCampus> LoadSceneText(const std::string& text, const std::string& file_name);

// The text of a bundled scenario ("campus", "courtyard", "studio", "minimal"), or nullopt.
std::optional<std::string_view> BundledScenarioText(std::string_view name);
std::vector<std::string> BundledScenarioNames();

// The text of a scenario named either as a bundled name or as a path to a .yaml file, with the
// label errors should carry (the bundled name + ".yaml", or the path's file name).
struct ScenarioSource {
  std::string text;
  std::string label;
};
absl::StatusOr<ScenarioSource> ReadScenarioSource(const std::string& name_or_path);

}  // namespace ave::scene
