#include "model_store/db/store.h"

#include <sqlite3.h>
#include <unistd.h>

#include <atomic>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <thread>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "absl/strings/str_cat.h"
#include "model_store/db/mesh_blob.h"

namespace ave::store {
namespace {

using ::testing::HasSubstr;

CameraRecord MakeCamera(const std::string& id) {
  CameraRecord c;
  c.id = id;
  c.name = "Gate " + id;
  c.intrinsics = PinholeIntrinsics::FromFov(1280, 720, 70.0);
  c.intrinsics.fy += 0.125;
  c.intrinsics.distortion = {-0.1, 0.01, 1e-4, -2e-4, 0.003};
  c.world_from_camera = Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized())),
                                Eigen::Vector3d(384512.25, 5412345.125, 312.0625));
  c.source_url = "rtsp://10.0.0.7/stream1";
  c.enabled = false;
  return c;
}

void ExpectSameCamera(const CameraRecord& a, const CameraRecord& b) {
  EXPECT_EQ(a.id, b.id);
  EXPECT_EQ(a.name, b.name);
  EXPECT_EQ(a.intrinsics.width, b.intrinsics.width);
  EXPECT_EQ(a.intrinsics.height, b.intrinsics.height);
  EXPECT_EQ(a.intrinsics.fx, b.intrinsics.fx);  // exact: REAL is binary64
  EXPECT_EQ(a.intrinsics.fy, b.intrinsics.fy);
  EXPECT_EQ(a.intrinsics.cx, b.intrinsics.cx);
  EXPECT_EQ(a.intrinsics.cy, b.intrinsics.cy);
  EXPECT_EQ(a.intrinsics.distortion, b.intrinsics.distortion);
  const Eigen::Quaterniond qa = a.world_from_camera.rotation.normalized();
  EXPECT_EQ(qa.coeffs(), b.world_from_camera.rotation.coeffs());
  EXPECT_EQ(a.world_from_camera.translation, b.world_from_camera.translation);
  EXPECT_EQ(a.source_url, b.source_url);
  EXPECT_EQ(a.enabled, b.enabled);
}

TriangleMesh MakeMesh() {
  TriangleMesh m;
  m.origin = Eigen::Vector3d(384500.5, 5412300.25, 300.125);
  m.positions = {{0, 0, 0}, {1.5f, 0, 0.1f}, {0, 2.25f, -0.3f}, {1e-7f, -3.75f, 12.5f}};
  m.normals = {{0, 0, 1}, {0, 0, 1}, {0, 1, 0}, {1, 0, 0}};
  m.colors = {{0.1f, 0.2f, 0.3f}, {1, 1, 1}, {0, 0, 0}, {0.5f, 0.25f, 0.125f}};
  m.indices = {0, 1, 2, 1, 3, 2};
  m.triangle_material = {SurfaceMaterial::kRoad, SurfaceMaterial::kRoof};
  m.triangle_object = {-1, 7};
  return m;
}

void ExpectSameMesh(const TriangleMesh& a, const TriangleMesh& b) {
  EXPECT_EQ(a.origin, b.origin);
  EXPECT_EQ(a.positions, b.positions);
  EXPECT_EQ(a.normals, b.normals);
  EXPECT_EQ(a.colors, b.colors);
  EXPECT_EQ(a.indices, b.indices);
  EXPECT_EQ(a.triangle_material, b.triangle_material);
  EXPECT_EQ(a.triangle_object, b.triangle_object);
}

class TempDir {
 public:
  TempDir() {
    std::string tmpl = (std::filesystem::temp_directory_path() / "ave_store_test_XXXXXX").string();
    path_ = mkdtemp(tmpl.data()) ? tmpl : "";
  }
  ~TempDir() { std::filesystem::remove_all(path_); }
  std::string File(const std::string& name) const { return path_ + "/" + name; }
  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

// A second, raw connection for tampering with the file behind the store's back.
class RawDb {
 public:
  explicit RawDb(const std::string& path) { EXPECT_EQ(sqlite3_open(path.c_str(), &db_), SQLITE_OK); }
  ~RawDb() { sqlite3_close(db_); }
  int Exec(const std::string& sql) { return sqlite3_exec(db_, sql.c_str(), nullptr, nullptr, nullptr); }
  std::string Error() const { return sqlite3_errmsg(db_); }

