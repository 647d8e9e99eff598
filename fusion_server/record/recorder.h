#pragma once
// The server's recorder (issue 18): every accepted camera frame's JPEG, exactly as received, is
// appended to a per-sensor segment file `<dir>/<sensor>/<start_ns>.seg`; its place (segment,
// offset, length), capture time on the server clock, pose + covariance and boxes go to the index
// in the model store (record_index.h). LiDAR sweeps (tracks, no points) and the fused objects (at
// a bounded rate) go to the index only.
//
// Off the ingest path: Submit* only moves a shared pointer into a bounded queue and returns; a
// writer thread does the I/O. A full queue drops the frame (counted), so a slow disk never slows
// sensors or live viewers.
//
// Crash order: each batch (about every flush_period) is written, made durable (one syncfs of the
// recording's filesystem, or an fdatasync per segment: SyncMethod), and only then its rows are
// committed in one transaction, so a row never points at bytes that are not on disk.
// Open() truncates each segment back to its last indexed byte and removes segment files the
// index does not know (written after the last commit).
//
// Retention: segments whose newest frame is older than max_age, then the oldest closed segments
// while the recording exceeds max_bytes, are deleted (rows first, then the file). Full disk
// (ENOSPC/EFBIG on write or sync, or max_bytes reached with nothing closed left to delete):
// recording stops cleanly (one log line, ave_record_disk_full 1), frames are counted as skipped,
// live serving goes on; every flush period the writer runs retention and tries again, and
// recording resumes (one log line) as soon as a write fits.
#include <sys/types.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "ave/v1/ave.pb.h"
#include "fusion_server/record/record_index.h"

namespace ave::record {

struct RecorderOptions {
  std::string dir;                                   // recording directory (created if missing)
  std::chrono::seconds max_age{0};                   // retention by age; 0 = keep
  int64_t max_bytes = 0;                             // segment bytes budget; 0 = the disk's size
  int64_t segment_max_bytes = 64 << 20;              // roll a segment past this size
  std::chrono::seconds segment_max_duration{60};     // or when its first frame is this old
  size_t queue_max_items = 4096;                     // bounded queue: frames/sweeps waiting for the writer
  int64_t queue_max_bytes = 256 << 20;               // and their JPEG bytes
  // Write + sync + one commit per period (`ave-server --record-sync-ms`). What a crash may lose:
  // the frames received since the last commit, at most this period plus one flush's duration;
  // nothing acknowledged as recorded (SensorAck.recorded_sequence) is ever lost.
  std::chrono::milliseconds flush_period{500};
  // How a flush makes its segments' bytes durable before their rows are committed:
  // kFilesystem: one syncfs(2) of the recording's filesystem when two or more segments on it have
  // new bytes (the kernel's flusher writes them back, one device cache flush for all), else
  // fdatasync; kPerFile: one fdatasync per segment with new bytes (50 cameras: 50 writebacks, 50
  // inode writes and 50 cache flushes per flush). kFilesystem also waits for whatever else is
  // dirty on that filesystem: on a disk shared with heavy writers, kPerFile bounds the flush time.
  enum class SyncMethod { kFilesystem, kPerFile };
  SyncMethod sync_method = SyncMethod::kFilesystem;
  // ave-server's default (off with `--record-buffered-io`; this struct's default stays off): write
  // each segment's batch with O_DIRECT from a page-aligned buffer (the batch's frames copied into
  // it; the partial block at the segment's end rewritten with the next batch), past the page cache: no page-cache pages, buffer heads or delayed block
  // allocation per 4 KB in the writer, no dirty pages for the kernel's flusher to write back. The
  // sync and commit order is the same (the sync still writes the inode and flushes the device
  // cache). Replay then reads recent frames from the disk, not from memory. A filesystem that
  // refuses O_DIRECT (EINVAL, or an aligned write refused) gets buffered writes, with one log line;
  // another failed O_DIRECT open (out of descriptors) costs only that segment its direct writes.
  // Each open segment then holds a second descriptor (the O_DIRECT one).
  bool direct_io = false;
  std::chrono::milliseconds objects_period{500};     // fused objects recorded at most this often
  // The fused objects now (a SceneUpdate holding only objects, server time in server_time_ns);
  // called on the writer thread once per objects_period. Empty: objects are not recorded.
  std::function<v1::SceneUpdate()> objects_source;
  // Wall clock in ns (tests inject one for retention by age); empty = system_clock.
  std::function<int64_t()> clock_ns;

