#include "model_store/db/store.h"

#include <sqlite3.h>

#include <cctype>
#include <chrono>
#include <cmath>
#include <cstring>
#include <mutex>
#include <utility>

#include "absl/status/status.h"
#include "model_store/avatar/avatar_blob.h"
#include "model_store/db/mesh_blob.h"

namespace ave::store {
namespace {

// Schema migrations: entry i takes the file from user_version i to i + 1. Append, never edit.
const std::vector<const char*>& Migrations() {
  static const std::vector<const char*> kSteps = {
      R"sql(
      CREATE TABLE cameras (
        id TEXT PRIMARY KEY NOT NULL, name TEXT NOT NULL,
        width INTEGER NOT NULL, height INTEGER NOT NULL,
        fx REAL NOT NULL, fy REAL NOT NULL, cx REAL NOT NULL, cy REAL NOT NULL,
        k1 REAL NOT NULL, k2 REAL NOT NULL, p1 REAL NOT NULL, p2 REAL NOT NULL, k3 REAL NOT NULL,
        qw REAL NOT NULL, qx REAL NOT NULL, qy REAL NOT NULL, qz REAL NOT NULL,
        tx REAL NOT NULL, ty REAL NOT NULL, tz REAL NOT NULL,
        source_url TEXT NOT NULL, enabled INTEGER NOT NULL, updated_at_ns INTEGER NOT NULL);
      CREATE TABLE static_models (
        version INTEGER PRIMARY KEY AUTOINCREMENT, name TEXT NOT NULL,
        created_at_ns INTEGER NOT NULL, mesh BLOB NOT NULL);
      CREATE TABLE audit (
        id INTEGER PRIMARY KEY AUTOINCREMENT, at_ns INTEGER NOT NULL,
        actor TEXT NOT NULL, action TEXT NOT NULL, target TEXT NOT NULL,
        before_json TEXT NOT NULL, after_json TEXT NOT NULL);
      CREATE TRIGGER audit_no_update BEFORE UPDATE ON audit
        BEGIN SELECT RAISE(ABORT, 'audit rows are append-only'); END;
      CREATE TRIGGER audit_no_delete BEFORE DELETE ON audit
        BEGIN SELECT RAISE(ABORT, 'audit rows are append-only'); END;
      )sql",
      // 1 -> 2: bearer tokens (issue 8). Only SHA-256 hex digests are stored, never the token.
      R"sql(
      CREATE TABLE tokens (
        hash TEXT PRIMARY KEY NOT NULL, role TEXT NOT NULL, camera_id TEXT NOT NULL,
        label TEXT NOT NULL, created_at_ns INTEGER NOT NULL, revoked INTEGER NOT NULL DEFAULT 0);
      )sql",
      // 2 -> 3: static scenes built from LiDAR (issue 4): provenance (input hash, parameters, time),
      // terrain tiles (height grids), buildings and their fitted primitives. Polygons are blobs of
      // little-endian doubles (x, y pairs), exact like the REAL columns.
      R"sql(
      CREATE TABLE scenes (
        id INTEGER PRIMARY KEY AUTOINCREMENT, name TEXT NOT NULL,
        origin_x REAL NOT NULL, origin_y REAL NOT NULL, origin_z REAL NOT NULL,
        input_path TEXT NOT NULL, input_sha256 TEXT NOT NULL, parameters_json TEXT NOT NULL,
        summary_json TEXT NOT NULL, static_model_version INTEGER REFERENCES static_models(version),
        created_at_ns INTEGER NOT NULL);
      CREATE TABLE terrain_tiles (
        scene_id INTEGER NOT NULL REFERENCES scenes(id) ON DELETE CASCADE,
        tile_col INTEGER NOT NULL, tile_row INTEGER NOT NULL,
        min_x REAL NOT NULL, min_y REAL NOT NULL, resolution_m REAL NOT NULL,
        cols INTEGER NOT NULL, rows INTEGER NOT NULL, format TEXT NOT NULL, data BLOB NOT NULL,
        PRIMARY KEY (scene_id, tile_col, tile_row));
      CREATE TABLE buildings (
        scene_id INTEGER NOT NULL REFERENCES scenes(id) ON DELETE CASCADE, building_id INTEGER NOT NULL,
        roof TEXT NOT NULL, footprint BLOB NOT NULL, area_m2 REAL NOT NULL, point_count INTEGER NOT NULL,
        PRIMARY KEY (scene_id, building_id));
      CREATE TABLE building_primitives (
        scene_id INTEGER NOT NULL, building_id INTEGER NOT NULL, part INTEGER NOT NULL,
        type TEXT NOT NULL, roof TEXT NOT NULL, center_x REAL NOT NULL, center_y REAL NOT NULL,
        size_x REAL NOT NULL, size_y REAL NOT NULL, yaw_rad REAL NOT NULL, base_z_m REAL NOT NULL,
        eave_height_m REAL NOT NULL, roof_height_m REAL NOT NULL, polygon BLOB NOT NULL,
        rms_m REAL NOT NULL, point_count INTEGER NOT NULL,
        PRIMARY KEY (scene_id, building_id, part),
        FOREIGN KEY (scene_id, building_id) REFERENCES buildings(scene_id, building_id) ON DELETE CASCADE);
      )sql",
      // 3 -> 4: the sensor kind (issue 16): 'camera' (every row before) or 'rotating_lidar', which
      // keeps zero intrinsics and its world_from_sensor in the pose columns.
      R"sql(
      ALTER TABLE cameras ADD COLUMN kind TEXT NOT NULL DEFAULT 'camera';
      )sql",
      // 4 -> 5: the recording index (issue 18). JPEG bytes live in per-camera segment files (never
      // in SQLite); a row names its segment, byte offset and length. Rows are committed only after
      // their bytes were written and fdatasync'd, so a row never points at missing bytes. `meta` is
      // the ave.v1.SensorFrame / LidarSweepFrame without its JPEG / points (pose + covariance,
      // boxes, tracks, clock offset); times are on the server clock (capture_server_ns: the
      // capture time corrected by the agent's clock offset, never later than received_ns).
      // record_sensors keeps each recorded sensor's registry entry (ave.v1.Camera) so that a
      // sensor removed from the registry still replays; record_objects the fused objects
      // (ave.v1.SceneUpdate holding only objects) at a bounded rate.
      R"sql(
      CREATE TABLE record_segments (
        id INTEGER PRIMARY KEY AUTOINCREMENT, sensor_id TEXT NOT NULL, path TEXT NOT NULL UNIQUE,
        start_ns INTEGER NOT NULL, end_ns INTEGER NOT NULL, bytes INTEGER NOT NULL, closed INTEGER NOT NULL);
      CREATE INDEX record_segments_start ON record_segments (start_ns);
      CREATE TABLE record_frames (
        segment_id INTEGER NOT NULL REFERENCES record_segments(id) ON DELETE CASCADE,
        sensor_id TEXT NOT NULL, sequence INTEGER NOT NULL, capture_server_ns INTEGER NOT NULL,
        received_ns INTEGER NOT NULL, offset INTEGER NOT NULL, length INTEGER NOT NULL, meta BLOB NOT NULL);
      CREATE INDEX record_frames_time ON record_frames (capture_server_ns);
      CREATE INDEX record_frames_sensor_time ON record_frames (sensor_id, capture_server_ns);
      CREATE INDEX record_frames_segment ON record_frames (segment_id);
      CREATE TABLE record_sweeps (
        sensor_id TEXT NOT NULL, sequence INTEGER NOT NULL, capture_server_ns INTEGER NOT NULL,
        received_ns INTEGER NOT NULL, meta BLOB NOT NULL);
      CREATE INDEX record_sweeps_time ON record_sweeps (capture_server_ns);
      CREATE TABLE record_objects (t_ns INTEGER NOT NULL, objects BLOB NOT NULL);
      CREATE INDEX record_objects_time ON record_objects (t_ns);
      CREATE TABLE record_sensors (
        sensor_id TEXT PRIMARY KEY NOT NULL, camera BLOB NOT NULL, updated_ns INTEGER NOT NULL);
      )sql",
      // 5 -> 6: avatar sequences (issue 17, i4D §5): one walk cycle per unique name, the blob in
      // avatar_blob.h's form; the summary columns let a listing skip the (large) blob.
      R"sql(
      CREATE TABLE IF NOT EXISTS avatar_sequences (
        version INTEGER PRIMARY KEY AUTOINCREMENT, name TEXT NOT NULL UNIQUE,
        frame_count INTEGER NOT NULL, frame_period_s REAL NOT NULL, stride_m REAL NOT NULL,
        created_at_ns INTEGER NOT NULL, blob BLOB NOT NULL);
      )sql",
  };
  return kSteps;
}