 private:
  sqlite3* db_ = nullptr;
};

std::unique_ptr<Store> OpenOrDie(const std::string& path) {
  auto store = Store::Open(path);
  EXPECT_TRUE(store.ok()) << store.status();
  return store.ok() ? std::move(*store) : nullptr;
}

TEST(Store, Camera_RoundTripsAllFieldsExactly) {
  auto store = OpenOrDie(":memory:");
  ASSERT_TRUE(store);
  const CameraRecord cam = MakeCamera("gate-1");
  ASSERT_TRUE(store->AddCamera(cam).ok());
  auto got = store->GetCamera("gate-1");
  ASSERT_TRUE(got.ok()) << got.status();
  ExpectSameCamera(cam, *got);
  EXPECT_GT(got->updated_at_ns, 1'600'000'000'000'000'000);

  CameraRecord changed = cam;
  changed.name = "Gate one";
  changed.enabled = true;
  changed.world_from_camera.translation.x() = -1e6 + 0.001;
  ASSERT_TRUE(store->UpdateCamera(changed).ok());
  ExpectSameCamera(changed, *store->GetCamera("gate-1"));
}

TEST(Store, Camera_ListIsOrderedById) {
  auto store = OpenOrDie(":memory:");
  ASSERT_TRUE(store);
  for (const char* id : {"c", "a", "b.2", "B"}) ASSERT_TRUE(store->AddCamera(MakeCamera(id)).ok());
  auto list = store->ListCameras();
  ASSERT_TRUE(list.ok());
  std::vector<std::string> ids;
  for (const auto& c : *list) ids.push_back(c.id);
  EXPECT_EQ(ids, (std::vector<std::string>{"B", "a", "b.2", "c"}));
}

TEST(Store, Camera_DuplicateIdIsAlreadyExists) {
  auto store = OpenOrDie(":memory:");
  ASSERT_TRUE(store);
  ASSERT_TRUE(store->AddCamera(MakeCamera("cam")).ok());
  const absl::Status s = store->AddCamera(MakeCamera("cam"));
  EXPECT_TRUE(absl::IsAlreadyExists(s)) << s;
  EXPECT_THAT(s.message(), HasSubstr("'cam'"));
}

TEST(Store, Camera_UnknownIdIsNotFoundNamingIt) {
  auto store = OpenOrDie(":memory:");
  ASSERT_TRUE(store);
  absl::Status s = store->UpdateCamera(MakeCamera("ghost"));
  EXPECT_TRUE(absl::IsNotFound(s)) << s;
  EXPECT_THAT(s.message(), HasSubstr("ghost"));
  s = store->RemoveCamera("ghost2");
  EXPECT_TRUE(absl::IsNotFound(s)) << s;
  EXPECT_THAT(s.message(), HasSubstr("ghost2"));
  EXPECT_TRUE(absl::IsNotFound(store->GetCamera("ghost3").status()));

  ASSERT_TRUE(store->AddCamera(MakeCamera("real")).ok());
  ASSERT_TRUE(store->RemoveCamera("real").ok());
  EXPECT_TRUE(absl::IsNotFound(store->GetCamera("real").status()));
}

struct InvalidCase {
  const char* label;
  void (*mutate)(CameraRecord&);
  const char* field;
};

class InvalidCamera : public ::testing::TestWithParam<InvalidCase> {};

TEST_P(InvalidCamera, IsRejectedNamingTheFieldAndNotStored) {
  auto store = OpenOrDie(":memory:");
  ASSERT_TRUE(store);
  CameraRecord cam = MakeCamera("cam-1");
  GetParam().mutate(cam);
  const absl::Status s = store->AddCamera(cam);
  EXPECT_TRUE(absl::IsInvalidArgument(s)) << s;
  EXPECT_THAT(s.message(), HasSubstr(GetParam().field));
  EXPECT_THAT(ValidateCamera(cam), HasSubstr(GetParam().field));
  EXPECT_TRUE(store->ListCameras()->empty());

  // Updating a valid stored camera with the bad record leaves the stored one untouched.
  ASSERT_TRUE(store->AddCamera(MakeCamera("cam-1")).ok());
  EXPECT_TRUE(absl::IsInvalidArgument(store->UpdateCamera(cam)));
  ExpectSameCamera(MakeCamera("cam-1"), *store->GetCamera("cam-1"));
}

const double kNaN = std::numeric_limits<double>::quiet_NaN();
INSTANTIATE_TEST_SUITE_P(
    Store, InvalidCamera,
    ::testing::Values(
        InvalidCase{"NaNFx", [](CameraRecord& c) { c.intrinsics.fx = kNaN; }, "intrinsics.fx"},
        InvalidCase{"EmptyId", [](CameraRecord& c) { c.id.clear(); }, "id must match"},
        InvalidCase{"BadIdChars", [](CameraRecord& c) { c.id = "cam 1;drop"; }, "id must match"},
        InvalidCase{"LongId", [](CameraRecord& c) { c.id = std::string(65, 'a'); }, "id must match"},
        InvalidCase{"LongName", [](CameraRecord& c) { c.name = std::string(129, 'n'); }, "name"},
        InvalidCase{"LongUrl", [](CameraRecord& c) { c.source_url = std::string(1025, 'u'); }, "source_url"},
        InvalidCase{"NonUnitQuaternion", [](CameraRecord& c) { c.world_from_camera.rotation.coeffs() *= 1.01; },
                    "world_from_camera.rotation"},
        InvalidCase{"NaNQuaternion", [](CameraRecord& c) { c.world_from_camera.rotation.x() = kNaN; },
                    "world_from_camera.rotation"},
        InvalidCase{"InfTranslation",
                    [](CameraRecord& c) { c.world_from_camera.translation.z() = std::numeric_limits<double>::infinity(); },
                    "world_from_camera.translation"}),
    [](const auto& info) { return std::string(info.param.label); });

TEST(Store, Camera_NearUnitQuaternionIsNormalised) {
  auto store = OpenOrDie(":memory:");
  ASSERT_TRUE(store);
  CameraRecord cam = MakeCamera("cam");
  cam.world_from_camera.rotation.coeffs() *= 1.0005;
  EXPECT_EQ(ValidateCamera(cam), "");
  ASSERT_TRUE(store->AddCamera(cam).ok());
  EXPECT_NEAR(store->GetCamera("cam")->world_from_camera.rotation.norm(), 1.0, 1e-15);
}

TEST(Store, StaticModel_RoundTripsBitExactAndVersionsIncrease) {
  auto store = OpenOrDie(":memory:");
  ASSERT_TRUE(store);
  auto none = store->LatestStaticModel();
  ASSERT_TRUE(none.ok());
  EXPECT_FALSE(none->has_value());

  const TriangleMesh mesh = MakeMesh();
  auto v1 = store->PutStaticModel("campus", mesh);
  ASSERT_TRUE(v1.ok()) << v1.status();
  TriangleMesh second = mesh;
  second.positions[3].z() = -0.0f;
  second.normals.clear();
  second.triangle_object.clear();
  auto v2 = store->PutStaticModel("campus-b", second);
  ASSERT_TRUE(v2.ok());
  EXPECT_GT(*v2, *v1);

  auto latest = store->LatestStaticModel();
  ASSERT_TRUE(latest.ok() && latest->has_value()) << latest.status();
  EXPECT_EQ((*latest)->version, *v2);
  EXPECT_EQ((*latest)->name, "campus-b");
  ExpectSameMesh(second, (*latest)->mesh);
  EXPECT_TRUE(std::signbit((*latest)->mesh.positions[3].z()));
}

TEST(Store, StaticModel_InconsistentMeshIsRejected) {
  auto store = OpenOrDie(":memory:");
  ASSERT_TRUE(store);
  TriangleMesh bad = MakeMesh();
  bad.indices[4] = 4;
  const auto s = store->PutStaticModel("bad", bad).status();
  EXPECT_TRUE(absl::IsInvalidArgument(s)) << s;
  EXPECT_THAT(s.message(), HasSubstr("out of range"));
  bad = MakeMesh();
  bad.triangle_material.pop_back();
  EXPECT_TRUE(absl::IsInvalidArgument(store->PutStaticModel("bad", bad).status()));
  EXPECT_FALSE(store->LatestStaticModel()->has_value());
}

TEST(MeshBlob, EveryTruncationAndFlippedCountIsDataLoss) {
  auto blob = EncodeMesh(MakeMesh(), "t");
  ASSERT_TRUE(blob.ok());
  ASSERT_TRUE(DecodeMesh(*blob, "t").ok());
  for (size_t n = 0; n < blob->size(); ++n) {
    const auto s = DecodeMesh(std::string_view(*blob).substr(0, n), "ctx").status();
    EXPECT_TRUE(absl::IsDataLoss(s)) << n << ": " << s;
  }
  EXPECT_TRUE(absl::IsDataLoss(DecodeMesh(*blob + "x", "ctx").status()));
  std::string huge = *blob;
  huge[8 + 7] = '\x7f';  // positions count to ~9e18
  EXPECT_TRUE(absl::IsDataLoss(DecodeMesh(huge, "ctx").status()));
  std::string bad_index = *blob;
  const size_t first_index = 8 + 48 + 24 + 3 * 12 * 4;
  bad_index[first_index] = 9;
  const auto s = DecodeMesh(bad_index, "ctx").status();
  EXPECT_TRUE(absl::IsDataLoss(s));
  EXPECT_THAT(s.message(), HasSubstr("out of range"));
}

TEST(Store, StaticModel_CorruptBlobIsClearErrorNotCrash) {
  TempDir dir;
  const std::string path = dir.File("model.db");
  auto store = OpenOrDie(path);
  ASSERT_TRUE(store);
  auto v = store->PutStaticModel("campus", MakeMesh());
  ASSERT_TRUE(v.ok());
  const std::string where = " WHERE version = " + std::to_string(*v);
  RawDb raw(path);
  // A genuine blob cut short, then plain garbage.
  ASSERT_EQ(raw.Exec("UPDATE static_models SET mesh = substr(mesh, 1, length(mesh) - 3)" + where), SQLITE_OK)
      << raw.Error();
  EXPECT_THAT(store->LatestStaticModel().status().message(), HasSubstr("truncated"));
  for (const char* garbage : {"x'00112233445566778899'", "x'4156454d01000000ffffffff'", "x''"}) {
    ASSERT_EQ(raw.Exec(std::string("UPDATE static_models SET mesh = ") + garbage + where), SQLITE_OK) << raw.Error();
    const auto s = store->LatestStaticModel().status();
    EXPECT_TRUE(absl::IsDataLoss(s)) << s;
    EXPECT_THAT(s.message(), HasSubstr("static_models version " + std::to_string(*v)));
  }
}

TEST(Store, File_ReopenSeesEverythingPersistedInWalMode) {
  TempDir dir;
  const std::string path = dir.File("model.db");
  int64_t version = 0;
  {
    auto store = OpenOrDie(path);
    ASSERT_TRUE(store);
    EXPECT_EQ(store->path(), path);
    ASSERT_TRUE(store->AddCamera(MakeCamera("north")).ok());
    auto v = store->PutStaticModel("campus", MakeMesh());
    ASSERT_TRUE(v.ok());
    version = *v;
    ASSERT_TRUE(store->AppendAudit("admin", "add_camera", "north", "{}", "{\"id\":\"north\"}").ok());
  }
  auto store = OpenOrDie(path);
  ASSERT_TRUE(store);
  EXPECT_EQ(store->SchemaVersion(), Store::LatestSchemaVersion());
  ExpectSameCamera(MakeCamera("north"), *store->GetCamera("north"));
  auto model = store->LatestStaticModel();
  ASSERT_TRUE(model.ok() && model->has_value());
  EXPECT_EQ((*model)->version, version);
  ExpectSameMesh(MakeMesh(), (*model)->mesh);
  ASSERT_EQ(store->ListAudit()->size(), 1u);

  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
  auto pragma = [&](const char* sql) {
    sqlite3_stmt* stmt = nullptr;
    std::string value;
    EXPECT_EQ(sqlite3_prepare_v2(db, sql, -1, &stmt, nullptr), SQLITE_OK);
    if (sqlite3_step(stmt) == SQLITE_ROW) value = reinterpret_cast<const char*>(sqlite3_column_text(stmt, 0));
    sqlite3_finalize(stmt);
    return value;
  };
  EXPECT_EQ(pragma("PRAGMA journal_mode"), "wal");
  EXPECT_EQ(pragma("PRAGMA user_version"), std::to_string(Store::LatestSchemaVersion()));
  sqlite3_close(db);
}

TEST(Store, File_NewerSchemaIsRefusedNamingBothVersions) {
  TempDir dir;
  const std::string path = dir.File("future.db");
  ASSERT_TRUE(OpenOrDie(path));
  const int future = Store::LatestSchemaVersion() + 5;
  {
    RawDb raw(path);
    ASSERT_EQ(raw.Exec("PRAGMA user_version = " + std::to_string(future)), SQLITE_OK);
  }
  auto store = Store::Open(path);
  ASSERT_FALSE(store.ok());
  EXPECT_TRUE(absl::IsFailedPrecondition(store.status())) << store.status();
  EXPECT_THAT(store.status().message(), HasSubstr(path));
  EXPECT_THAT(store.status().message(), HasSubstr(std::to_string(future)));
  EXPECT_THAT(store.status().message(), HasSubstr("(" + std::to_string(Store::LatestSchemaVersion()) + ")"));
}

TEST(Store, File_UnopenablePathNamesThePath) {
  const auto s = Store::Open("/nonexistent-dir-for-ave/model.db").status();
  EXPECT_FALSE(s.ok());
  EXPECT_THAT(s.message(), HasSubstr("/nonexistent-dir-for-ave/model.db"));
}

// Issue 14: --store / --db pointing at a file that is not SQLite (a LAS file, say).
TEST(Store, File_NotADatabaseNamesThePath) {
  const std::string path = ::testing::TempDir() + "/ave_not_a_db.las";
  {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out << "LASF" << std::string(4096, '\x07');
  }
  const auto s = Store::Open(path).status();
  EXPECT_FALSE(s.ok());
  EXPECT_THAT(s.message(), HasSubstr(path));
  std::remove(path.c_str());
}

// Issue 14: a camera row edited outside ave is refused on read, naming the store and the camera,
// instead of reaching the server's registry with a zero focal length.
TEST(Store, File_CameraRowEditedOutsideIsRefusedOnRead) {
  TempDir dir;
  const std::string path = dir.File("edited.db");
  {
    auto store = OpenOrDie(path);
    ASSERT_TRUE(store);
    ASSERT_TRUE(store->AddCamera(MakeCamera("gate-1")).ok());
  }
  {
    RawDb raw(path);
    ASSERT_EQ(raw.Exec("UPDATE cameras SET fx = 0 WHERE id = 'gate-1'"), SQLITE_OK) << raw.Error();
  }
  auto store = OpenOrDie(path);
  ASSERT_TRUE(store);
  for (const absl::Status& s : {store->ListCameras().status(), store->GetCamera("gate-1").status()}) {
    EXPECT_TRUE(absl::IsDataLoss(s)) << s;
    EXPECT_THAT(s.message(), HasSubstr(path));
    EXPECT_THAT(s.message(), HasSubstr("camera 'gate-1': intrinsics.fx"));
  }
}

TEST(Store, Audit_IsNewestFirstAndAppendOnly) {
  TempDir dir;
  const std::string path = dir.File("audit.db");
  auto store = OpenOrDie(path);
  ASSERT_TRUE(store);
  for (int i = 0; i < 3; ++i) {
    auto id = store->AppendAudit("alice", "update_camera", "cam-" + std::to_string(i), "{\"a\":1}", "{\"a\":2}");
    ASSERT_TRUE(id.ok()) << id.status();
  }
  auto rows = store->ListAudit(2);
  ASSERT_TRUE(rows.ok());
  ASSERT_EQ(rows->size(), 2u);
  EXPECT_EQ((*rows)[0].target, "cam-2");
  EXPECT_EQ((*rows)[1].target, "cam-1");
  EXPECT_GT((*rows)[0].id, (*rows)[1].id);
  EXPECT_GE((*rows)[0].at_ns, (*rows)[1].at_ns);
  EXPECT_EQ((*rows)[0].actor, "alice");
  EXPECT_EQ((*rows)[0].before_json, "{\"a\":1}");
  EXPECT_EQ((*rows)[0].after_json, "{\"a\":2}");

  RawDb raw(path);
  EXPECT_NE(raw.Exec("UPDATE audit SET actor = 'mallory'"), SQLITE_OK);
  EXPECT_THAT(raw.Error(), HasSubstr("append-only"));
  EXPECT_NE(raw.Exec("DELETE FROM audit"), SQLITE_OK);
  EXPECT_THAT(raw.Error(), HasSubstr("append-only"));
  EXPECT_EQ(store->ListAudit()->size(), 3u);
  EXPECT_EQ(store->ListAudit()->back().actor, "alice");
}

TEST(Store, Concurrency_FourThreadsAddAndListWithoutCorruption) {
  TempDir dir;
  auto store = OpenOrDie(dir.File("threads.db"));
  ASSERT_TRUE(store);
  constexpr int kThreads = 4, kPerThread = 25;
  std::atomic<int> failures{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&, t] {
      for (int i = 0; i < kPerThread; ++i) {
        const std::string id = absl::StrCat("t", t, "-", i);
        if (!store->AddCamera(MakeCamera(id)).ok()) ++failures;
        auto list = store->ListCameras();
        if (!list.ok() || list->empty()) ++failures;
        if (!store->AppendAudit("t", "add", "x", "", "").ok()) ++failures;
      }
    });
  }
  for (auto& th : threads) th.join();
  EXPECT_EQ(failures.load(), 0);
  auto list = store->ListCameras();
  ASSERT_TRUE(list.ok());
  EXPECT_EQ(list->size(), static_cast<size_t>(kThreads * kPerThread));
  for (const auto& c : *list) ExpectSameCamera(MakeCamera(c.id), c);
  EXPECT_EQ(store->ListAudit(1000)->size(), static_cast<size_t>(kThreads * kPerThread));
}

