#include "fusion_server/record/record_index.h"

#include <sqlite3.h>

#include <algorithm>
#include <map>
#include <tuple>
#include <utility>

#include "absl/strings/str_cat.h"

namespace ave::record {
namespace {

// RAII prepared statement; every failure becomes a Status naming the SQL and the store file.
class Stmt {
 public:
  Stmt(sqlite3* db, const std::string& path, const std::string& sql) : db_(db), path_(path) {
    if (sqlite3_prepare_v2(db, sql.c_str(), -1, &s_, nullptr) != SQLITE_OK) status_ = Error("prepare");
  }
  // A statement the index keeps prepared (RecordIndex::Cached): reset, not finalized, at the end.
  Stmt(sqlite3* db, const std::string& path, sqlite3_stmt* cached, const char* sql)
      : db_(db), path_(path), s_(cached), owned_(false) {
    if (!s_) status_ = absl::InternalError(absl::StrCat("recording index '", path_, "': prepare \"", sql, "\": ",
                                                         sqlite3_errmsg(db_)));
  }
  ~Stmt() {
    if (owned_) {
      sqlite3_finalize(s_);
    } else if (s_) {
      sqlite3_reset(s_);
      sqlite3_clear_bindings(s_);
    }
  }
  Stmt(const Stmt&) = delete;
  Stmt& operator=(const Stmt&) = delete;

  const absl::Status& status() const { return status_; }
  void Bind(int i, int64_t v) { Check(sqlite3_bind_int64(s_, i, v)); }
  void Bind(int i, const std::string& v) {
    Check(sqlite3_bind_text64(s_, i, v.data(), v.size(), SQLITE_TRANSIENT, SQLITE_UTF8));
  }
  void BindBlob(int i, const std::string& v) { Check(sqlite3_bind_blob64(s_, i, v.data(), v.size(), SQLITE_TRANSIENT)); }
  // True when a row is ready; false at the end or on an error (then status() says which).
  bool Step() {
    if (!status_.ok()) return false;
    const int rc = sqlite3_step(s_);
    if (rc == SQLITE_ROW) return true;
    if (rc != SQLITE_DONE) status_ = Error("step");
    return false;
  }
  absl::Status Run() {
    Step();
    sqlite3_reset(s_);
    sqlite3_clear_bindings(s_);
    return status_;
  }
  int64_t Int(int col) const { return sqlite3_column_int64(s_, col); }
  std::string Text(int col) const {
    const auto* p = reinterpret_cast<const char*>(sqlite3_column_text(s_, col));
    return p ? std::string(p, sqlite3_column_bytes(s_, col)) : std::string();
  }
  std::string BlobAt(int col) const {
    const auto* p = static_cast<const char*>(sqlite3_column_blob(s_, col));
    return p ? std::string(p, sqlite3_column_bytes(s_, col)) : std::string();
  }

