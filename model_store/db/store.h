#pragma once
// The model store: cameras, versioned static scene meshes and an append-only audit log in one
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
#include "model_store/geometry/camera.h"
#include "model_store/geometry/mesh.h"
#include "model_store/geometry/rigid3.h"

namespace ave::store {

struct CameraRecord {
  std::string id;    // [A-Za-z0-9_.-]{1,64}, the primary key
  std::string name;  // free text, at most 128 characters
  PinholeIntrinsics intrinsics;
  Rigid3d world_from_camera;  // mounting pose in the local world frame; rotation stored normalised
  std::string source_url;     // at most 1024 characters; may be empty
  bool enabled = true;
  int64_t updated_at_ns = 0;  // set by the store on add/update; ignored on input
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

 private:
  class Impl;
  explicit Store(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace ave::store