TEST(Store, Token_StoresHashesOnlyAndRevokesByPrefix) {
  TempDir dir;
  const std::string path = dir.File("tokens.db");
  const std::string hash_a(64, 'a'), hash_b = std::string(63, 'b') + "c";
  {
    auto store = OpenOrDie(path);
    ASSERT_TRUE(store);
    ASSERT_TRUE(store->AddToken({hash_a, "sensor", "cam1", "gate sensor"}).ok());
    ASSERT_TRUE(store->AddToken({hash_b, "viewer", "", ""}).ok());
    EXPECT_TRUE(absl::IsAlreadyExists(store->AddToken({hash_a, "viewer", "", ""})));
    EXPECT_THAT(std::string(store->AddToken({"secret-token", "viewer", "", ""}).message()), HasSubstr("hash"));
    EXPECT_THAT(std::string(store->AddToken({std::string(64, 'd'), "root", "", ""}).message()), HasSubstr("role"));
    EXPECT_THAT(std::string(store->AddToken({std::string(64, 'e'), "sensor", "", ""}).message()),
                HasSubstr("camera_id"));
    EXPECT_TRUE(absl::IsNotFound(store->RevokeToken("0123456789")));
    ASSERT_TRUE(store->RevokeToken(hash_b.substr(0, 12)).ok());
  }
  auto store = OpenOrDie(path);  // reopened: the tokens table came through a migration and persisted
  ASSERT_TRUE(store);
  auto tokens = store->ListTokens();
  ASSERT_TRUE(tokens.ok()) << tokens.status();
  ASSERT_EQ(tokens->size(), 2u);
  for (const TokenRecord& t : *tokens) {
    if (t.hash == hash_a) {
      EXPECT_EQ(t.role, "sensor");
      EXPECT_EQ(t.camera_id, "cam1");
      EXPECT_FALSE(t.revoked);
    } else {
      EXPECT_EQ(t.hash, hash_b);
      EXPECT_TRUE(t.revoked);
    }
    EXPECT_GT(t.created_at_ns, 0);
  }
}

