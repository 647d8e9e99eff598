#include "model_store/scene/scene_file.h"

#include <cmath>
#include <functional>
#include <set>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "model_store/geometry/raycast.h"
#include "model_store/scene/yaml_fields.h"

namespace ave::scene {
namespace {

using ::testing::HasSubstr;
using ::testing::StartsWith;

SyntheticCampus LoadBundled(const std::string& name) {
  auto text = BundledScenarioText(name);
  EXPECT_TRUE(text.has_value()) << name;
  auto campus = LoadSceneText(std::string(text.value_or("")), name + ".yaml");
  EXPECT_TRUE(campus.ok()) << campus.status();
  return campus.ok() ? *campus : SyntheticCampus{};
}

// The error message of a scenario text that must be rejected.
std::string Rejection(const std::string& text) {
  auto campus = LoadSceneText(text, "bad.yaml");
  EXPECT_FALSE(campus.ok()) << "accepted:\n" << text;
  return campus.ok() ? std::string() : std::string(campus.status().message());
}

TEST(SceneFile, AllBundledScenariosLoad) {
  const std::vector<std::string> names = BundledScenarioNames();
  EXPECT_EQ(std::set<std::string>(names.begin(), names.end()), (std::set<std::string>{"campus", "courtyard", "studio", "minimal"}));
  for (const auto& name : names) EXPECT_EQ(LoadBundled(name).name, name);
}

TEST(SceneFile, CampusHasWhatTheDemoNeeds) {
  const SyntheticCampus campus = LoadBundled("campus");
  EXPECT_GE(campus.buildings.size(), 30u);
  std::set<PrimitiveKind> kinds;
  int multi = 0;
  for (const auto& b : campus.buildings) {
    for (const auto& p : b.Parts()) kinds.insert(p.kind);
    multi += !b.extra_parts.empty();
  }
  EXPECT_EQ(kinds.size(), 6u) << "every primitive kind appears";
  EXPECT_GE(multi, 1);
  EXPECT_GE(campus.trees.size(), 10u);
  int people = 0, cars = 0;
  for (const auto& m : campus.movers) (m.kind == MoverKind::kPerson ? people : cars)++;
  EXPECT_GE(people, 20);
  EXPECT_GE(cars, 5);
  for (const char* id : {"cam1", "cam2", "cam3"}) {
    ASSERT_NE(campus.FindCamera(id), nullptr) << id;
    EXPECT_FALSE(campus.FindCamera(id)->path.has_value()) << id;
  }
  ASSERT_NE(campus.FindCamera("backpack"), nullptr);
  EXPECT_TRUE(campus.FindCamera("backpack")->path.has_value());
}

// The foundation demo's three mast cameras keep their poses (eye on a mast above the terrain,
// looking at a ground point), so the registry and the e2e expectations do not move.
TEST(SceneFile, BuiltinCampusIsTheCampusScenarioWithItsFixedCameras) {
  const SyntheticCampus builtin = BuiltinCampus();
  const SyntheticCampus scenario = LoadBundled("campus");
  EXPECT_EQ(builtin.buildings.size(), scenario.buildings.size());
  EXPECT_EQ(builtin.movers.size(), scenario.movers.size());
  ASSERT_EQ(builtin.cameras.size(), 3u);
  struct Mast {
    const char* id;
    Eigen::Vector2d eye;
    double mast_m;
    Eigen::Vector2d target;
  };
  for (const Mast& m : {Mast{"cam1", {-12, -62}, 16, {4, -12}}, Mast{"cam2", {62, 8}, 18, {20, 4}}, Mast{"cam3", {-10, 58}, 17, {-12, 12}}}) {
    const CameraSpec* cam = builtin.FindCamera(m.id);
    ASSERT_NE(cam, nullptr);
    const Rigid3d want = LookAt({m.eye.x(), m.eye.y(), builtin.TerrainHeight(m.eye.x(), m.eye.y()) + m.mast_m},
                                {m.target.x(), m.target.y(), builtin.TerrainHeight(m.target.x(), m.target.y())});
    EXPECT_LT((cam->world_from_camera.translation - want.translation).norm(), 1e-12) << m.id;
    EXPECT_LT(cam->world_from_camera.rotation.angularDistance(want.rotation), 1e-12) << m.id;
    EXPECT_EQ(cam->intrinsics.width, 640);
  }
}

// Every primitive's roof is where the analytic shape says: a vertical ray hits the mesh's roof of
// that building at RoofHeightAt, at the part's centre and at off-centre points on each slope.
TEST(SceneFile, EveryPrimitiveRoofIsWhereTheMeshSays) {
  SyntheticCampus campus = LoadBundled("campus");
  campus.trees.clear();  // crowns may overhang eaves; this test is about roofs
  campus.objects.clear();
  const TriangleMesh mesh = BuildStaticMesh(campus, 4.0);
  int checked = 0;
  for (size_t i = 0; i < campus.buildings.size(); ++i) {
    const BoxBuilding& b = campus.buildings[i];
    for (const BuildingPart& part : b.Parts()) {
      const double c = std::cos(part.yaw_rad), s = std::sin(part.yaw_rad);
      for (const Eigen::Vector2d& f : {Eigen::Vector2d(0.013, 0.017), Eigen::Vector2d(0.3, -0.25), Eigen::Vector2d(-0.35, 0.3)}) {
        const double px = f.x() * part.size_m.x(), py = f.y() * part.size_m.y();
        const Eigen::Vector2d xy = part.center_m + Eigen::Vector2d(c * px - s * py, s * px + c * py);
        const auto want = campus.RoofHeightAt(b, xy.x(), xy.y());
        ASSERT_TRUE(want.has_value()) << b.id;
        const auto hit = RaycastMesh(mesh, {xy.x(), xy.y(), 500}, {0, 0, -1});
        ASSERT_TRUE(hit.has_value()) << b.id;
        // Dome facets lie inside the analytic half-spheroid by up to a few centimetres.
        bool round = false;
        for (const BuildingPart& other : b.Parts()) round |= other.kind == PrimitiveKind::kDome && PartCovers(other, xy.x(), xy.y());
        EXPECT_NEAR(500 - hit->distance_m, *want, round ? 0.06 : 1e-3) << b.id << " (" << PrimitiveName(part.kind) << ")";
        EXPECT_EQ(mesh.triangle_material[hit->triangle], SurfaceMaterial::kRoof) << b.id;
        EXPECT_EQ(mesh.triangle_object[hit->triangle], static_cast<int32_t>(i)) << b.id;
        ++checked;
      }
    }
  }
  EXPECT_GE(checked, 90);
  // The highest roof point of every building (sampled on a grid over each part) is its top.
  for (const BoxBuilding& b : campus.buildings) {
    double highest = -1e9;
    for (const BuildingPart& part : b.Parts()) {
      const double c = std::cos(part.yaw_rad), s = std::sin(part.yaw_rad);
      for (int i = 0; i <= 20; ++i) {
        for (int j = 0; j <= 20; ++j) {
          const double px = (i / 20.0 - 0.5) * 0.999999 * part.size_m.x(), py = (j / 20.0 - 0.5) * 0.999999 * part.size_m.y();
          const auto z = campus.RoofHeightAt(b, part.center_m.x() + c * px - s * py, part.center_m.y() + s * px + c * py);
          if (z) highest = std::max(highest, *z);
        }
      }
    }
    EXPECT_NEAR(highest, campus.BuildingTop(b), 1e-4) << b.id;
  }
}

TEST(SceneFile, MaterialsPerTriangle) {
  const SyntheticCampus campus = LoadBundled("campus");
  const TriangleMesh mesh = BuildStaticMesh(campus, 8.0);
  std::vector<int> walls(campus.buildings.size()), roofs(campus.buildings.size());
  int vegetation = 0, objects = 0;
  for (size_t t = 0; t < mesh.TriangleCount(); ++t) {
    const SurfaceMaterial m = mesh.triangle_material[t];
    const int32_t o = mesh.triangle_object[t];
    if (m == SurfaceMaterial::kWall || m == SurfaceMaterial::kRoof) {
      ASSERT_GE(o, 0);
      ASSERT_LT(o, static_cast<int32_t>(campus.buildings.size()));
      (m == SurfaceMaterial::kWall ? walls : roofs)[o]++;
    } else {
      ASSERT_EQ(o, -1) << "only walls and roofs carry a building index";
    }
    vegetation += m == SurfaceMaterial::kVegetation;
    objects += m == SurfaceMaterial::kObject;
  }
  for (size_t i = 0; i < campus.buildings.size(); ++i) {
    EXPECT_GE(walls[i], 8) << campus.buildings[i].id;
    EXPECT_GE(roofs[i], 2) << campus.buildings[i].id;
  }
  EXPECT_GT(vegetation, static_cast<int>(100 * campus.trees.size()));
  EXPECT_GT(objects, 0);
  // Normals of roof triangles point up (a dome's lowest ring is nearly vertical); walls are vertical.
  for (size_t t = 0; t < mesh.TriangleCount(); ++t) {
    const Eigen::Vector3f n = mesh.normals[mesh.indices[3 * t]];
    if (mesh.triangle_material[t] == SurfaceMaterial::kRoof) {
      ASSERT_GT(n.z(), 0.05f) << "triangle " << t;
    }
    if (mesh.triangle_material[t] == SurfaceMaterial::kWall) {
      ASSERT_NEAR(n.z(), 0.0f, 1e-4f) << "triangle " << t;
    }
  }
}

TEST(SceneFile, GridTerrainIsBilinear) {
  auto campus = LoadSceneText(R"(
name: grid
terrain:
  half_extent_m: 10
  grid: {origin: [-10, -10], spacing_m: 10, cols: 3, rows: 3, heights_m: [0, 1, 2, 0, 1, 2, 4, 5, 6]}
)",
                              "grid.yaml");
  ASSERT_TRUE(campus.ok()) << campus.status();
  EXPECT_NEAR(campus->TerrainHeight(-10, -10), 0, 1e-12);
  EXPECT_NEAR(campus->TerrainHeight(5, 5), 0.5 * (1.5 + 5.5), 1e-12);
  EXPECT_NEAR(campus->TerrainHeight(100, 100), 6, 1e-12) << "clamped at the border";
  EXPECT_TRUE(campus->TerrainNormal(5, 5).allFinite());
}

TEST(SceneFile, RoadsAndCrossings) {
  const SyntheticCampus campus = LoadBundled("campus");
  auto at = campus.RoadAt(2, 50);
  ASSERT_TRUE(at.has_value());
  EXPECT_NEAR(at->across_m, 2, 1e-12);
  EXPECT_NEAR(at->along_m, 170, 1e-9);
  EXPECT_FALSE(at->crossing);
  EXPECT_TRUE(campus.RoadAt(1, 1)->crossing);
  EXPECT_FALSE(campus.IsRoad(20, 20));
}

// ---- Bad input: file, line and field named -------------------------------------------------

constexpr const char* kGood = R"(name: t
terrain: {half_extent_m: 50}
buildings:
  - {id: b1, type: box, position: [0, 20], size: [10, 10], height_m: 8}
cameras:
  - {id: c1, position: [0, -20], height_above_ground_m: 3, look_at: [0, 0]}
people:
  - {path: [[-5, 0], [5, 0]]}
)";