  std::string Check() const;  // empty when usable, else names the field
};

struct RecorderStats {
  uint64_t frames_recorded = 0, bytes_recorded = 0, sweeps_recorded = 0, objects_recorded = 0;
  uint64_t queue_drops = 0;       // queue full: the writer is behind
  uint64_t disk_full_skips = 0;   // not recorded while the disk (or budget) was full
  uint64_t disk_full_events = 0;  // times recording stopped for a full disk
  uint64_t write_errors = 0;      // other I/O errors (frame skipped)
  uint64_t segments_deleted = 0;
  uint64_t commits = 0;
  uint64_t syncs = 0;  // syncfs or fdatasync calls made to commit segment bytes
  uint64_t direct_writes = 0;  // O_DIRECT writes of segment batches (RecorderOptions::direct_io)
  int64_t queue_items = 0;
  int64_t bytes_on_disk = 0;  // committed segment bytes
  bool disk_full = false;
};

class Recorder {
 public:
  // `store_path`: the model store file (already migrated by store::Store::Open). Repairs segment
  // tails and orphans (see above), then starts the writer thread.
  static absl::StatusOr<std::unique_ptr<Recorder>> Open(const std::string& store_path, RecorderOptions options);
  ~Recorder();  // writes and commits what is queued, then stops

  // Non-blocking. `capture_server_ns` is the frame's capture time on the server clock.
  void SubmitFrame(const std::string& sensor_id, std::shared_ptr<const v1::SensorFrame> frame, int64_t received_ns,
                   int64_t capture_server_ns);
  void SubmitSweep(const std::string& sensor_id, std::shared_ptr<const v1::LidarSweepFrame> sweep, int64_t received_ns,
                   int64_t capture_server_ns);
  // The sensor's registry entry (serialized ave.v1.Camera), kept so that it replays after removal.
  void NoteSensor(const std::string& sensor_id, std::string camera_bytes);

  // The sequence of the newest frame or sweep of `sensor_id` received at or after
  // `since_received_ns` whose bytes and index row are committed (written, fdatasync'd, then one
  // transaction); 0 when none. Acks carry it (SensorAck.recorded_sequence).
  uint64_t RecordedSequence(const std::string& sensor_id, int64_t since_received_ns) const;

  // Blocks until everything submitted before the call is written and committed (or skipped).
  void Drain();
  RecorderStats Stats() const;
  // ave_record_* lines in Prometheus text.
  void RenderPrometheus(std::string& out) const;
  const RecorderOptions& options() const { return options_; }

 private:
  struct Item {
    std::string sensor_id;
    std::shared_ptr<const v1::SensorFrame> frame;
    std::shared_ptr<const v1::LidarSweepFrame> sweep;
    int64_t received_ns = 0, capture_server_ns = 0;
  };
  struct OpenSegment {
    SegmentRow row;
    int fd = -1;
    int64_t written = 0;  // bytes in the file or pending for it (row.bytes: committed)
    bool dirty = false;
    // Frames placed in this segment (offsets from pending_from) but not yet written: one pwritev
    // per segment per flush instead of one pwrite per frame. `hold` keeps their JPEGs alive.
    int64_t pending_from = 0;
    int64_t pending_bytes = 0;
    // Bytes reserved by fallocate (FALLOC_FL_KEEP_SIZE: the file's size stays what is written), a
    // few MB at a time, so that ext4 allocates blocks once per reservation, not at every flush's
    // writeback. What is left over is released when the segment's descriptor closes (CloseFd) or,
    // after a crash, by Open's repair.
    int64_t allocated = 0;
    bool same_fs = false;  // on the record dir's filesystem: one syncfs covers it
    // direct_io: a second descriptor with O_DIRECT, and the bytes of the partial block at the end
    // of the last direct write (from tail_from), which the next batch's aligned write repeats.
    int direct_fd = -1;
    int64_t tail_from = -1;
    std::string tail;
    std::vector<std::shared_ptr<const v1::SensorFrame>> hold;
  };
  Recorder(RecorderOptions options, std::unique_ptr<RecordIndex> index);
  absl::Status Repair();
  void Loop();
  void WriteItem(Item& item);
  void FlushBatch();
  // Makes the new bytes of the dirty segments durable (SyncMethod); on failure drops their
  // batch's rows and bytes (a full disk stops recording).
  void SyncSegments();
  void SyncFailed(OpenSegment& seg, int err);
  // Writes a segment's pending frames (WriteItem places them); on failure truncates back and drops
  // their rows from the batch (counted as skipped for a full disk, else as write errors).
  void WritePending(OpenSegment& seg);
  // direct_io: the pending frames in one aligned O_DIRECT write; false when it could not be tried
  // (the caller writes them buffered), else *err is the write's errno (0: written).
  bool WritePendingDirect(OpenSegment& seg, int* err);
  void CloseFd(OpenSegment& seg);  // releases the unused reservation, then closes
  // mu_ held: the queue holds enough to wake the writer before its flush time.
  bool WakeDue() const {
    return queue_bytes_ >= std::min<int64_t>(kWakeBytes, options_.queue_max_bytes / 4) ||
           queue_.size() >= std::max<size_t>(1, options_.queue_max_items / 4);
  }
  static constexpr int64_t kWakeBytes = 4 << 20;
  static constexpr int64_t kPendingMaxBytes = 1 << 20;  // per segment, then written at once
  static constexpr size_t kMaxIov = 256;
  static constexpr int64_t kReserveBytes = 4 << 20;  // fallocate step
  static constexpr int64_t kDirectAlign = 4096;     // O_DIRECT offset, length and buffer alignment
  // Deletes segments past max_age, then the oldest closed ones while the recording plus
  // `need_bytes` exceeds max_bytes.
  void RunRetention(int64_t need_bytes = 0);
  bool EnsureRoom(int64_t bytes);  // false: budget full
  OpenSegment* SegmentFor(const std::string& sensor_id, int64_t capture_server_ns, int64_t bytes);
  void CloseSegment(OpenSegment& seg);
  void SetDiskFull(bool full, const std::string& why);
  int64_t NowNs() const;

