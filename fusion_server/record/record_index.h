#pragma once
// The recording index (issue 18): rows in the model store's SQLite file (schema v5, see the
// migration list in model_store/db/store.cc) that say where each recorded JPEG lies in the segment
// files. A second connection to the store file (WAL: readers never block the writer), so the
// recorder's batches do not queue behind registry calls on the Store's mutex.
//
// Times are server-clock nanoseconds (system_clock since the Unix epoch).
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

struct sqlite3;
struct sqlite3_stmt;

namespace ave::record {

struct SegmentRow {
  int64_t id = 0;  // 0 until first committed
  std::string sensor_id;
  std::string path;  // relative to the recording directory: "<sensor>/<start_ns>.seg"
  int64_t start_ns = 0, end_ns = 0;
  int64_t bytes = 0;  // committed (indexed, fdatasync'd) bytes: the file may hold more after a crash
  bool closed = false;
};

struct FrameRow {
  int64_t segment_id = 0;
  std::string segment_path;  // filled by queries
  std::string sensor_id;
  uint64_t sequence = 0;
  int64_t capture_server_ns = 0, received_ns = 0;
  int64_t offset = 0, length = 0;
  std::string meta;  // serialized ave.v1.SensorFrame without its JPEG
};

struct SweepRow {
  std::string sensor_id;
  uint64_t sequence = 0;
  int64_t capture_server_ns = 0, received_ns = 0;
  std::string meta;  // serialized ave.v1.LidarSweepFrame without its points
};

struct ObjectsRow {
  int64_t t_ns = 0;
  std::string objects;  // serialized ave.v1.SceneUpdate holding only objects
};

// One commit: segments created or grown, and the rows whose bytes they now hold.
struct IndexBatch {
  std::vector<SegmentRow*> segments;  // id == 0: inserted (id set on success); else updated
  std::vector<FrameRow> frames;       // segment_id 0: the segment in `segments` with the same path
  std::vector<SweepRow> sweeps;
  std::vector<ObjectsRow> objects;
  std::vector<std::pair<std::string, std::string>> sensors;  // (id, serialized ave.v1.Camera)
};

struct RecordedSpan {
  std::string sensor_id;
  int64_t first_ns = 0, last_ns = 0;
  int64_t frames = 0;
};

// A sensor's recorded time, as intervals (the viewer's time line).
struct RecordedIntervals {
  std::string sensor_id;
  std::vector<std::pair<int64_t, int64_t>> intervals;  // [first, last] capture ns, oldest first, disjoint
};

// Merges segment rows (any order) into each sensor's intervals: segments of one sensor that
// overlap or lie at most `merge_gap_ns` apart are one interval. Sensors by id; only those in
// `sensor_ids` (all when empty). Empty segments (end_ns < start_ns) are skipped.
std::vector<RecordedIntervals> MergeSegmentIntervals(std::vector<SegmentRow> segments,
                                                     const std::vector<std::string>& sensor_ids, int64_t merge_gap_ns);

class RecordIndex {
 public:
  // Opens the store file written by store::Store (already migrated to schema >= 5).
  static absl::StatusOr<std::unique_ptr<RecordIndex>> Open(const std::string& store_path);
  ~RecordIndex();
  RecordIndex(const RecordIndex&) = delete;
  RecordIndex& operator=(const RecordIndex&) = delete;

  // Everything in one transaction.
  absl::Status Commit(IndexBatch& batch);
  absl::StatusOr<std::vector<SegmentRow>> Segments();  // oldest start first
  // Deletes a segment's row and its frames (one transaction); the caller unlinks the file after.
  absl::Status DeleteSegment(int64_t segment_id);
  // Deletes sweeps and object rows older than `before_ns`.
  absl::Status DeleteMetadataBefore(int64_t before_ns);
  absl::Status CloseOpenSegments();  // marks every segment closed (a restart ends them)

  // Frames of `sensor_ids` (all when empty) with from_ns <= capture_server_ns < to_ns, in server
  // capture order (ties by sensor, then sequence); at most `limit` rows.
  absl::StatusOr<std::vector<FrameRow>> Frames(const std::vector<std::string>& sensor_ids, int64_t from_ns,
                                               int64_t to_ns, int64_t limit);
  absl::StatusOr<std::vector<SweepRow>> Sweeps(const std::vector<std::string>& sensor_ids, int64_t from_ns,
                                               int64_t to_ns, int64_t limit);
  // The newest frame row per sensor with capture_server_ns < before_ns (the seek target's image).
  absl::StatusOr<std::vector<FrameRow>> LatestBefore(const std::vector<std::string>& sensor_ids, int64_t before_ns);
  absl::StatusOr<std::vector<RecordedSpan>> Spans();
  absl::StatusOr<std::vector<std::pair<std::string, std::string>>> Sensors();  // (id, ave.v1.Camera bytes)
  absl::StatusOr<std::string> IntegrityCheck();  // "ok" when clean
  const std::string& path() const { return path_; }

 private:
  RecordIndex(sqlite3* db, std::string path) : db_(db), path_(std::move(path)) {}
  absl::Status Exec(const char* sql);
  absl::Status Error(const std::string& what) const;
  // The commit's statements, prepared once (not per commit); nullptr when preparing fails.
  sqlite3_stmt* Cached(const char* sql);
  sqlite3* db_;
  std::string path_;
  std::map<std::string, sqlite3_stmt*> cached_;
};

}  // namespace ave::record