TEST(SceneFileBadInput, TheGoodBaseLoads) { EXPECT_TRUE(LoadSceneText(kGood, "good.yaml").ok()); }

TEST(SceneFileBadInput, TypoedKeyNamesLineFieldAndSuggestion) {
  const std::string msg = Rejection(R"(name: t
buildings:
  - {id: b1, type: box, position: [0, 20], size: [10, 10], hieght_m: 8}
)");
  EXPECT_THAT(msg, StartsWith("bad.yaml:3: buildings[0].hieght_m: unknown key"));
  EXPECT_THAT(msg, HasSubstr("did you mean 'height_m'"));
  EXPECT_THAT(Rejection("name: t\ncameraz: []\n"), StartsWith("bad.yaml:2: cameraz: unknown key; did you mean 'cameras'?"));
}

TEST(SceneFileBadInput, NegativeRateIsRejected) {
  const std::string msg = Rejection(R"(name: t
cameras:
  - {id: c0, position: [0, -20], look_at: [0, 0]}
  - {id: c1, position: [0, -20], look_at: [0, 0]}
  - {id: c2, position: [0, -20], look_at: [0, 0]}
  - {id: c3, position: [0, -20], look_at: [0, 0],
     fps: -5}
)");
  EXPECT_EQ(msg, "bad.yaml:7: cameras[3].fps: must be > 0");
}