TEST(StoreScenes, SceneTilesBuildingsAndProvenanceRoundTripExactly) {
  auto store = OpenOrDie(":memory:");
  ASSERT_TRUE(store);
  auto model = store->PutStaticModel("lidar", TriangleMesh{});
  ASSERT_TRUE(model.ok()) << model.status();
  SceneRecord scene;
  scene.name = "campus";
  scene.origin = {384500.0, 3768200.0, 85.0};
  scene.input_path = "/data/campus.las";
  scene.input_sha256 = std::string(64, 'a');
  scene.parameters_json = R"({"resolution_m":0.5})";
  scene.summary_json = R"({"points":10})";
  scene.static_model_version = *model;
  TerrainTileRecord tile{0, 0, -120.25, -119.75, 0.5, 481, 480, "exr", std::string("\0\1binary", 8)};
  StoredBuilding b;
  b.building_id = 3;
  b.roof = "gable";
  b.footprint_m = {{0.1, 0.2}, {10.3, 0.2}, {10.3, 8.7}};
  b.area_m2 = 43.125;
  b.point_count = 512;
  PrimitiveRecord p;
  p.type = "wedge";
  p.roof = "gable";
  p.center_m = {5.2, 4.45};
  p.size_m = {10.2, 8.5};
  p.yaw_rad = 0.1234567890123;
  p.base_z_m = 1.5;
  p.eave_height_m = 6;
  p.roof_height_m = 2.5;
  p.rms_m = 0.04;
  p.point_count = 500;
  b.parts = {p, p};
  b.parts[1].type = "box";
  auto id = store->PutScene(scene, {tile}, {b});
  ASSERT_TRUE(id.ok()) << id.status();
  auto scenes = store->ListScenes();
  ASSERT_TRUE(scenes.ok());
  ASSERT_EQ(scenes->size(), 1u);
  EXPECT_EQ(scenes->at(0).origin, scene.origin);
  EXPECT_EQ(scenes->at(0).input_sha256, scene.input_sha256);
  EXPECT_EQ(scenes->at(0).parameters_json, scene.parameters_json);
  EXPECT_EQ(scenes->at(0).static_model_version, *model);
  EXPECT_GT(scenes->at(0).created_at_ns, 0);
  auto tiles = store->GetTerrainTiles(*id);
  ASSERT_TRUE(tiles.ok());
  ASSERT_EQ(tiles->size(), 1u);
  EXPECT_EQ(tiles->at(0).data, tile.data);
  EXPECT_EQ(tiles->at(0).min_x, tile.min_x);
  auto buildings = store->GetBuildings(*id);
  ASSERT_TRUE(buildings.ok()) << buildings.status();
  ASSERT_EQ(buildings->size(), 1u);
  EXPECT_EQ(buildings->at(0).footprint_m, b.footprint_m);
  ASSERT_EQ(buildings->at(0).parts.size(), 2u);
  EXPECT_EQ(buildings->at(0).parts[0].yaw_rad, p.yaw_rad);
  EXPECT_EQ(buildings->at(0).parts[1].type, "box");
  // Bad input names the scene and field; a scene without a model version stores NULL.
  scene.origin.x() = std::nan("");
  EXPECT_THAT(std::string(store->PutScene(scene, {}, {}).status().message()), HasSubstr("origin must be finite"));
  scene.origin.x() = 1;
  scene.static_model_version.reset();
  tile.cols = 0;
  EXPECT_THAT(std::string(store->PutScene(scene, {tile}, {}).status().message()), HasSubstr("terrain tile (0, 0)"));
  ASSERT_TRUE(store->PutScene(scene, {}, {}).ok());
  EXPECT_FALSE(store->ListScenes()->back().static_model_version.has_value());
}

