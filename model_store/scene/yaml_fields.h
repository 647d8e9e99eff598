#pragma once
// Strict reading of YAML scenario documents (docs/SCENARIOS.md): every map is checked for unknown
// keys (a typo is an error, with the closest known key as a hint), every value for its type and
// range, and every error carries the document line and the field path, e.g.
//   campus.yaml:42: cameras[3].fps: must be > 0
//
// Used by the scene part (scene_file.cc) and the simulator part (the simulator's scenario.cc,
// target ave_scenario) of one scenario file. Parsing functions throw FieldError; the public entry
// points catch it and return absl::Status (FormatFieldError). Include only from .cc files: it
// pulls in yaml-cpp.
#include <initializer_list>
#include <limits>
#include <optional>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <yaml-cpp/yaml.h>

#include "model_store/scene/campus.h"

namespace ave::scene::yaml {

struct FieldError : std::runtime_error {
  FieldError(int line_in, std::string field_in, const std::string& message)
      : std::runtime_error(message), line(line_in), field(std::move(field_in)) {}
  int line;  // 1-based; 0 when unknown
  std::string field;
};

// "file:line: field: message" (the line left out when unknown).
std::string FormatFieldError(const std::string& file, const FieldError& e);

// 1-based line of a node (0 for a node that is not in the document).
int LineOf(const YAML::Node& node);

[[noreturn]] void Fail(const YAML::Node& node, const std::string& field, const std::string& message);

// For the *In / *UpTo fields: no fallback, the key must be there.
inline constexpr std::nullopt_t kRequired = std::nullopt;
// An open end of a range ("must be >= lo" / "must be <= hi").
inline constexpr double kUnbounded = std::numeric_limits<double>::infinity();

// A YAML mapping at field path `field` (e.g. "cameras[3]").
class Map {
 public:
  Map(const YAML::Node& node, std::string field);

  // Every key must be one of `allowed`; otherwise FieldError naming the key (and a near match).
  void AllowOnly(std::initializer_list<const char*> allowed) const;
  void AllowOnly(const std::set<std::string>& allowed) const;

  bool Has(const char* key) const;
  YAML::Node Get(const char* key) const;  // undefined node when absent
  std::string Field(const char* key) const { return field_ + "." + key; }
  const std::string& field() const { return field_; }
  const YAML::Node& node() const { return node_; }

  // Typed values; the *Or forms return `fallback` when the key is absent. Required forms fail
  // with "required" on the map's own line.
  double Number(const char* key) const;
  double NumberOr(const char* key, double fallback) const;
  int IntOr(const char* key, int fallback) const;
  bool BoolOr(const char* key, bool fallback) const;
  std::string String(const char* key) const;
  std::string StringOr(const char* key, const std::string& fallback) const;
  // [x, y] (or [x, y, z] when `allow_3d`: the size of the result tells).
  std::vector<double> Numbers(const char* key, size_t min_size, size_t max_size) const;
  Eigen::Vector2d Vec2(const char* key) const;
  std::vector<Eigen::Vector2d> Points(const char* key, size_t min_points) const;

  // Range checks on a value read from `key` (for the error's line). RequireRange says
  // "must be in [lo, hi]", or "must be >= lo" / "must be <= hi" when the other end is kUnbounded.
  void RequirePositive(const char* key, double value) const;
  void RequireRange(const char* key, double value, double lo, double hi) const;
  // The common numeric field in one call: the value at `key` (`fallback` when absent; kRequired:
  // absent is an error), checked against [lo, hi]. IntIn also wants a whole number; the Positive
  // forms first say "must be > 0" for zero and negative values, then check the range.
  double NumberIn(const char* key, std::optional<double> fallback, double lo, double hi) const;
  int IntIn(const char* key, std::optional<int> fallback, int lo, int hi) const;
  double PositiveIn(const char* key, std::optional<double> fallback, double lo, double hi) const;
  double PositiveUpTo(const char* key, std::optional<double> fallback, double hi = kUnbounded) const {
    return PositiveIn(key, fallback, 0, hi);
  }

 private:
  YAML::Node node_;
  std::string field_;
};

double ToNumber(const YAML::Node& node, const std::string& field);
// A sequence node at `field`; fails when it is something else.
void RequireSequence(const YAML::Node& node, const std::string& field);

// The scene part of a scenario document. The root's keys must be scene keys or one of
// `other_top_level_keys` (left to the caller). Throws FieldError.
SyntheticCampus ParseScene(const YAML::Node& root, const std::set<std::string>& other_top_level_keys);

// YAML text -> root node; a syntax error becomes a FieldError at its line.
YAML::Node ParseYamlText(const std::string& text);

}  // namespace ave::scene::yaml