TEST(SceneFileBadInput, CameraInsideABuildingIsRejected) {
  const std::string msg = Rejection(R"(name: t
buildings:
  - {id: gym, type: gable, position: [0, 20], size: [10, 10], height_m: 8}
cameras:
  - {id: c1, position: [1, 21], height_above_ground_m: 3, look_at: [0, 0]}
)");
  EXPECT_THAT(msg, StartsWith("bad.yaml:5: cameras[0].position: the camera"));
  EXPECT_THAT(msg, HasSubstr("inside building 'gym'"));
  // Above the roof is fine.
  EXPECT_TRUE(LoadSceneText(R"(name: t
buildings:
  - {id: gym, type: box, position: [0, 20], size: [10, 10], height_m: 8}
cameras:
  - {id: c1, position: [1, 21], height_above_ground_m: 9, look_at: [0, 0]}
)",
                           "ok.yaml")
                  .ok());
}

TEST(SceneFileBadInput, MovingCameraThroughABuildingIsRejected) {
  const std::string msg = Rejection(R"(name: t
buildings:
  - {id: gym, type: box, position: [0, 20], size: [10, 10], height_m: 8}
cameras:
  - id: walker
    path:
      waypoints: [[0, 0], [0, 40]]
)");
  EXPECT_THAT(msg, StartsWith("bad.yaml:7: cameras[0].path.waypoints[0]: the path point"));
  EXPECT_THAT(msg, HasSubstr("'gym'"));
}