// Issue 14: a scene, tile or building row damaged behind the store's back is refused on reading,
// naming the store, the table or scene and the field; it is never handed on as if it were good.
TEST(StoreScenes, DamagedRowsAreDataLossNamingTheRow) {
  TempDir dir;
  const std::string path = dir.File("scenes.db");
  int64_t id = 0;
  {
    auto store = OpenOrDie(path);
    ASSERT_TRUE(store);
    SceneRecord scene;
    scene.name = "campus";
    StoredBuilding b;
    b.building_id = 7;
    b.footprint_m = {{0, 0}, {4, 0}, {4, 3}};
    b.area_m2 = 12;
    auto put = store->PutScene(scene, {TerrainTileRecord{1, 2, 0, 0, 0.5, 4, 4, "exr", "x"}}, {b});
    ASSERT_TRUE(put.ok()) << put.status();
    id = *put;
  }
  const auto reopen_and = [&](const std::string& damage) {
    {
      RawDb raw(path);
      EXPECT_EQ(raw.Exec(damage), SQLITE_OK) << raw.Error();
    }
    return OpenOrDie(path);
  };
  auto store = reopen_and("UPDATE terrain_tiles SET resolution_m = -1");
  absl::StatusOr<std::vector<TerrainTileRecord>> tiles = store->GetTerrainTiles(id);
  ASSERT_FALSE(tiles.ok());
  EXPECT_EQ(tiles.status().code(), absl::StatusCode::kDataLoss);
  EXPECT_THAT(std::string(tiles.status().message()), HasSubstr("terrain tile (1, 2)"));
  EXPECT_THAT(std::string(tiles.status().message()), HasSubstr(path));
  store.reset();
  store = reopen_and("UPDATE buildings SET area_m2 = 9e999");  // +inf in SQLite
  EXPECT_THAT(std::string(store->GetBuildings(id).status().message()), HasSubstr("building 7 area must be finite"));
  store.reset();
  store = reopen_and("UPDATE buildings SET area_m2 = 12, footprint = x'000000000000F07F0000000000000000'");  // (inf, 0)
  EXPECT_THAT(std::string(store->GetBuildings(id).status().message()), HasSubstr("polygon vertex 0 is not finite"));
  store.reset();
  store = reopen_and("UPDATE scenes SET name = ''");
  absl::StatusOr<std::vector<SceneRecord>> scenes = store->ListScenes();
  ASSERT_FALSE(scenes.ok());
  EXPECT_EQ(scenes.status().code(), absl::StatusCode::kDataLoss);
  EXPECT_THAT(std::string(scenes.status().message()), HasSubstr("scenes row " + std::to_string(id)));
}

}  // namespace
}  // namespace ave::store