int64_t NowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

struct Blob {
  std::string_view bytes;
};

// Owns the connection; every failure becomes a Status carrying sqlite3_errmsg and the path.
class Db {
 public:
  static absl::StatusOr<std::unique_ptr<Db>> Open(const std::string& path) {
    sqlite3* raw = nullptr;
    const int rc = sqlite3_open_v2(path.c_str(), &raw, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE, nullptr);
    auto db = std::unique_ptr<Db>(new Db(raw, path));  // closes `raw` even when open failed
    if (rc != SQLITE_OK) {
      return absl::UnavailableError("model store '" + path + "': cannot open: " +
                                    (raw ? sqlite3_errmsg(raw) : sqlite3_errstr(rc)));
    }
    return db;
  }
  ~Db() { sqlite3_close_v2(db_); }  // v2 defers the close if a statement leaked; nothing to report

  sqlite3* get() const { return db_; }
  const std::string& path() const { return path_; }

  absl::Status Error(std::string_view what) const {
    const int code = sqlite3_extended_errcode(db_);
    std::string msg = "model store '" + path_ + "': " + std::string(what) + ": " + sqlite3_errmsg(db_);
    if (code == SQLITE_CONSTRAINT_PRIMARYKEY || code == SQLITE_CONSTRAINT_UNIQUE) return absl::AlreadyExistsError(msg);
    if ((code & 0xFF) == SQLITE_BUSY || (code & 0xFF) == SQLITE_LOCKED) return absl::UnavailableError(msg);
    if ((code & 0xFF) == SQLITE_CORRUPT || (code & 0xFF) == SQLITE_NOTADB) return absl::DataLossError(msg);
    return absl::InternalError(msg);
  }

  absl::Status Exec(const char* sql, std::string_view what) {
    if (sqlite3_exec(db_, sql, nullptr, nullptr, nullptr) != SQLITE_OK) return Error(what);
    return absl::OkStatus();
  }

 private:
  Db(sqlite3* db, std::string path) : db_(db), path_(std::move(path)) {}
  sqlite3* db_;
  std::string path_;
};

// A prepared statement; Bind(...) binds parameters 1..N in order, Step() says whether a row is ready.
class Stmt {
 public:
  static absl::StatusOr<Stmt> Prepare(Db& db, const char* sql) {
    sqlite3_stmt* s = nullptr;
    if (sqlite3_prepare_v2(db.get(), sql, -1, &s, nullptr) != SQLITE_OK) {
      return db.Error(std::string("prepare \"") + sql + "\"");
    }
    return Stmt(db, s);
  }
  Stmt(Stmt&& o) noexcept : db_(o.db_), s_(std::exchange(o.s_, nullptr)) {}
  Stmt& operator=(Stmt&&) = delete;
  ~Stmt() { sqlite3_finalize(s_); }  // returns the last step's error, already reported by Step()

  template <typename... Args>
  absl::Status Bind(const Args&... args) {
    int index = 0;
    absl::Status status;
    ((status.ok() ? status = BindOne(++index, args) : status), ...);
    return status;
  }

  absl::StatusOr<bool> Step() {
    const int rc = sqlite3_step(s_);
    if (rc == SQLITE_ROW) return true;
    if (rc == SQLITE_DONE) return false;
    return db_->Error(std::string("step \"") + sqlite3_sql(s_) + "\"");
  }
  absl::Status Run() {  // a statement expected to return no rows
    absl::StatusOr<bool> row = Step();
    if (!row.ok()) return row.status();
    return absl::OkStatus();
  }