TEST(SceneFileBadInput, EmptyPathsAreRejected) {
  EXPECT_EQ(Rejection("name: t\npeople:\n  - {path: []}\n"), "bad.yaml:3: people[0].path: is empty; needs at least 1 points [x, y]");
  EXPECT_THAT(Rejection("name: t\ncameras:\n  - id: w\n    path: {waypoints: []}\n"),
              StartsWith("bad.yaml:4: cameras[0].path.waypoints: is empty"));
  EXPECT_THAT(Rejection("name: t\ncameras:\n  - id: w\n    path: {waypoints: [[0, 0], [5, 0]], turn_rate_deg_s: 0}\n"),
              StartsWith("bad.yaml:4: cameras[0].path.turn_rate_deg_s: must be > 0"));
}

TEST(SceneFileBadInput, OtherMistakesNameTheirField) {
  EXPECT_THAT(Rejection("name: t\nbuildings:\n  - {type: igloo, position: [0, 0], size: [1, 1], height_m: 2}\n"),
              StartsWith("bad.yaml:3: buildings[0].type: unknown primitive 'igloo'"));
  EXPECT_THAT(Rejection("name: t\nbuildings:\n  - {type: box, position: [0, 0], size: [1, 1]}\n"),
              StartsWith("bad.yaml:3: buildings[0].height_m: required"));
  EXPECT_THAT(Rejection("name: t\nbuildings:\n  - {type: box, position: [0, x], size: [1, 1], height_m: 2}\n"),
              StartsWith("bad.yaml:3: buildings[0].position[1]: must be a number"));
  EXPECT_THAT(Rejection("name: t\nbuildings:\n  - {id: a, position: [0, 0], size: [1, 1], height_m: 2}\n  - {id: a, position: [9, 0], size: [1, 1], height_m: 2}\n"),
              StartsWith("bad.yaml:4: buildings[1].id: duplicate building id 'a'"));
  EXPECT_THAT(Rejection("name: t\nbuildings: [\n"), StartsWith("bad.yaml:"));
  EXPECT_THAT(Rejection("name: t\ncameras:\n  - {id: c, position: [0, 0, 5], look_at: [0, 9], fx: -3}\n"),
              StartsWith("bad.yaml:3: cameras[0].fx: must be > 0"));
}