  const RecorderOptions options_;
  std::unique_ptr<RecordIndex> index_;

  mutable std::mutex mu_;
  std::condition_variable wake_, drained_;
  std::deque<Item> queue_;
  int64_t queue_bytes_ = 0;
  std::vector<std::pair<std::string, std::string>> sensors_pending_;
  uint64_t submitted_ = 0, written_ = 0, done_ = 0;  // items; done_: written and committed
  uint64_t flushes_ = 0;
  // By sensor: (sequence, received_ns) of the newest frame or sweep committed.
  std::map<std::string, std::pair<uint64_t, int64_t>> recorded_sequence_;
  int drain_waiters_ = 0;
  bool stop_ = false;

  // Writer thread only.
  std::map<std::string, OpenSegment> open_;  // by sensor
  IndexBatch batch_;
  std::vector<SegmentRow> closed_pending_;  // closed since the last commit (their final rows)
  int64_t last_objects_ns_ = 0;
  bool reserve_ = true;  // false once fallocate says the filesystem cannot
  int dir_fd_ = -1;      // the record dir, for syncfs
  dev_t dir_dev_ = 0;
  bool syncfs_ok_ = true;  // false once syncfs says the kernel cannot
  bool direct_ok_ = true;  // false once the filesystem refused O_DIRECT
  char* direct_buf_ = nullptr;  // page-aligned staging buffer for direct writes
  size_t direct_cap_ = 0;
  bool probe_ = false;  // while full: the next frame may try to write (set once per flush)
  int64_t last_retention_ns_ = 0;

  std::atomic<uint64_t> frames_recorded_{0}, bytes_recorded_{0}, sweeps_recorded_{0}, objects_recorded_{0};
  std::atomic<uint64_t> queue_drops_{0}, disk_full_skips_{0}, disk_full_events_{0}, write_errors_{0};
  std::atomic<uint64_t> segments_deleted_{0}, commits_{0}, syncs_{0}, direct_writes_{0};
  std::atomic<int64_t> bytes_on_disk_{0};
  std::atomic<bool> disk_full_{false};
  std::thread thread_;
};

// What the index keeps of a frame (FrameRow.meta): the serialized ave.v1.SensorFrame without its
// JPEG (capture time, sequence, pose, boxes, clock offset). Written field by field from the
// received message, the same bytes as serializing a copy of those fields, without the copy.
std::string FrameMetaBytes(const v1::SensorFrame& frame);

// The server's wall clock (system_clock) in ns: the clock recorded times are on.
int64_t WallNowNs();

// Reads `length` bytes at `offset` of `<dir>/<segment_path>`: NotFound when the file is gone,
// DataLoss when it is shorter than the index says.
absl::StatusOr<std::string> ReadSegmentBytes(const std::string& dir, const std::string& segment_path, int64_t offset,
                                             int64_t length);

}  // namespace ave::record