  // Clears bindings and rewinds, so one prepared statement inserts many rows.
  absl::Status Reset() {
    sqlite3_reset(s_);  // returns the previous step's error, already reported by Step()
    return Check(sqlite3_clear_bindings(s_), 0);
  }
  template <typename T>
  absl::Status BindAt(int index, const T& v) { return BindOne(index, v); }
  absl::Status BindNullAt(int index) { return Check(sqlite3_bind_null(s_, index), index); }
  bool IsNull(int col) const { return sqlite3_column_type(s_, col) == SQLITE_NULL; }

  double Double(int col) const { return sqlite3_column_double(s_, col); }
  int64_t Int(int col) const { return sqlite3_column_int64(s_, col); }
  std::string Text(int col) const {
    const auto* p = reinterpret_cast<const char*>(sqlite3_column_text(s_, col));
    return p ? std::string(p, sqlite3_column_bytes(s_, col)) : std::string();
  }
  std::string_view BlobAt(int col) const {
    const void* p = sqlite3_column_blob(s_, col);
    return p ? std::string_view(static_cast<const char*>(p), sqlite3_column_bytes(s_, col)) : std::string_view();
  }

 private:
  Stmt(Db& db, sqlite3_stmt* s) : db_(&db), s_(s) {}
  absl::Status Check(int rc, int index) {
    if (rc == SQLITE_OK) return absl::OkStatus();
    return db_->Error("bind parameter " + std::to_string(index) + " of \"" + sqlite3_sql(s_) + "\"");
  }
  absl::Status BindOne(int i, double v) { return Check(sqlite3_bind_double(s_, i, v), i); }
  absl::Status BindOne(int i, int64_t v) { return Check(sqlite3_bind_int64(s_, i, v), i); }
  absl::Status BindOne(int i, int v) { return Check(sqlite3_bind_int64(s_, i, v), i); }
  absl::Status BindOne(int i, bool v) { return Check(sqlite3_bind_int64(s_, i, v ? 1 : 0), i); }
  absl::Status BindOne(int i, const std::string& v) {
    return Check(sqlite3_bind_text64(s_, i, v.data(), v.size(), SQLITE_TRANSIENT, SQLITE_UTF8), i);
  }
  absl::Status BindOne(int i, const Blob& v) {
    return Check(sqlite3_bind_blob64(s_, i, v.bytes.data(), v.bytes.size(), SQLITE_TRANSIENT), i);
  }

  Db* db_;
  sqlite3_stmt* s_;
};

// BEGIN IMMEDIATE ... COMMIT; rolls back unless Commit() succeeded.
class Transaction {
 public:
  explicit Transaction(Db& db) : db_(db) {}
  absl::Status Begin() {
    absl::Status s = db_.Exec("BEGIN IMMEDIATE", "begin transaction");
    open_ = s.ok();
    return s;
  }
  absl::Status Commit() {
    absl::Status s = db_.Exec("COMMIT", "commit");
    if (s.ok()) open_ = false;
    return s;
  }
  ~Transaction() {
    if (open_) sqlite3_exec(db_.get(), "ROLLBACK", nullptr, nullptr, nullptr);  // best effort on an error path
  }

 private:
  Db& db_;
  bool open_ = false;
};

#define AVE_RETURN_IF_ERROR(expr)        \
  do {                                   \
    absl::Status _st = (expr);           \
    if (!_st.ok()) return _st;           \
  } while (0)