TEST(SceneFile, UnknownScenarioNamesTheKnownOnes) {
  auto s = ReadScenarioSource("mars");
  ASSERT_FALSE(s.ok());
  EXPECT_THAT(std::string(s.status().message()), HasSubstr("campus"));
  EXPECT_FALSE(ReadScenarioSource("/no/such/file.yaml").ok());
  EXPECT_EQ(ReadScenarioSource("minimal")->label, "minimal.yaml");
}

// The one-call numeric fields every reader (scene, simulator, intrinsics) uses: value or fallback,
// presence, whole numbers, open-ended ranges and the "> 0" message, each error on the key's line
// (the map's own line when the key is absent).
TEST(YamlFields, NumericFieldsCheckPresenceWholeNumbersAndRanges) {
  const YAML::Node root = yaml::ParseYamlText("a: 2.5\nb: 0\nc: 7\nd: -1\n");
  const yaml::Map m(root, "x");
  auto error = [](const std::function<void()>& read) -> std::string {
    try {
      read();
    } catch (const yaml::FieldError& e) {
      return std::to_string(e.line) + " " + e.field + ": " + e.what();
    }
    return "accepted";
  };
  EXPECT_EQ(m.NumberIn("a", 1, 0, 3), 2.5);
  EXPECT_EQ(m.NumberIn("absent", 1, 0, 3), 1);
  EXPECT_EQ(m.IntIn("c", 1, 0, 10), 7);
  EXPECT_EQ(m.PositiveUpTo("c", yaml::kRequired), 7);
  EXPECT_EQ(m.PositiveIn("a", yaml::kRequired, 1, 3), 2.5);
  EXPECT_EQ(error([&] { m.NumberIn("a", 1, 3, 4); }), "1 x.a: must be in [3, 4]");
  EXPECT_EQ(error([&] { m.NumberIn("absent", 9, 3, 4); }), "1 x.absent: must be in [3, 4]");
  EXPECT_EQ(error([&] { m.NumberIn("absent", yaml::kRequired, 0, 10); }), "1 x.absent: required");
  EXPECT_EQ(error([&] { m.IntIn("absent", yaml::kRequired, 0, 10); }), "1 x.absent: required");
  EXPECT_EQ(error([&] { m.IntIn("a", 1, 0, 10); }), "1 x.a: must be a whole number");
  EXPECT_EQ(error([&] { m.IntIn("c", 1, 8, 10); }), "3 x.c: must be in [8, 10]");
  EXPECT_EQ(error([&] { m.PositiveIn("b", 1, 0.5, 4); }), "2 x.b: must be > 0");
  EXPECT_EQ(error([&] { m.PositiveIn("a", 1, 3, 4); }), "1 x.a: must be in [3, 4]");
  EXPECT_EQ(error([&] { m.PositiveUpTo("d", 1); }), "4 x.d: must be > 0");
  EXPECT_EQ(error([&] { m.NumberIn("d", 0, 0, yaml::kUnbounded); }), "4 x.d: must be >= 0");
  EXPECT_EQ(error([&] { m.NumberIn("c", 0, -yaml::kUnbounded, 5); }), "3 x.c: must be <= 5");
}

}  // namespace
}  // namespace ave::scene