 private:
  void Check(int rc) {
    if (rc != SQLITE_OK && status_.ok()) status_ = Error("bind");
  }
  absl::Status Error(const char* what) const {
    return absl::InternalError(absl::StrCat("recording index '", path_, "': ", what, " \"",
                                            s_ ? sqlite3_sql(s_) : "?", "\": ", sqlite3_errmsg(db_)));
  }
  sqlite3* db_;
  const std::string& path_;
  sqlite3_stmt* s_ = nullptr;
  bool owned_ = true;
  absl::Status status_;
};

// "sensor_id IN (?, ?, ...)" for a non-empty list, else "1".
std::string SensorFilter(const char* column, size_t n, int first_param) {
  if (n == 0) return "1";
  std::string s = absl::StrCat(column, " IN (");
  for (size_t i = 0; i < n; ++i) absl::StrAppend(&s, i ? ", " : "", "?", first_param + static_cast<int>(i));
  return s + ")";
}

FrameRow ReadFrame(const Stmt& s) {
  FrameRow f;
  f.segment_id = s.Int(0);
  f.segment_path = s.Text(1);
  f.sensor_id = s.Text(2);
  f.sequence = static_cast<uint64_t>(s.Int(3));
  f.capture_server_ns = s.Int(4);
  f.received_ns = s.Int(5);
  f.offset = s.Int(6);
  f.length = s.Int(7);
  f.meta = s.BlobAt(8);
  return f;
}

constexpr char kFrameColumns[] =
    "f.segment_id, g.path, f.sensor_id, f.sequence, f.capture_server_ns, f.received_ns, f.offset, f.length, f.meta";

}  // namespace

absl::StatusOr<std::unique_ptr<RecordIndex>> RecordIndex::Open(const std::string& store_path) {
  sqlite3* raw = nullptr;
  const int rc = sqlite3_open_v2(store_path.c_str(), &raw, SQLITE_OPEN_READWRITE, nullptr);
  std::unique_ptr<RecordIndex> index(new RecordIndex(raw, store_path));
  if (rc != SQLITE_OK) {
    return absl::UnavailableError(absl::StrCat("recording index '", store_path, "': cannot open: ",
                                               raw ? sqlite3_errmsg(raw) : sqlite3_errstr(rc)));
  }
  sqlite3_busy_timeout(raw, 5000);
  if (absl::Status s = index->Exec("PRAGMA foreign_keys = ON"); !s.ok()) return s;
  // Rows are committed after their bytes are fdatasync'd; the commit itself needs to be durable
  // only as far as WAL's NORMAL gives (a power cut may lose the last batch, never corrupt).
  if (absl::Status s = index->Exec("PRAGMA synchronous = NORMAL"); !s.ok()) return s;
  Stmt check(raw, index->path_, "SELECT count(*) FROM sqlite_master WHERE name = 'record_frames'");
  if (!check.Step() || check.Int(0) != 1) {
    return absl::FailedPreconditionError(
        absl::StrCat("recording index '", store_path, "': no record_frames table (open it with store::Store first)"));
  }
  return index;
}

RecordIndex::~RecordIndex() {
  for (auto& [sql, stmt] : cached_) sqlite3_finalize(stmt);
  sqlite3_close_v2(db_);
}

sqlite3_stmt* RecordIndex::Cached(const char* sql) {
  auto it = cached_.find(sql);
  if (it != cached_.end()) return it->second;
  sqlite3_stmt* stmt = nullptr;
  if (sqlite3_prepare_v2(db_, sql, -1, &stmt, nullptr) != SQLITE_OK) return nullptr;
  cached_.emplace(sql, stmt);
  return stmt;
}

absl::Status RecordIndex::Error(const std::string& what) const {
  return absl::InternalError(absl::StrCat("recording index '", path_, "': ", what, ": ", sqlite3_errmsg(db_)));
}

absl::Status RecordIndex::Exec(const char* sql) {
  if (sqlite3_exec(db_, sql, nullptr, nullptr, nullptr) != SQLITE_OK) return Error(sql);
  return absl::OkStatus();
}

absl::Status RecordIndex::Commit(IndexBatch& batch) {
  if (absl::Status s = Exec("BEGIN IMMEDIATE"); !s.ok()) return s;
  auto body = [&]() -> absl::Status {
    std::map<std::string, int64_t> ids;
    static constexpr char kInsertSegment[] =
        "INSERT INTO record_segments (sensor_id, path, start_ns, end_ns, bytes, closed) VALUES (?1, ?2, ?3, ?4, ?5, ?6)";
    Stmt insert_seg(db_, path_, Cached(kInsertSegment), kInsertSegment);
    static constexpr char kUpdateSegment[] =
        "UPDATE record_segments SET end_ns = ?2, bytes = ?3, closed = ?4 WHERE id = ?1";
    Stmt update_seg(db_, path_, Cached(kUpdateSegment), kUpdateSegment);
    for (SegmentRow* seg : batch.segments) {
      if (seg->id == 0) {
        insert_seg.Bind(1, seg->sensor_id);
        insert_seg.Bind(2, seg->path);
        insert_seg.Bind(3, seg->start_ns);
        insert_seg.Bind(4, seg->end_ns);
        insert_seg.Bind(5, seg->bytes);
        insert_seg.Bind(6, int64_t{seg->closed});
        if (absl::Status s = insert_seg.Run(); !s.ok()) return s;
        ids[seg->path] = sqlite3_last_insert_rowid(db_);
      } else {
        update_seg.Bind(1, seg->id);
        update_seg.Bind(2, seg->end_ns);
        update_seg.Bind(3, seg->bytes);
        update_seg.Bind(4, int64_t{seg->closed});
        if (absl::Status s = update_seg.Run(); !s.ok()) return s;
        ids[seg->path] = seg->id;
      }
    }
    static constexpr char kInsertFrame[] =
        "INSERT INTO record_frames (segment_id, sensor_id, sequence, capture_server_ns, received_ns, offset, "
        "length, meta) VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8)";
    Stmt insert_frame(db_, path_, Cached(kInsertFrame), kInsertFrame);
    for (const FrameRow& f : batch.frames) {
      int64_t segment_id = f.segment_id;
      if (segment_id == 0) {
        auto it = ids.find(f.segment_path);
        if (it == ids.end()) return absl::InternalError("recording index: frame row for an unknown segment " + f.segment_path);
        segment_id = it->second;
      }
      insert_frame.Bind(1, segment_id);
      insert_frame.Bind(2, f.sensor_id);
      insert_frame.Bind(3, static_cast<int64_t>(f.sequence));
      insert_frame.Bind(4, f.capture_server_ns);
      insert_frame.Bind(5, f.received_ns);
      insert_frame.Bind(6, f.offset);
      insert_frame.Bind(7, f.length);
      insert_frame.BindBlob(8, f.meta);
      if (absl::Status s = insert_frame.Run(); !s.ok()) return s;
    }
    static constexpr char kInsertSweep[] =
        "INSERT INTO record_sweeps (sensor_id, sequence, capture_server_ns, received_ns, meta) VALUES (?1, ?2, ?3, ?4, ?5)";
    Stmt insert_sweep(db_, path_, Cached(kInsertSweep), kInsertSweep);
    for (const SweepRow& w : batch.sweeps) {
      insert_sweep.Bind(1, w.sensor_id);
      insert_sweep.Bind(2, static_cast<int64_t>(w.sequence));
      insert_sweep.Bind(3, w.capture_server_ns);
      insert_sweep.Bind(4, w.received_ns);
      insert_sweep.BindBlob(5, w.meta);
      if (absl::Status s = insert_sweep.Run(); !s.ok()) return s;
    }
    static constexpr char kInsertObjects[] =
        "INSERT INTO record_objects (t_ns, objects) VALUES (?1, ?2)";
    Stmt insert_objects(db_, path_, Cached(kInsertObjects), kInsertObjects);
    for (const ObjectsRow& o : batch.objects) {
      insert_objects.Bind(1, o.t_ns);
      insert_objects.BindBlob(2, o.objects);
      if (absl::Status s = insert_objects.Run(); !s.ok()) return s;
    }
    static constexpr char kUpsertSensor[] =
        "INSERT INTO record_sensors (sensor_id, camera, updated_ns) VALUES (?1, ?2, strftime('%s','now') * 1000000000) "
        "ON CONFLICT(sensor_id) DO UPDATE SET camera = excluded.camera, updated_ns = excluded.updated_ns";
    Stmt upsert_sensor(db_, path_, Cached(kUpsertSensor), kUpsertSensor);
    for (const auto& [id, camera] : batch.sensors) {
      upsert_sensor.Bind(1, id);
      upsert_sensor.BindBlob(2, camera);
      if (absl::Status s = upsert_sensor.Run(); !s.ok()) return s;
    }
    return absl::OkStatus();
  };
  if (absl::Status s = body(); !s.ok()) {
    sqlite3_exec(db_, "ROLLBACK", nullptr, nullptr, nullptr);
    return s;
  }
  if (absl::Status s = Exec("COMMIT"); !s.ok()) {
    sqlite3_exec(db_, "ROLLBACK", nullptr, nullptr, nullptr);
    return s;
  }
  for (SegmentRow* seg : batch.segments) {
    if (seg->id == 0) {
      Stmt q(db_, path_, "SELECT id FROM record_segments WHERE path = ?1");
      q.Bind(1, seg->path);
      if (q.Step()) seg->id = q.Int(0);
    }
  }
  return absl::OkStatus();
}

std::vector<RecordedIntervals> MergeSegmentIntervals(std::vector<SegmentRow> segments,
                                                     const std::vector<std::string>& sensor_ids, int64_t merge_gap_ns) {
  std::sort(segments.begin(), segments.end(), [](const SegmentRow& a, const SegmentRow& b) {
    return std::tie(a.sensor_id, a.start_ns, a.end_ns) < std::tie(b.sensor_id, b.start_ns, b.end_ns);
  });
  std::vector<RecordedIntervals> out;
  for (const SegmentRow& seg : segments) {
    if (seg.end_ns < seg.start_ns) continue;
    if (!sensor_ids.empty() && std::find(sensor_ids.begin(), sensor_ids.end(), seg.sensor_id) == sensor_ids.end()) {
      continue;
    }
    if (out.empty() || out.back().sensor_id != seg.sensor_id) out.push_back({seg.sensor_id, {}});
    auto& intervals = out.back().intervals;
    if (!intervals.empty() && seg.start_ns - intervals.back().second <= merge_gap_ns) {
      intervals.back().second = std::max(intervals.back().second, seg.end_ns);
    } else {
      intervals.emplace_back(seg.start_ns, seg.end_ns);
    }
  }
  return out;
}

absl::StatusOr<std::vector<SegmentRow>> RecordIndex::Segments() {
  Stmt s(db_, path_, "SELECT id, sensor_id, path, start_ns, end_ns, bytes, closed FROM record_segments ORDER BY start_ns, id");
  std::vector<SegmentRow> out;
  while (s.Step()) {
    out.push_back({s.Int(0), s.Text(1), s.Text(2), s.Int(3), s.Int(4), s.Int(5), s.Int(6) != 0});
  }
  if (!s.status().ok()) return s.status();
  return out;
}

absl::Status RecordIndex::DeleteSegment(int64_t segment_id) {
  if (absl::Status s = Exec("BEGIN IMMEDIATE"); !s.ok()) return s;
  Stmt frames(db_, path_, "DELETE FROM record_frames WHERE segment_id = ?1");
  frames.Bind(1, segment_id);
  absl::Status st = frames.Run();
  if (st.ok()) {
    Stmt seg(db_, path_, "DELETE FROM record_segments WHERE id = ?1");
    seg.Bind(1, segment_id);
    st = seg.Run();
  }
  if (st.ok()) st = Exec("COMMIT");
  if (!st.ok()) sqlite3_exec(db_, "ROLLBACK", nullptr, nullptr, nullptr);
  return st;
}

absl::Status RecordIndex::DeleteMetadataBefore(int64_t before_ns) {
  Stmt sweeps(db_, path_, "DELETE FROM record_sweeps WHERE capture_server_ns < ?1");
  sweeps.Bind(1, before_ns);
  if (absl::Status s = sweeps.Run(); !s.ok()) return s;
  Stmt objects(db_, path_, "DELETE FROM record_objects WHERE t_ns < ?1");
  objects.Bind(1, before_ns);
  return objects.Run();
}

absl::Status RecordIndex::CloseOpenSegments() { return Exec("UPDATE record_segments SET closed = 1 WHERE closed = 0"); }

absl::StatusOr<std::vector<FrameRow>> RecordIndex::Frames(const std::vector<std::string>& sensor_ids, int64_t from_ns,
                                                          int64_t to_ns, int64_t limit) {
  Stmt s(db_, path_,
         absl::StrCat("SELECT ", kFrameColumns,
                      " FROM record_frames f JOIN record_segments g ON g.id = f.segment_id "
                      "WHERE f.capture_server_ns >= ?1 AND f.capture_server_ns < ?2 AND ",
                      SensorFilter("f.sensor_id", sensor_ids.size(), 4),
                      " ORDER BY f.capture_server_ns, f.sensor_id, f.sequence LIMIT ?3"));
  s.Bind(1, from_ns);
  s.Bind(2, to_ns);
  s.Bind(3, limit);
  for (size_t i = 0; i < sensor_ids.size(); ++i) s.Bind(4 + static_cast<int>(i), sensor_ids[i]);
  std::vector<FrameRow> out;
  while (s.Step()) out.push_back(ReadFrame(s));
  if (!s.status().ok()) return s.status();
  return out;
}

absl::StatusOr<std::vector<SweepRow>> RecordIndex::Sweeps(const std::vector<std::string>& sensor_ids, int64_t from_ns,
                                                          int64_t to_ns, int64_t limit) {
  Stmt s(db_, path_,
         absl::StrCat("SELECT sensor_id, sequence, capture_server_ns, received_ns, meta FROM record_sweeps "
                      "WHERE capture_server_ns >= ?1 AND capture_server_ns < ?2 AND ",
                      SensorFilter("sensor_id", sensor_ids.size(), 4),
                      " ORDER BY capture_server_ns, sensor_id, sequence LIMIT ?3"));
  s.Bind(1, from_ns);
  s.Bind(2, to_ns);
  s.Bind(3, limit);
  for (size_t i = 0; i < sensor_ids.size(); ++i) s.Bind(4 + static_cast<int>(i), sensor_ids[i]);
  std::vector<SweepRow> out;
  while (s.Step()) out.push_back({s.Text(0), static_cast<uint64_t>(s.Int(1)), s.Int(2), s.Int(3), s.BlobAt(4)});
  if (!s.status().ok()) return s.status();
  return out;
}

absl::StatusOr<std::vector<FrameRow>> RecordIndex::LatestBefore(const std::vector<std::string>& sensor_ids,
                                                                int64_t before_ns) {
  // One indexed probe per sensor (record_frames_sensor_time): the seek cost does not grow with
  // the recording's length.
  std::vector<std::string> ids = sensor_ids;
  if (ids.empty()) {
    Stmt all(db_, path_, "SELECT DISTINCT sensor_id FROM record_segments ORDER BY sensor_id");
    while (all.Step()) ids.push_back(all.Text(0));
    if (!all.status().ok()) return all.status();
  }
  std::vector<FrameRow> out;
  Stmt s(db_, path_,
         absl::StrCat("SELECT ", kFrameColumns,
                      " FROM record_frames f JOIN record_segments g ON g.id = f.segment_id "
                      "WHERE f.sensor_id = ?1 AND f.capture_server_ns < ?2 ORDER BY f.capture_server_ns DESC LIMIT 1"));
  for (const std::string& id : ids) {
    s.Bind(1, id);
    s.Bind(2, before_ns);
    if (s.Step()) out.push_back(ReadFrame(s));
    if (absl::Status st = s.Run(); !st.ok()) return st;
  }
  return out;
}

absl::StatusOr<std::vector<RecordedSpan>> RecordIndex::Spans() {
  Stmt s(db_, path_,
         "SELECT sensor_id, min(capture_server_ns), max(capture_server_ns), count(*) FROM record_frames "
         "GROUP BY sensor_id ORDER BY sensor_id");
  std::vector<RecordedSpan> out;
  while (s.Step()) out.push_back({s.Text(0), s.Int(1), s.Int(2), s.Int(3)});
  if (!s.status().ok()) return s.status();
  return out;
}

absl::StatusOr<std::vector<std::pair<std::string, std::string>>> RecordIndex::Sensors() {
  Stmt s(db_, path_, "SELECT sensor_id, camera FROM record_sensors ORDER BY sensor_id");
  std::vector<std::pair<std::string, std::string>> out;
  while (s.Step()) out.emplace_back(s.Text(0), s.BlobAt(1));
  if (!s.status().ok()) return s.status();
  return out;
}

absl::StatusOr<std::string> RecordIndex::IntegrityCheck() {
  Stmt s(db_, path_, "PRAGMA integrity_check");
  std::string out;
  while (s.Step()) absl::StrAppend(&out, out.empty() ? "" : "; ", s.Text(0));
  if (!s.status().ok()) return s.status();
  return out;
}

}  // namespace ave::record