#define AVE_ASSIGN_OR_RETURN(lhs, expr)         \
  auto lhs##_or = (expr);                       \
  if (!lhs##_or.ok()) return lhs##_or.status(); \
  auto lhs = std::move(*lhs##_or)

absl::StatusOr<int> QueryInt(Db& db, const char* sql) {
  AVE_ASSIGN_OR_RETURN(stmt, Stmt::Prepare(db, sql));
  AVE_ASSIGN_OR_RETURN(row, stmt.Step());
  if (!row) return absl::InternalError("model store '" + db.path() + "': \"" + sql + "\" returned no row");
  return static_cast<int>(stmt.Int(0));
}

constexpr char kCameraColumns[] =
    "id, name, width, height, fx, fy, cx, cy, k1, k2, p1, p2, k3, qw, qx, qy, qz, tx, ty, tz, source_url, enabled, "
    "updated_at_ns, kind";

CameraRecord ReadCamera(const Stmt& s) {
  CameraRecord c;
  c.id = s.Text(0);
  c.name = s.Text(1);
  PinholeIntrinsics& k = c.intrinsics;
  k.width = static_cast<int>(s.Int(2));
  k.height = static_cast<int>(s.Int(3));
  k.fx = s.Double(4), k.fy = s.Double(5), k.cx = s.Double(6), k.cy = s.Double(7);
  for (int i = 0; i < 5; ++i) k.distortion[i] = s.Double(8 + i);
  // Assigned directly: the Rigid3d constructor would renormalise and perturb the stored bits.
  c.world_from_camera.rotation = Eigen::Quaterniond(s.Double(13), s.Double(14), s.Double(15), s.Double(16));
  c.world_from_camera.translation = Eigen::Vector3d(s.Double(17), s.Double(18), s.Double(19));
  c.source_url = s.Text(20);
  c.enabled = s.Int(21) != 0;
  c.updated_at_ns = s.Int(22);
  c.kind = s.Text(23);
  return c;
}

// Binds all columns in kCameraColumns order; the rotation is normalised here.
absl::Status BindCamera(Stmt& s, const CameraRecord& c, int64_t now_ns) {
  const PinholeIntrinsics& k = c.intrinsics;
  const Eigen::Quaterniond q = c.world_from_camera.rotation.normalized();
  const Eigen::Vector3d& t = c.world_from_camera.translation;
  const auto& d = k.distortion;
  return s.Bind(c.id, c.name, k.width, k.height, k.fx, k.fy, k.cx, k.cy, d[0], d[1], d[2], d[3], d[4], q.w(), q.x(),
                q.y(), q.z(), t.x(), t.y(), t.z(), c.source_url, c.enabled, now_ns, c.kind);
}

}  // namespace

std::string ValidateCamera(const CameraRecord& c) {
  const std::string prefix = "camera '" + c.id + "': ";
  bool id_ok = !c.id.empty() && c.id.size() <= 64;
  for (char ch : c.id) {
    id_ok = id_ok && (std::isalnum(static_cast<unsigned char>(ch)) || ch == '_' || ch == '.' || ch == '-');
  }
  if (!id_ok) return prefix + "id must match [A-Za-z0-9_.-]{1,64}";
  if (c.name.size() > 128) return prefix + "name must be at most 128 characters";
  if (c.kind == kSensorKindRotatingLidar) {
    const PinholeIntrinsics& k = c.intrinsics;
    const bool zero = k.width == 0 && k.height == 0 && k.fx == 0 && k.fy == 0 && k.cx == 0 && k.cy == 0 &&
                      k.distortion == std::array<double, 5>{};
    if (!zero) return prefix + "intrinsics must be absent (zero) for a rotating LiDAR";
  } else if (c.kind != kSensorKindCamera) {
    return prefix + "kind must be '" + kSensorKindCamera + "' or '" + kSensorKindRotatingLidar + "', not '" + c.kind + "'";
  } else if (std::string why = c.intrinsics.Check(); !why.empty()) {
    return prefix + "intrinsics." + why;
  }
  if (!c.world_from_camera.translation.allFinite()) return prefix + "world_from_camera.translation must be finite";
  const Eigen::Quaterniond& q = c.world_from_camera.rotation;
  if (!q.coeffs().allFinite()) return prefix + "world_from_camera.rotation must be finite";
  if (std::abs(1.0 - q.norm()) > 1e-3)
    return prefix + "world_from_camera.rotation must be a unit quaternion (|q| = " + std::to_string(q.norm()) + ")";
  if (c.source_url.size() > 1024) return prefix + "source_url must be at most 1024 characters";
  return {};
}

class Store::Impl {
 public:
  Impl(std::unique_ptr<Db> db, int version) : db(std::move(db)), schema_version(version) {}
  std::mutex mu;
  std::unique_ptr<Db> db;
  int schema_version;
};

Store::Store(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Store::~Store() = default;
int Store::SchemaVersion() const { return impl_->schema_version; }
int Store::LatestSchemaVersion() { return static_cast<int>(Migrations().size()); }
const std::string& Store::path() const { return impl_->db->path(); }

absl::StatusOr<std::unique_ptr<Store>> Store::Open(const std::string& path) {
  AVE_ASSIGN_OR_RETURN(db, Db::Open(path));
  if (sqlite3_busy_timeout(db->get(), 5000) != SQLITE_OK) return db->Error("set busy timeout");
  AVE_RETURN_IF_ERROR(db->Exec("PRAGMA foreign_keys = ON", "enable foreign keys"));
  {
    AVE_ASSIGN_OR_RETURN(stmt, Stmt::Prepare(*db, "PRAGMA journal_mode = WAL"));
    AVE_ASSIGN_OR_RETURN(row, stmt.Step());
    const std::string mode = row ? stmt.Text(0) : "";
    if (mode != "wal" && !(path == ":memory:" && mode == "memory")) {
      return absl::FailedPreconditionError("model store '" + path + "': cannot enable WAL journal (mode is '" + mode +
                                           "')");
    }
  }
  AVE_ASSIGN_OR_RETURN(version, QueryInt(*db, "PRAGMA user_version"));
  const int latest = LatestSchemaVersion();
  if (version > latest || version < 0) {
    return absl::FailedPreconditionError("model store '" + path + "' has schema version " + std::to_string(version) +
                                         ", newer than the latest this build knows (" + std::to_string(latest) +
                                         "); refusing to open it (upgrade AVE)");
  }
  for (; version < latest; ++version) {
    const std::string step = "migrate schema " + std::to_string(version) + " -> " + std::to_string(version + 1);
    Transaction txn(*db);
    AVE_RETURN_IF_ERROR(txn.Begin());
    AVE_RETURN_IF_ERROR(db->Exec(Migrations()[version], step));
    const std::string set_version = "PRAGMA user_version = " + std::to_string(version + 1);
    AVE_RETURN_IF_ERROR(db->Exec(set_version.c_str(), step));
    AVE_RETURN_IF_ERROR(txn.Commit());
  }
  return std::unique_ptr<Store>(new Store(std::make_unique<Impl>(std::move(db), version)));
}

absl::Status Store::AddCamera(const CameraRecord& camera) {
  if (std::string why = ValidateCamera(camera); !why.empty()) return absl::InvalidArgumentError(why);
  std::lock_guard lock(impl_->mu);
  AVE_ASSIGN_OR_RETURN(stmt, Stmt::Prepare(*impl_->db, (std::string("INSERT INTO cameras (") + kCameraColumns +
                                                        ") VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)")
                                                           .c_str()));
  AVE_RETURN_IF_ERROR(BindCamera(stmt, camera, NowNs()));
  absl::Status s = stmt.Run();
  if (absl::IsAlreadyExists(s)) return absl::AlreadyExistsError("camera '" + camera.id + "' already exists");
  return s;
}

absl::Status Store::UpdateCamera(const CameraRecord& camera) {
  if (std::string why = ValidateCamera(camera); !why.empty()) return absl::InvalidArgumentError(why);
  std::lock_guard lock(impl_->mu);
  // Parameter 1 is the id (WHERE ?1), the rest follow kCameraColumns order.
  AVE_ASSIGN_OR_RETURN(stmt, Stmt::Prepare(*impl_->db,
                                           "UPDATE cameras SET name=?2, width=?3, height=?4, fx=?5, fy=?6, cx=?7, "
                                           "cy=?8, k1=?9, k2=?10, p1=?11, p2=?12, k3=?13, qw=?14, qx=?15, qy=?16, "
                                           "qz=?17, tx=?18, ty=?19, tz=?20, source_url=?21, enabled=?22, "
                                           "updated_at_ns=?23, kind=?24 WHERE id=?1"));
  AVE_RETURN_IF_ERROR(BindCamera(stmt, camera, NowNs()));
  AVE_RETURN_IF_ERROR(stmt.Run());
  if (sqlite3_changes(impl_->db->get()) == 0) return absl::NotFoundError("camera '" + camera.id + "' not found");
  return absl::OkStatus();
}

absl::Status Store::RemoveCamera(const std::string& id) {
  std::lock_guard lock(impl_->mu);
  AVE_ASSIGN_OR_RETURN(stmt, Stmt::Prepare(*impl_->db, "DELETE FROM cameras WHERE id = ?"));
  AVE_RETURN_IF_ERROR(stmt.Bind(id));
  AVE_RETURN_IF_ERROR(stmt.Run());
  if (sqlite3_changes(impl_->db->get()) == 0) return absl::NotFoundError("camera '" + id + "' not found");
  return absl::OkStatus();
}

absl::StatusOr<CameraRecord> Store::GetCamera(const std::string& id) {
  std::lock_guard lock(impl_->mu);
  AVE_ASSIGN_OR_RETURN(
      stmt, Stmt::Prepare(*impl_->db, (std::string("SELECT ") + kCameraColumns + " FROM cameras WHERE id = ?").c_str()));
  AVE_RETURN_IF_ERROR(stmt.Bind(id));
  AVE_ASSIGN_OR_RETURN(row, stmt.Step());
  if (!row) return absl::NotFoundError("camera '" + id + "' not found");
  CameraRecord camera = ReadCamera(stmt);
  // Rows are validated on write; one edited outside ave (or by an older build) is refused here.
  if (std::string why = ValidateCamera(camera); !why.empty()) return absl::DataLossError("model store '" + path() + "': " + why);
  return camera;
}

absl::StatusOr<std::vector<CameraRecord>> Store::ListCameras() {
  std::lock_guard lock(impl_->mu);
  AVE_ASSIGN_OR_RETURN(
      stmt, Stmt::Prepare(*impl_->db, (std::string("SELECT ") + kCameraColumns + " FROM cameras ORDER BY id").c_str()));
  std::vector<CameraRecord> out;
  for (;;) {
    AVE_ASSIGN_OR_RETURN(row, stmt.Step());
    if (!row) return out;
    out.push_back(ReadCamera(stmt));
    if (std::string why = ValidateCamera(out.back()); !why.empty()) {
      return absl::DataLossError("model store '" + impl_->db->path() + "': " + why);
    }
  }
}

absl::StatusOr<int64_t> Store::PutStaticModel(const std::string& name, const TriangleMesh& mesh) {
  AVE_ASSIGN_OR_RETURN(blob, EncodeMesh(mesh, "static model '" + name + "'"));
  std::lock_guard lock(impl_->mu);
  AVE_ASSIGN_OR_RETURN(
      stmt, Stmt::Prepare(*impl_->db, "INSERT INTO static_models (name, created_at_ns, mesh) VALUES (?, ?, ?)"));
  AVE_RETURN_IF_ERROR(stmt.Bind(name, NowNs(), Blob{blob}));
  AVE_RETURN_IF_ERROR(stmt.Run());
  return sqlite3_last_insert_rowid(impl_->db->get());
}

absl::StatusOr<std::optional<StaticModelRecord>> Store::LatestStaticModel() {
  std::lock_guard lock(impl_->mu);
  AVE_ASSIGN_OR_RETURN(stmt, Stmt::Prepare(*impl_->db,
                                           "SELECT version, name, created_at_ns, mesh FROM static_models "
                                           "ORDER BY version DESC LIMIT 1"));
  AVE_ASSIGN_OR_RETURN(row, stmt.Step());
  if (!row) return std::optional<StaticModelRecord>();
  StaticModelRecord rec;
  rec.version = stmt.Int(0);
  rec.name = stmt.Text(1);
  rec.created_at_ns = stmt.Int(2);
  AVE_ASSIGN_OR_RETURN(
      mesh, DecodeMesh(stmt.BlobAt(3), "model store '" + path() + "': static_models version " + std::to_string(rec.version)));
  rec.mesh = std::move(mesh);
  return rec;
}

absl::StatusOr<int64_t> Store::AppendAudit(const std::string& actor, const std::string& action,
                                           const std::string& target, const std::string& before_json,
                                           const std::string& after_json) {
  std::lock_guard lock(impl_->mu);
  AVE_ASSIGN_OR_RETURN(stmt, Stmt::Prepare(*impl_->db,
                                           "INSERT INTO audit (at_ns, actor, action, target, before_json, after_json) "
                                           "VALUES (?, ?, ?, ?, ?, ?)"));
  AVE_RETURN_IF_ERROR(stmt.Bind(NowNs(), actor, action, target, before_json, after_json));
  AVE_RETURN_IF_ERROR(stmt.Run());
  return sqlite3_last_insert_rowid(impl_->db->get());
}

namespace {

bool IsHexDigest(const std::string& s) {
  if (s.size() != 64) return false;
  for (char c : s) {
    if (!((c >= '0' && c <= '9') || (c >= 'a' && c <= 'f'))) return false;
  }
  return true;
}

}  // namespace

absl::Status Store::AddToken(const TokenRecord& token) {
  if (!IsHexDigest(token.hash)) {
    return absl::InvalidArgumentError("token: hash must be 64 lowercase hex characters (a SHA-256 digest)");
  }
  if (token.role != "sensor" && token.role != "viewer" && token.role != "admin") {
    return absl::InvalidArgumentError("token: role must be sensor, viewer or admin, not '" + token.role + "'");
  }
  if (token.role == "sensor" && token.camera_id.empty()) {
    return absl::InvalidArgumentError("token: a sensor token must name its camera_id");
  }
  if (token.camera_id.size() > 64 || token.label.size() > 128) {
    return absl::InvalidArgumentError("token: camera_id at most 64 and label at most 128 characters");
  }
  std::lock_guard lock(impl_->mu);
  AVE_ASSIGN_OR_RETURN(stmt, Stmt::Prepare(*impl_->db,
                                           "INSERT INTO tokens (hash, role, camera_id, label, created_at_ns, revoked) "
                                           "VALUES (?, ?, ?, ?, ?, 0)"));
  AVE_RETURN_IF_ERROR(stmt.Bind(token.hash, token.role, token.camera_id, token.label, NowNs()));
  absl::Status s = stmt.Run();
  if (absl::IsAlreadyExists(s)) return absl::AlreadyExistsError("token " + token.hash.substr(0, 12) + " already exists");
  return s;
}

absl::Status Store::RevokeToken(const std::string& hash_prefix) {
  if (hash_prefix.size() < 8 || hash_prefix.size() > 64) {
    return absl::InvalidArgumentError("token id must be 8..64 hex characters of the token's hash");
  }
  std::lock_guard lock(impl_->mu);
  AVE_ASSIGN_OR_RETURN(stmt, Stmt::Prepare(*impl_->db,
                                           "UPDATE tokens SET revoked = 1 WHERE substr(hash, 1, ?1) = ?2"));
  AVE_RETURN_IF_ERROR(stmt.Bind(static_cast<int>(hash_prefix.size()), hash_prefix));
  AVE_RETURN_IF_ERROR(stmt.Run());
  const int changed = sqlite3_changes(impl_->db->get());
  if (changed == 0) return absl::NotFoundError("token " + hash_prefix + " not found");
  return absl::OkStatus();
}

absl::StatusOr<std::vector<TokenRecord>> Store::ListTokens() {
  std::lock_guard lock(impl_->mu);
  AVE_ASSIGN_OR_RETURN(stmt, Stmt::Prepare(*impl_->db,
                                           "SELECT hash, role, camera_id, label, created_at_ns, revoked FROM tokens "
                                           "ORDER BY created_at_ns, hash"));
  std::vector<TokenRecord> out;
  for (;;) {
    AVE_ASSIGN_OR_RETURN(row, stmt.Step());
    if (!row) return out;
    out.push_back(TokenRecord{stmt.Text(0), stmt.Text(1), stmt.Text(2), stmt.Text(3), stmt.Int(4), stmt.Int(5) != 0});
  }
}

absl::StatusOr<std::vector<AuditEntry>> Store::ListAudit(int limit) {
  if (limit < 0) return absl::InvalidArgumentError("ListAudit: limit must be >= 0");
  std::lock_guard lock(impl_->mu);
  AVE_ASSIGN_OR_RETURN(stmt, Stmt::Prepare(*impl_->db,
                                           "SELECT id, at_ns, actor, action, target, before_json, after_json "
                                           "FROM audit ORDER BY id DESC LIMIT ?"));
  AVE_RETURN_IF_ERROR(stmt.Bind(limit));
  std::vector<AuditEntry> out;
  for (;;) {
    AVE_ASSIGN_OR_RETURN(row, stmt.Step());
    if (!row) return out;
    out.push_back(AuditEntry{stmt.Int(0), stmt.Int(1), stmt.Text(2), stmt.Text(3), stmt.Text(4), stmt.Text(5),
                             stmt.Text(6)});
  }
}

namespace {

std::string PackPolygon(const std::vector<Eigen::Vector2d>& polygon) {
  std::string out(polygon.size() * 2 * sizeof(double), '\0');
  std::memcpy(out.data(), polygon.data(), out.size());  // Vector2d is two packed doubles
  return out;
}

absl::StatusOr<std::vector<Eigen::Vector2d>> UnpackPolygon(std::string_view bytes, const std::string& what) {
  if (bytes.size() % (2 * sizeof(double)) != 0) return absl::DataLossError(what + ": polygon blob of " + std::to_string(bytes.size()) + " bytes");
  std::vector<Eigen::Vector2d> out(bytes.size() / (2 * sizeof(double)));
  std::memcpy(static_cast<void*>(out.data()), bytes.data(), bytes.size());
  for (size_t i = 0; i < out.size(); ++i) {
    if (!out[i].allFinite()) return absl::DataLossError(what + ": polygon vertex " + std::to_string(i) + " is not finite");
  }
  return out;
}

// The rules a scene, a tile and a building obey, checked when they are stored and again when they
// are read back (a row edited or damaged on disk is refused naming the store, table and row, not
// handed on; issue 14). Empty when usable.
std::string CheckSceneFields(const SceneRecord& scene) {
  if (scene.name.empty() || scene.name.size() > 128) return "scene name must be 1..128 characters";
  if (!scene.origin.allFinite()) return "scene '" + scene.name + "': origin must be finite";
  return {};
}
std::string CheckTile(const TerrainTileRecord& t) {
  if (t.cols <= 0 || t.rows <= 0 || !(t.resolution_m > 0) || !std::isfinite(t.resolution_m) || !std::isfinite(t.min_x) ||
      !std::isfinite(t.min_y)) {
    return "terrain tile (" + std::to_string(t.tile_col) + ", " + std::to_string(t.tile_row) +
           ") needs cols, rows, resolution_m > 0 and a finite corner";
  }
  return {};
}
std::string CheckBuilding(const StoredBuilding& b) {
  if (!std::isfinite(b.area_m2)) return "building " + std::to_string(b.building_id) + " area must be finite";
  return {};
}

std::string ValidateScene(const SceneRecord& scene, const std::vector<TerrainTileRecord>& tiles,
                          const std::vector<StoredBuilding>& buildings) {
  if (std::string why = CheckSceneFields(scene); !why.empty()) return why;
  for (const TerrainTileRecord& t : tiles) {
    if (std::string why = CheckTile(t); !why.empty()) return "scene '" + scene.name + "': " + why;
  }
  for (const StoredBuilding& b : buildings) {
    if (std::string why = CheckBuilding(b); !why.empty()) return "scene '" + scene.name + "': " + why;
  }
  return {};
}

}  // namespace

absl::StatusOr<int64_t> Store::PutScene(const SceneRecord& scene, const std::vector<TerrainTileRecord>& tiles,
                                        const std::vector<StoredBuilding>& buildings) {
  if (std::string why = ValidateScene(scene, tiles, buildings); !why.empty()) return absl::InvalidArgumentError(why);
  std::lock_guard lock(impl_->mu);
  Db& db = *impl_->db;
  Transaction txn(db);
  AVE_RETURN_IF_ERROR(txn.Begin());
  AVE_ASSIGN_OR_RETURN(insert_scene, Stmt::Prepare(db,
                                                   "INSERT INTO scenes (name, origin_x, origin_y, origin_z, input_path, "
                                                   "input_sha256, parameters_json, summary_json, static_model_version, "
                                                   "created_at_ns) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?)"));
  AVE_RETURN_IF_ERROR(insert_scene.Bind(scene.name, scene.origin.x(), scene.origin.y(), scene.origin.z(), scene.input_path,
                                        scene.input_sha256, scene.parameters_json, scene.summary_json));
  AVE_RETURN_IF_ERROR(scene.static_model_version ? insert_scene.BindAt(9, *scene.static_model_version) : insert_scene.BindNullAt(9));
  AVE_RETURN_IF_ERROR(insert_scene.BindAt(10, NowNs()));
  AVE_RETURN_IF_ERROR(insert_scene.Run());
  const int64_t id = sqlite3_last_insert_rowid(db.get());
  AVE_ASSIGN_OR_RETURN(insert_tile, Stmt::Prepare(db,
                                                  "INSERT INTO terrain_tiles (scene_id, tile_col, tile_row, min_x, min_y, "
                                                  "resolution_m, cols, rows, format, data) VALUES (?,?,?,?,?,?,?,?,?,?)"));
  for (const TerrainTileRecord& t : tiles) {
    AVE_RETURN_IF_ERROR(insert_tile.Reset());
    AVE_RETURN_IF_ERROR(insert_tile.Bind(id, t.tile_col, t.tile_row, t.min_x, t.min_y, t.resolution_m, t.cols, t.rows, t.format, Blob{t.data}));
    AVE_RETURN_IF_ERROR(insert_tile.Run());
  }
  AVE_ASSIGN_OR_RETURN(insert_building, Stmt::Prepare(db,
                                                      "INSERT INTO buildings (scene_id, building_id, roof, footprint, area_m2, "
                                                      "point_count) VALUES (?,?,?,?,?,?)"));
  AVE_ASSIGN_OR_RETURN(insert_part, Stmt::Prepare(db,
                                                  "INSERT INTO building_primitives (scene_id, building_id, part, type, roof, "
                                                  "center_x, center_y, size_x, size_y, yaw_rad, base_z_m, eave_height_m, "
                                                  "roof_height_m, polygon, rms_m, point_count) "
                                                  "VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)"));
  for (const StoredBuilding& b : buildings) {
    AVE_RETURN_IF_ERROR(insert_building.Reset());
    const std::string footprint = PackPolygon(b.footprint_m);
    AVE_RETURN_IF_ERROR(insert_building.Bind(id, b.building_id, b.roof, Blob{footprint}, b.area_m2, b.point_count));
    AVE_RETURN_IF_ERROR(insert_building.Run());
    for (size_t k = 0; k < b.parts.size(); ++k) {
      const PrimitiveRecord& p = b.parts[k];
      const std::string polygon = PackPolygon(p.polygon_m);
      AVE_RETURN_IF_ERROR(insert_part.Reset());
      AVE_RETURN_IF_ERROR(insert_part.Bind(id, b.building_id, static_cast<int64_t>(k), p.type, p.roof, p.center_m.x(), p.center_m.y(),
                                           p.size_m.x(), p.size_m.y(), p.yaw_rad, p.base_z_m, p.eave_height_m, p.roof_height_m,
                                           Blob{polygon}, p.rms_m, p.point_count));
      AVE_RETURN_IF_ERROR(insert_part.Run());
    }
  }
  AVE_RETURN_IF_ERROR(txn.Commit());
  return id;
}

absl::StatusOr<std::vector<SceneRecord>> Store::ListScenes() {
  std::lock_guard lock(impl_->mu);
  AVE_ASSIGN_OR_RETURN(stmt, Stmt::Prepare(*impl_->db,
                                           "SELECT id, name, origin_x, origin_y, origin_z, input_path, input_sha256, "
                                           "parameters_json, summary_json, static_model_version, created_at_ns "
                                           "FROM scenes ORDER BY id"));
  std::vector<SceneRecord> out;
  for (;;) {
    AVE_ASSIGN_OR_RETURN(row, stmt.Step());
    if (!row) return out;
    SceneRecord s;
    s.id = stmt.Int(0);
    s.name = stmt.Text(1);
    s.origin = {stmt.Double(2), stmt.Double(3), stmt.Double(4)};
    s.input_path = stmt.Text(5);
    s.input_sha256 = stmt.Text(6);
    s.parameters_json = stmt.Text(7);
    s.summary_json = stmt.Text(8);
    if (!stmt.IsNull(9)) s.static_model_version = stmt.Int(9);
    s.created_at_ns = stmt.Int(10);
    if (std::string why = CheckSceneFields(s); !why.empty())
      return absl::DataLossError("model store '" + path() + "': scenes row " + std::to_string(s.id) + ": " + why);
    out.push_back(std::move(s));
  }
}

absl::StatusOr<std::vector<TerrainTileRecord>> Store::GetTerrainTiles(int64_t scene_id) {
  std::lock_guard lock(impl_->mu);
  AVE_ASSIGN_OR_RETURN(stmt, Stmt::Prepare(*impl_->db,
                                           "SELECT tile_col, tile_row, min_x, min_y, resolution_m, cols, rows, format, data "
                                           "FROM terrain_tiles WHERE scene_id = ? ORDER BY tile_row, tile_col"));
  AVE_RETURN_IF_ERROR(stmt.Bind(scene_id));
  std::vector<TerrainTileRecord> out;
  for (;;) {
    AVE_ASSIGN_OR_RETURN(row, stmt.Step());
    if (!row) return out;
    TerrainTileRecord t{static_cast<int>(stmt.Int(0)), static_cast<int>(stmt.Int(1)), stmt.Double(2), stmt.Double(3),
                        stmt.Double(4), static_cast<int>(stmt.Int(5)), static_cast<int>(stmt.Int(6)), stmt.Text(7),
                        std::string(stmt.BlobAt(8))};
    if (std::string why = CheckTile(t); !why.empty())
      return absl::DataLossError("model store '" + path() + "': scene " + std::to_string(scene_id) + ": " + why);
    out.push_back(std::move(t));
  }
}

absl::StatusOr<std::vector<StoredBuilding>> Store::GetBuildings(int64_t scene_id) {
  std::lock_guard lock(impl_->mu);
  const std::string what = "model store '" + path() + "': scene " + std::to_string(scene_id);
  AVE_ASSIGN_OR_RETURN(stmt, Stmt::Prepare(*impl_->db,
                                           "SELECT building_id, roof, footprint, area_m2, point_count FROM buildings "
                                           "WHERE scene_id = ? ORDER BY building_id"));
  AVE_RETURN_IF_ERROR(stmt.Bind(scene_id));
  std::vector<StoredBuilding> out;
  for (;;) {
    AVE_ASSIGN_OR_RETURN(row, stmt.Step());
    if (!row) break;
    StoredBuilding b;
    b.building_id = stmt.Int(0);
    b.roof = stmt.Text(1);
    AVE_ASSIGN_OR_RETURN(footprint, UnpackPolygon(stmt.BlobAt(2), what));
    b.footprint_m = std::move(footprint);
    b.area_m2 = stmt.Double(3);
    b.point_count = stmt.Int(4);
    if (std::string why = CheckBuilding(b); !why.empty()) return absl::DataLossError(what + ": " + why);
    out.push_back(std::move(b));
  }
  AVE_ASSIGN_OR_RETURN(parts, Stmt::Prepare(*impl_->db,
                                            "SELECT type, roof, center_x, center_y, size_x, size_y, yaw_rad, base_z_m, "
                                            "eave_height_m, roof_height_m, polygon, rms_m, point_count "
                                            "FROM building_primitives WHERE scene_id = ? AND building_id = ? ORDER BY part"));
  for (StoredBuilding& b : out) {
    AVE_RETURN_IF_ERROR(parts.Reset());
    AVE_RETURN_IF_ERROR(parts.Bind(scene_id, b.building_id));
    for (;;) {
      AVE_ASSIGN_OR_RETURN(row, parts.Step());
      if (!row) break;
      PrimitiveRecord p;
      p.type = parts.Text(0);
      p.roof = parts.Text(1);
      p.center_m = {parts.Double(2), parts.Double(3)};
      p.size_m = {parts.Double(4), parts.Double(5)};
      p.yaw_rad = parts.Double(6);
      p.base_z_m = parts.Double(7);
      p.eave_height_m = parts.Double(8);
      p.roof_height_m = parts.Double(9);
      AVE_ASSIGN_OR_RETURN(polygon, UnpackPolygon(parts.BlobAt(10), what));
      p.polygon_m = std::move(polygon);
      p.rms_m = parts.Double(11);
      p.point_count = parts.Int(12);
      b.parts.push_back(std::move(p));
    }
  }
  return out;
}

std::string ValidateAvatarName(const std::string& name) {
  bool ok = !name.empty() && name.size() <= 64;
  for (char ch : name) ok = ok && (std::isalnum(static_cast<unsigned char>(ch)) || ch == '_' || ch == '.' || ch == '-');
  return ok ? std::string() : "avatar sequence name '" + name.substr(0, 80) + "' must match [A-Za-z0-9_.-]{1,64}";
}

absl::StatusOr<int64_t> Store::PutAvatarSequence(const avatar::AvatarSequence& sequence) {
  if (std::string why = ValidateAvatarName(sequence.name); !why.empty()) return absl::InvalidArgumentError(why);
  AVE_ASSIGN_OR_RETURN(blob, avatar::EncodeAvatarSequence(sequence, "avatar sequence '" + sequence.name + "'"));
  std::lock_guard lock(impl_->mu);
  AVE_ASSIGN_OR_RETURN(stmt, Stmt::Prepare(*impl_->db,
                                           "INSERT INTO avatar_sequences (name, frame_count, frame_period_s, stride_m, "
                                           "created_at_ns, blob) VALUES (?, ?, ?, ?, ?, ?)"));
  AVE_RETURN_IF_ERROR(stmt.Bind(sequence.name, static_cast<int64_t>(sequence.frames.size()), sequence.frame_period_s,
                                sequence.stride_m, NowNs(), Blob{blob}));
  absl::Status s = stmt.Run();
  if (absl::IsAlreadyExists(s)) return absl::AlreadyExistsError("avatar sequence '" + sequence.name + "' already exists");
  AVE_RETURN_IF_ERROR(s);
  return sqlite3_last_insert_rowid(impl_->db->get());
}

namespace {
constexpr char kAvatarColumns[] = "version, name, frame_count, frame_period_s, stride_m, created_at_ns, length(blob)";
AvatarSequenceRecord ReadAvatarRecord(const Stmt& s) {
  return AvatarSequenceRecord{s.Int(0), s.Text(1), s.Int(2), s.Double(3), s.Double(4), s.Int(5), s.Int(6), {}};
}
}  // namespace

absl::StatusOr<std::vector<AvatarSequenceRecord>> Store::ListAvatarSequences() {
  std::lock_guard lock(impl_->mu);
  AVE_ASSIGN_OR_RETURN(stmt, Stmt::Prepare(*impl_->db, (std::string("SELECT ") + kAvatarColumns +
                                                        " FROM avatar_sequences ORDER BY name").c_str()));
  std::vector<AvatarSequenceRecord> out;
  for (;;) {
    AVE_ASSIGN_OR_RETURN(row, stmt.Step());
    if (!row) return out;
    out.push_back(ReadAvatarRecord(stmt));
  }
}

absl::StatusOr<AvatarSequenceRecord> Store::GetAvatarSequenceBlob(const std::string& name) {
  std::lock_guard lock(impl_->mu);
  AVE_ASSIGN_OR_RETURN(stmt, Stmt::Prepare(*impl_->db, (std::string("SELECT ") + kAvatarColumns +
                                                        ", blob FROM avatar_sequences WHERE name = ?").c_str()));
  AVE_RETURN_IF_ERROR(stmt.Bind(name));
  AVE_ASSIGN_OR_RETURN(row, stmt.Step());
  if (!row) return absl::NotFoundError("avatar sequence '" + name + "' not found");
  AvatarSequenceRecord record = ReadAvatarRecord(stmt);
  record.blob = std::string(stmt.BlobAt(7));
  return record;
}

absl::StatusOr<avatar::AvatarSequence> Store::GetAvatarSequence(const std::string& name) {
  AVE_ASSIGN_OR_RETURN(record, GetAvatarSequenceBlob(name));
  return avatar::DecodeAvatarSequence(record.blob, "model store '" + path() + "': avatar_sequences row '" + name + "'");
}

}  // namespace ave::store
