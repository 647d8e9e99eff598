#pragma once
// `ave-model fit` (MISSION part A, AVE §4.1 semi-automatic mode): the user gives a footprint
// polygon or a click point and a primitive type; the points there are fitted by least squares and
// the building record is printed as one JSON line. With --db it is also stored: a scene named
// "fit:<input stem>" (origin, input path, parameters) holding that one building, no terrain tiles.
//
//   ave-model fit --input F (--footprint x,y;x,y;... | --click x,y) --type box|wedge|cylinder|sphere|polyhedron
//                 [--roof flat|shed|gable|hip|dome|cylinder] [--resolution 0.5] [--local] [--units U] [--db DB]
//
// Coordinates are world (file) metres unless --local says they are relative to the cloud's origin.
#include <iosfwd>
#include <optional>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <Eigen/Core>
#include "absl/status/statusor.h"

#include "model_store/buildings/buildings.h"
#include "model_store/db/store.h"

namespace ave::model {

struct FitCommandOptions {
  std::string input;
  std::string footprint;  // "x,y;x,y;x,y[;...]"
  std::string click;      // "x,y"
  std::string type = "box";
  std::string roof;       // empty: chosen by the fit (wedge: shed or gable)
  double resolution_m = 0.5;
  bool local = false;
  std::optional<double> units;
  std::string db;
};

// "x,y;x,y;..." -> points; InvalidArgument naming the vertex that does not parse.
absl::StatusOr<std::vector<Eigen::Vector2d>> ParseFootprint(const std::string& text);
absl::StatusOr<PrimitiveType> ParsePrimitiveType(const std::string& name);
absl::StatusOr<RoofType> ParseRoofType(const std::string& name);

// The store's plain-field form of a building record (type and roof names as text).
store::StoredBuilding ToStoredBuilding(const BuildingRecord& record);

// One line of JSON: the record with every primitive's parameters; centres also in world metres.
std::string BuildingJson(const BuildingRecord& record, const Eigen::Vector3d& origin);

// Reads, grids and ground-filters the input, fits, prints; returns the process exit code
// (0 ok, 1 bad input or failed fit, with one line on `err` naming the cause).
int RunFit(const FitCommandOptions& options, std::ostream& out, std::ostream& err);

// Registers the `fit` subcommand on ave-model's app (h4a's model_main.cc calls this).
void AddFitCommand(CLI::App& app);

}  // namespace ave::model
