#pragma once
// The model store: cameras, versioned static scene meshes, an append-only audit log, LiDAR-built
// scenes (terrain tiles, buildings, provenance) and avatar sequences in one
// SQLite file (MISSION part A). SQLite stays behind this interface; callers see absl::Status.
//
// File layout: see the migration list in store.cc. Doubles are stored as SQLite REAL (IEEE-754
// binary64), so poses and intrinsics round-trip bit-exactly; meshes as a versioned blob
// (mesh_blob.h). Timestamps are std::chrono::system_clock nanoseconds since the Unix epoch.
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "model_store/avatar/avatar_sequence.h"
#include "model_store/geometry/camera.h"
#include "model_store/geometry/mesh.h"
#include "model_store/geometry/rigid3.h"

namespace ave::store {

// CameraRecord::kind values (schema v4, issue 16).
inline constexpr char kSensorKindCamera[] = "camera";
inline constexpr char kSensorKindRotatingLidar[] = "rotating_lidar";

// A registered sensor: a camera, or a rotating LiDAR (kind "rotating_lidar": zero intrinsics,
// world_from_camera is its world_from_sensor).
struct CameraRecord {
  std::string id;    // [A-Za-z0-9_.-]{1,64}, the primary key
  std::string name;  // free text, at most 128 characters
  PinholeIntrinsics intrinsics;
  Rigid3d world_from_camera;  // mounting pose in the local world frame; rotation stored normalised
  std::string source_url;     // at most 1024 characters; may be empty
  bool enabled = true;
  int64_t updated_at_ns = 0;  // set by the store on add/update; ignored on input
  std::string kind = kSensorKindCamera;
};

struct StaticModelRecord {
  int64_t version = 0;  // strictly increasing, never reused
  std::string name;
  TriangleMesh mesh;
  int64_t created_at_ns = 0;
};

struct AuditEntry {
  int64_t id = 0;
  int64_t at_ns = 0;
  std::string actor, action, target, before_json, after_json;
};

// A bearer token (issue 8). The token itself is never stored: `hash` is its SHA-256 as 64 lowercase
// hex characters (computed by the caller). role is "sensor", "viewer" or "admin"; a sensor token is
// bound to `camera_id`.
struct TokenRecord {
  std::string hash;
  std::string role;
  std::string camera_id;  // required for sensor tokens, empty otherwise
  std::string label;      // free text, at most 128 characters
  int64_t created_at_ns = 0;  // set by the store
  bool revoked = false;
};

// A static scene built from LiDAR (issue 4, schema v3) with its provenance: which input (path
// and SHA-256 of its bytes), which parameters (JSON), when; the summary (JSON) and the static
// model version the assembled mesh was stored as.
struct SceneRecord {
  int64_t id = 0;  // set by the store
  std::string name;
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();  // world coordinates of the local zero
  std::string input_path, input_sha256, parameters_json, summary_json;
  std::optional<int64_t> static_model_version;
  int64_t created_at_ns = 0;  // set by the store
};

// One tile of a height grid: `data` is the encoded grid (format "exr": an OpenEXR file as written
// by terrain/mesh_export.h WriteHeightExr), corner and resolution in the scene's local frame.
struct TerrainTileRecord {
  int tile_col = 0, tile_row = 0;
  double min_x = 0, min_y = 0, resolution_m = 0;
  int cols = 0, rows = 0;
  std::string format;
  std::string data;
};

// A fitted primitive and a building as plain fields (names of types as text: "box", "gable", ...),
// so the store needs nothing from the buildings library.
struct PrimitiveRecord {
  std::string type, roof;
  Eigen::Vector2d center_m = Eigen::Vector2d::Zero(), size_m = Eigen::Vector2d::Zero();
  double yaw_rad = 0, base_z_m = 0, eave_height_m = 0, roof_height_m = 0;
  std::vector<Eigen::Vector2d> polygon_m;
  double rms_m = 0;
  int64_t point_count = 0;
};
struct StoredBuilding {
  int64_t building_id = 0;
  std::string roof;
  std::vector<Eigen::Vector2d> footprint_m;
  double area_m2 = 0;
  int64_t point_count = 0;
  std::vector<PrimitiveRecord> parts;  // main part first
};

// An avatar sequence as stored (issue 17, schema v5): `version` is its row id (strictly increasing,
// never reused), so a viewer that cached (name, version) knows when a name was stored anew. `blob`
// (avatar_blob.h's encoding) is filled by GetAvatarSequenceBlob only.
struct AvatarSequenceRecord {
  int64_t version = 0;
  std::string name;
  int64_t frame_count = 0;
  double frame_period_s = 0, stride_m = 0;
  int64_t created_at_ns = 0;
  int64_t blob_bytes = 0;
  std::string blob;
};

// Empty when `name` may name an avatar sequence ([A-Za-z0-9_.-]{1,64}); else the reason, naming it.
std::string ValidateAvatarName(const std::string& name);

// Empty when the record may be stored; otherwise names the camera and the first bad field, e.g.
// "camera 'gate-1': intrinsics.fx must be finite and > 0". A rotation with |1 - |q|| <= 1e-3 is
// accepted (and normalised when stored); further from unit, or non-finite, is rejected.
std::string ValidateCamera(const CameraRecord& camera);

// Thread-safe: one mutex serialises all use of the connection.
class Store {
 public:
  // Opens or creates the SQLite file at `path` (":memory:" for an in-memory store): WAL journal,
  // foreign keys on, 5 s busy timeout, then applies any pending schema migrations, each in its own
  // transaction. A file written by a newer schema than LatestSchemaVersion() is refused.
  static absl::StatusOr<std::unique_ptr<Store>> Open(const std::string& path);
  ~Store();
  Store(const Store&) = delete;
  Store& operator=(const Store&) = delete;