namespace ave::store {
namespace {

// Issue 16: a rotating LiDAR is registered like a camera, with its kind and no intrinsics.
TEST(Store, Camera_RotatingLidarRoundTripsWithItsKindAndNoIntrinsics) {
  auto store = Store::Open(":memory:");
  ASSERT_TRUE(store.ok());
  CameraRecord lidar = MakeCamera("hdl64");
  lidar.kind = kSensorKindRotatingLidar;
  EXPECT_THAT(ValidateCamera(lidar), HasSubstr("camera 'hdl64': intrinsics must be absent"));
  lidar.intrinsics = PinholeIntrinsics{};
  ASSERT_TRUE((*store)->AddCamera(lidar).ok());
  auto got = (*store)->GetCamera("hdl64");
  ASSERT_TRUE(got.ok());
  EXPECT_EQ(got->kind, kSensorKindRotatingLidar);
  ExpectSameCamera(lidar, *got);
  lidar.kind = "radar";
  EXPECT_THAT((*store)->UpdateCamera(lidar).message(), HasSubstr("kind must be 'camera' or 'rotating_lidar'"));
  EXPECT_EQ((*store)->GetCamera("hdl64")->kind, kSensorKindRotatingLidar);
}

// Schema v4 -> v5 (issue 18): a store from before recording gains the empty recording index and
// keeps its cameras.
TEST(Store, File_Version4StoreGainsTheRecordingIndex) {
  TempDir dir;
  const std::string path = dir.File("v4.db");
  {
    auto store = OpenOrDie(path);
    ASSERT_TRUE(store);
    ASSERT_TRUE(store->AddCamera(MakeCamera("north")).ok());
  }
  {
    RawDb raw(path);
    for (const char* table : {"record_frames", "record_segments", "record_sweeps", "record_objects", "record_sensors"}) {
      ASSERT_EQ(raw.Exec(std::string("DROP TABLE ") + table), SQLITE_OK) << table;
    }
    ASSERT_EQ(raw.Exec("PRAGMA user_version = 4"), SQLITE_OK);
  }
  auto store = OpenOrDie(path);
  ASSERT_TRUE(store);
  EXPECT_EQ(store->SchemaVersion(), Store::LatestSchemaVersion());
  EXPECT_TRUE(store->GetCamera("north").ok());
  RawDb raw(path);
  EXPECT_EQ(raw.Exec("SELECT segment_id, sensor_id, sequence, capture_server_ns, received_ns, offset, length, meta "
                     "FROM record_frames"),
            SQLITE_OK)
      << raw.Error();
  EXPECT_EQ(raw.Exec("SELECT id, sensor_id, path, start_ns, end_ns, bytes, closed FROM record_segments"), SQLITE_OK)
      << raw.Error();
}

// Schema v3 -> v4: cameras registered before issue 16 read back as cameras, unchanged.
TEST(Store, File_CamerasOfAVersion3StoreBecomeCameraKind) {
  TempDir dir;
  const std::string path = dir.File("v3.db");
  {
    auto store = OpenOrDie(path);
    ASSERT_TRUE(store);
    ASSERT_TRUE(store->AddCamera(MakeCamera("north")).ok());
  }
  {
    RawDb raw(path);
    ASSERT_EQ(raw.Exec("ALTER TABLE cameras DROP COLUMN kind"), SQLITE_OK);
    // What later migrations added goes too, so the file is a true version 3 one (v5: issue 18).
    for (const char* table : {"record_frames", "record_segments", "record_sweeps", "record_objects", "record_sensors"}) {
      ASSERT_EQ(raw.Exec(std::string("DROP TABLE ") + table), SQLITE_OK) << table;
    }
    ASSERT_EQ(raw.Exec("PRAGMA user_version = 3"), SQLITE_OK);
  }
  auto store = OpenOrDie(path);
  ASSERT_TRUE(store);
  EXPECT_EQ(store->SchemaVersion(), Store::LatestSchemaVersion());
  auto got = store->GetCamera("north");
  ASSERT_TRUE(got.ok());
  EXPECT_EQ(got->kind, kSensorKindCamera);
  ExpectSameCamera(MakeCamera("north"), *got);
}

}  // namespace
}  // namespace ave::store