  int SchemaVersion() const;
  static int LatestSchemaVersion();
  const std::string& path() const;

  absl::Status AddCamera(const CameraRecord& camera);     // AlreadyExists if the id is taken
  absl::Status UpdateCamera(const CameraRecord& camera);  // NotFound naming the id
  absl::Status RemoveCamera(const std::string& id);       // NotFound naming the id
  absl::StatusOr<CameraRecord> GetCamera(const std::string& id);
  absl::StatusOr<std::vector<CameraRecord>> ListCameras();  // ordered by id

  // Stores a new version of the static model and returns its version number. InvalidArgument
  // if the mesh is inconsistent (index out of range, per-triangle arrays of the wrong length).
  absl::StatusOr<int64_t> PutStaticModel(const std::string& name, const TriangleMesh& mesh);
  // The highest version, or nullopt when none was stored. DataLoss if its blob is corrupt.
  absl::StatusOr<std::optional<StaticModelRecord>> LatestStaticModel();

  // Audit rows cannot be updated or deleted (SQLite triggers abort such statements).
  absl::StatusOr<int64_t> AppendAudit(const std::string& actor, const std::string& action, const std::string& target,
                                      const std::string& before_json, const std::string& after_json);
  absl::StatusOr<std::vector<AuditEntry>> ListAudit(int limit = 100);  // newest first

  // Tokens: hashes only. AddToken: InvalidArgument naming the field, AlreadyExists for a known hash.
  absl::Status AddToken(const TokenRecord& token);
  // Marks every token whose hash starts with `hash_prefix` (8..64 hex characters) revoked; NotFound
  // when none matches. Revoked rows stay (the audit table names them).
  absl::Status RevokeToken(const std::string& hash_prefix);
  absl::StatusOr<std::vector<TokenRecord>> ListTokens();  // oldest first, revoked included

  // Scenes (schema v3): the scene row, its terrain tiles and buildings in one transaction; returns
  // the scene id. InvalidArgument naming the scene and field for a non-finite origin or bad tile.
  absl::StatusOr<int64_t> PutScene(const SceneRecord& scene, const std::vector<TerrainTileRecord>& tiles,
                                   const std::vector<StoredBuilding>& buildings);
  absl::StatusOr<std::vector<SceneRecord>> ListScenes();  // oldest first
  absl::StatusOr<std::vector<TerrainTileRecord>> GetTerrainTiles(int64_t scene_id);
  absl::StatusOr<std::vector<StoredBuilding>> GetBuildings(int64_t scene_id);  // by building_id, parts in order

  // Avatar sequences (issue 17). Put: InvalidArgument naming the name or the frame and field
  // (avatar_blob.h CheckAvatarSequence), AlreadyExists for a taken name; returns the version.
  absl::StatusOr<int64_t> PutAvatarSequence(const avatar::AvatarSequence& sequence);
  absl::StatusOr<std::vector<AvatarSequenceRecord>> ListAvatarSequences();  // by name, without blobs
  // NotFound naming the name. The blob is returned as stored (the server sends it to viewers as is).
  absl::StatusOr<AvatarSequenceRecord> GetAvatarSequenceBlob(const std::string& name);
  // Decoded; DataLoss naming the store and row when the blob is corrupt.
  absl::StatusOr<avatar::AvatarSequence> GetAvatarSequence(const std::string& name);

 private:
  class Impl;
  explicit Store(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace ave::store
