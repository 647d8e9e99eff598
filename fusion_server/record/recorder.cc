#include "fusion_server/record/recorder.h"

#include <fcntl.h>
#include <pthread.h>
#include <sys/stat.h>
#include <sys/uio.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <climits>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <set>

#include "absl/strings/str_cat.h"
#include "model_store/common/log.h"

namespace ave::record {
namespace fs = std::filesystem;
namespace {

bool IsNoSpace(int err) { return err == ENOSPC || err == EFBIG || err == EDQUOT; }

// Writes all of `bytes` at `offset`; on failure returns errno (the caller truncates back).
int WriteAll(int fd, const std::string& bytes, int64_t offset) {
  size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::pwrite(fd, bytes.data() + done, bytes.size() - done, offset + static_cast<int64_t>(done));
    if (n < 0) {
      if (errno == EINTR) continue;
      return errno;
    }
    if (n == 0) return EIO;
    done += static_cast<size_t>(n);
  }
  return 0;
}

// Writes all of `iov` (in order) at `offset`, as few pwritev calls as the kernel allows; on
// failure returns errno (the caller truncates back).
int WriteAllV(int fd, std::vector<iovec>& iov, int64_t offset) {
  size_t first = 0;
  while (first < iov.size()) {
    const int count = static_cast<int>(std::min<size_t>(iov.size() - first, IOV_MAX));
    const ssize_t n = ::pwritev(fd, iov.data() + first, count, offset);
    if (n < 0) {
      if (errno == EINTR) continue;
      return errno;
    }
    if (n == 0) return EIO;
    offset += n;
    for (size_t left = static_cast<size_t>(n); left > 0 && first < iov.size();) {  // skip what was written
      if (left >= iov[first].iov_len) {
        left -= iov[first].iov_len;
        ++first;
      } else {
        iov[first].iov_base = static_cast<char*>(iov[first].iov_base) + left;
        iov[first].iov_len -= left;
        left = 0;
      }
    }
    while (first < iov.size() && iov[first].iov_len == 0) ++first;
  }
  return 0;
}

void SyncDir(const fs::path& dir) {
  const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY);
  if (fd >= 0) {
    ::fsync(fd);
    ::close(fd);
  }
}

}  // namespace

std::string RecorderOptions::Check() const {
  if (dir.empty()) return "record dir: must be set";
  if (max_age.count() < 0) return "retention: must be >= 0 s";
  if (max_bytes < 0) return "record max bytes: must be >= 0";
  if (segment_max_bytes < 1024) return "segment_max_bytes: must be at least 1024";
  if (segment_max_duration.count() <= 0) return "segment_max_duration: must be > 0 s";
  if (queue_max_items == 0 || queue_max_bytes <= 0) return "queue: bounds must be > 0";
  if (flush_period.count() <= 0 || flush_period.count() > 60'000) {
    return "flush_period (--record-sync-ms): must be 1..60000 ms";
  }
  return "";
}

namespace {

size_t VarintSize(uint64_t v) {
  size_t n = 1;
  for (; v >= 0x80; v >>= 7) ++n;
  return n;
}

uint8_t* PutVarint(uint8_t* p, uint64_t v) {
  for (; v >= 0x80; v >>= 7) *p++ = static_cast<uint8_t>(v | 0x80);
  *p++ = static_cast<uint8_t>(v);
  return p;
}

// A length-delimited field (wire type 2) holding `m`, whose size ByteSizeLong has just cached.
uint8_t* PutMessage(uint8_t* p, uint32_t field, const google::protobuf::MessageLite& m) {
  p = PutVarint(p, (field << 3) | 2);
  p = PutVarint(p, static_cast<uint64_t>(m.GetCachedSize()));
  return m.SerializeWithCachedSizesToArray(p);
}

}  // namespace

std::string FrameMetaBytes(const v1::SensorFrame& frame) {
  // The fields in number order (1 capture time, 2 sequence, 3 pose, 4 boxes, 7 clock offset), as
  // SerializeToString of such a copy writes them (proto3: zero scalars left out). Each
  // sub-message's size is computed once (ByteSizeLong caches it for the serialization that
  // follows) and the string is allocated once.
  const uint64_t capture = static_cast<uint64_t>(frame.capture_time_ns());
  const uint64_t sequence = frame.sequence();
  const uint64_t offset = static_cast<uint64_t>(frame.clock_offset_ns());
  size_t total = 0;
  if (capture != 0) total += 1 + VarintSize(capture);
  if (sequence != 0) total += 1 + VarintSize(sequence);
  if (frame.has_pose()) {
    const size_t n = frame.pose().ByteSizeLong();
    total += 1 + VarintSize(n) + n;
  }
  for (const v1::DetectedBox& box : frame.boxes()) {
    const size_t n = box.ByteSizeLong();
    total += 1 + VarintSize(n) + n;
  }
  if (offset != 0) total += 1 + VarintSize(offset);
  std::string out(total, '\0');
  uint8_t* p = reinterpret_cast<uint8_t*>(out.data());
  if (capture != 0) p = PutVarint(PutVarint(p, (v1::SensorFrame::kCaptureTimeNsFieldNumber << 3) | 0), capture);
  if (sequence != 0) p = PutVarint(PutVarint(p, (v1::SensorFrame::kSequenceFieldNumber << 3) | 0), sequence);
  if (frame.has_pose()) p = PutMessage(p, v1::SensorFrame::kPoseFieldNumber, frame.pose());
  for (const v1::DetectedBox& box : frame.boxes()) p = PutMessage(p, v1::SensorFrame::kBoxesFieldNumber, box);
  if (offset != 0) p = PutVarint(PutVarint(p, (v1::SensorFrame::kClockOffsetNsFieldNumber << 3) | 0), offset);
  out.resize(static_cast<size_t>(p - reinterpret_cast<uint8_t*>(out.data())));  // == total
  return out;
}

int64_t WallNowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

absl::StatusOr<std::string> ReadSegmentBytes(const std::string& dir, const std::string& segment_path, int64_t offset,
                                             int64_t length) {
  const fs::path path = fs::path(dir) / segment_path;
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) {
    if (errno == ENOENT) return absl::NotFoundError(absl::StrCat("segment '", path.string(), "' is missing"));
    return absl::UnavailableError(absl::StrCat("segment '", path.string(), "': ", std::strerror(errno)));
  }
  std::string bytes(static_cast<size_t>(length), '\0');
  size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::pread(fd, bytes.data() + done, bytes.size() - done, offset + static_cast<int64_t>(done));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) break;
    done += static_cast<size_t>(n);
  }
  ::close(fd);
  if (done != bytes.size()) {
    return absl::DataLossError(absl::StrCat("segment '", path.string(), "': ", length, " bytes at offset ", offset,
                                            " indexed, only ", done, " there"));
  }
  return bytes;
}

Recorder::Recorder(RecorderOptions options, std::unique_ptr<RecordIndex> index)
    : options_(std::move(options)), index_(std::move(index)) {}

absl::StatusOr<std::unique_ptr<Recorder>> Recorder::Open(const std::string& store_path, RecorderOptions options) {
  if (std::string why = options.Check(); !why.empty()) return absl::InvalidArgumentError("recorder: " + why);
  std::error_code ec;
  fs::create_directories(options.dir, ec);
  if (ec) return absl::UnavailableError(absl::StrCat("record dir '", options.dir, "': ", ec.message()));
  auto index = RecordIndex::Open(store_path);
  if (!index.ok()) return index.status();
  std::unique_ptr<Recorder> recorder(new Recorder(std::move(options), *std::move(index)));
  if (absl::Status s = recorder->Repair(); !s.ok()) return s;
  recorder->dir_fd_ = ::open(recorder->options_.dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  struct stat dir_stat {};
  if (recorder->dir_fd_ < 0 || ::fstat(recorder->dir_fd_, &dir_stat) != 0) {
    return absl::UnavailableError(absl::StrCat("record dir '", recorder->options_.dir, "': ", std::strerror(errno)));
  }
  recorder->dir_dev_ = dir_stat.st_dev;
  recorder->thread_ = std::thread([r = recorder.get()] { r->Loop(); });
  // Named, so that top -H, perf and ave-bench record can tell its CPU from the rest of the server's.
  pthread_setname_np(recorder->thread_.native_handle(), "ave-recorder");
  return recorder;
}

Recorder::~Recorder() {
  {
    std::lock_guard lock(mu_);
    stop_ = true;
  }
  wake_.notify_all();
  if (thread_.joinable()) thread_.join();
  if (dir_fd_ >= 0) ::close(dir_fd_);
  std::free(direct_buf_);
}

int64_t Recorder::NowNs() const {
  if (options_.clock_ns) return options_.clock_ns();
  return WallNowNs();
}

absl::Status Recorder::Repair() {
  auto segments = index_->Segments();
  if (!segments.ok()) return segments.status();
  std::set<fs::path> known;
  int64_t total = 0;
  int truncated = 0;
  for (const SegmentRow& seg : *segments) {
    const fs::path path = fs::path(options_.dir) / seg.path;
    known.insert(path.lexically_normal());
    total += seg.bytes;
    std::error_code ec;
    const auto size = fs::file_size(path, ec);
    if (ec) continue;  // gone: replay reports the gap
    // Bytes written after the last commit (a crash between write and commit): no row names them.
    // A segment still open at the crash is cut at its indexed end even when no byte lies past it:
    // that frees the blocks fallocate reserved past the end.
    if (static_cast<int64_t>(size) > seg.bytes || !seg.closed) {
      if (::truncate(path.c_str(), seg.bytes) != 0) {
        return absl::UnavailableError(absl::StrCat("segment '", path.string(), "': cannot truncate to its indexed ",
                                                   seg.bytes, " bytes: ", std::strerror(errno)));
      }
      if (static_cast<int64_t>(size) > seg.bytes) ++truncated;
    }
  }
  int orphans = 0;
  std::error_code ec;
  for (auto it = fs::recursive_directory_iterator(options_.dir, ec); !ec && it != fs::recursive_directory_iterator();
       it.increment(ec)) {
    if (!it->is_regular_file() || it->path().extension() != ".seg") continue;
    if (known.count(it->path().lexically_normal())) continue;
    std::error_code rm;
    if (fs::remove(it->path(), rm)) ++orphans;  // created after the last commit: nothing indexes it
  }
  if (absl::Status s = index_->CloseOpenSegments(); !s.ok()) return s;
  bytes_on_disk_ = total;
  AVE_LOG(INFO) << "recording to '" << options_.dir << "': " << segments->size() << " segments (" << total
                << " bytes) indexed, " << truncated << " tails truncated, " << orphans << " unindexed files removed";
  return absl::OkStatus();
}

void Recorder::SubmitFrame(const std::string& sensor_id, std::shared_ptr<const v1::SensorFrame> frame,
                           int64_t received_ns, int64_t capture_server_ns) {
  if (frame->metadata_only() || frame->jpeg().empty()) return;  // no image: nothing to replay
  const int64_t bytes = static_cast<int64_t>(frame->jpeg().size());
  {
    std::lock_guard lock(mu_);
    if (stop_ || queue_.size() >= options_.queue_max_items || queue_bytes_ + bytes > options_.queue_max_bytes) {
      queue_drops_.fetch_add(1, std::memory_order_relaxed);
      return;
    }
    const bool was_due = WakeDue();
    queue_bytes_ += bytes;
    queue_.push_back({sensor_id, std::move(frame), nullptr, received_ns, capture_server_ns});
    ++submitted_;
    if (was_due || !WakeDue()) return;  // the writer wakes at its flush time
  }
  wake_.notify_one();  // the queue just reached a wake-up's worth
}

void Recorder::SubmitSweep(const std::string& sensor_id, std::shared_ptr<const v1::LidarSweepFrame> sweep,
                           int64_t received_ns, int64_t capture_server_ns) {
  {
    std::lock_guard lock(mu_);
    if (stop_ || queue_.size() >= options_.queue_max_items) {
      queue_drops_.fetch_add(1, std::memory_order_relaxed);
      return;
    }
    const bool was_due = WakeDue();
    queue_.push_back({sensor_id, nullptr, std::move(sweep), received_ns, capture_server_ns});
    ++submitted_;
    if (was_due || !WakeDue()) return;
  }
  wake_.notify_one();
}

void Recorder::NoteSensor(const std::string& sensor_id, std::string camera_bytes) {
  std::lock_guard lock(mu_);
  sensors_pending_.emplace_back(sensor_id, std::move(camera_bytes));
}

void Recorder::Drain() {
  std::unique_lock lock(mu_);
  const uint64_t target = submitted_;
  ++drain_waiters_;
  wake_.notify_all();
  // Two flushes after this call: the second began after it, so it saw everything submitted before.
  const uint64_t flush_target = flushes_ + 2;
  drained_.wait(lock, [&] { return done_ >= target && flushes_ >= flush_target; });
  --drain_waiters_;
}

void Recorder::Loop() {
  auto next_flush = std::chrono::steady_clock::now() + options_.flush_period;
  for (;;) {
    std::deque<Item> items;
    bool stopping = false, draining = false;
    {
      std::unique_lock lock(mu_);
      // Once per flush period, or sooner when the queue holds a wake-up's worth (WakeDue), a
      // drain is waiting or the recorder stops: not once per frame (a wake-up per frame cost the
      // ingest threads a futex call and the writer a context switch, 750 times a second at 50
      // cameras).
      wake_.wait_until(lock, next_flush, [&] { return stop_ || WakeDue() || drain_waiters_ > 0; });
      items.swap(queue_);
      queue_bytes_ = 0;
      stopping = stop_;
      draining = drain_waiters_ > 0;
      batch_.sensors.insert(batch_.sensors.end(), sensors_pending_.begin(), sensors_pending_.end());
      sensors_pending_.clear();
    }
    for (Item& item : items) WriteItem(item);
    const auto now = std::chrono::steady_clock::now();
    const bool flush = stopping || draining || now >= next_flush;
    if (flush) {
      FlushBatch();
      // Retention reads every segment row: every 10 s of the recorder's clock, or each flush
      // while recording is stopped for a full disk (it may free room and lets a frame try again).
      const int64_t now_ns = NowNs();
      if (disk_full_.load() || now_ns - last_retention_ns_ >= 10'000'000'000) {
        last_retention_ns_ = now_ns;
        RunRetention();
      }
      next_flush = now + options_.flush_period;
    }
    {
      std::lock_guard lock(mu_);
      written_ += items.size();
      if (flush) {
        done_ = written_;
        ++flushes_;
      }
    }
    if (flush) drained_.notify_all();
    if (stopping) {
      std::lock_guard lock(mu_);
      if (queue_.empty()) break;
    }
  }
  for (auto& [id, seg] : open_) CloseSegment(seg);
  FlushBatch();
  for (auto& [id, seg] : open_) CloseFd(seg);
}

void Recorder::SetDiskFull(bool full, const std::string& why) {
  if (disk_full_.exchange(full) == full) return;
  if (full) {
    disk_full_events_.fetch_add(1, std::memory_order_relaxed);
    AVE_LOG(ERROR) << "recording stopped: " << why << " (live serving continues; retrying every "
                   << options_.flush_period.count() << " ms)";
  } else {
    AVE_LOG(INFO) << "recording resumed: " << why;
  }
}

void Recorder::CloseSegment(OpenSegment& seg) {
  if (seg.row.closed) return;
  seg.row.closed = true;
  seg.dirty = true;  // the next commit stores closed = 1
}

bool Recorder::EnsureRoom(int64_t bytes) {
  if (options_.max_bytes <= 0) return true;
  auto total = [&] {
    int64_t t = bytes_on_disk_.load();
    for (const auto& [id, seg] : open_) t += seg.written - seg.row.bytes;
    return t;
  };
  if (total() + bytes <= options_.max_bytes) return true;
  RunRetention(bytes);
  if (total() + bytes <= options_.max_bytes) return true;
  // Nothing closed is left to delete: the open segments alone fill the budget. Stop; close them so
  // that the next retention pass may delete the oldest and recording can resume.
  SetDiskFull(true, absl::StrCat("recording budget of ", options_.max_bytes, " bytes (--record-max-bytes) is full"));
  for (auto& [id, seg] : open_) CloseSegment(seg);
  FlushBatch();
  for (auto& [id, seg] : open_) CloseFd(seg);
  open_.clear();
  return false;
}

Recorder::OpenSegment* Recorder::SegmentFor(const std::string& sensor_id, int64_t capture_server_ns, int64_t bytes) {
  auto it = open_.find(sensor_id);
  if (it != open_.end()) {
    OpenSegment& seg = it->second;
    const bool roll = seg.row.closed || seg.written + bytes > options_.segment_max_bytes ||
                      capture_server_ns - seg.row.start_ns >= std::chrono::nanoseconds(options_.segment_max_duration).count();
    if (!roll) return &seg;
    CloseSegment(seg);
    FlushBatch();  // sync and commit it (closed) before its descriptor goes
    CloseFd(seg);
    open_.erase(it);
  }
  const fs::path sensor_dir = fs::path(options_.dir) / sensor_id;
  std::error_code ec;
  const bool created_dir = fs::create_directories(sensor_dir, ec);
  if (ec) {
    if (IsNoSpace(ec.value())) SetDiskFull(true, absl::StrCat("cannot create '", sensor_dir.string(), "': ", ec.message()));
    else write_errors_.fetch_add(1, std::memory_order_relaxed);
    return nullptr;
  }
  if (created_dir) SyncDir(options_.dir);
  OpenSegment seg;
  seg.row.sensor_id = sensor_id;
  seg.row.start_ns = capture_server_ns;
  seg.row.end_ns = capture_server_ns;
  int64_t name_ns = capture_server_ns;
  for (;; ++name_ns) {  // unique even when a camera's clock repeats a start time
    seg.row.path = absl::StrCat(sensor_id, "/", name_ns, ".seg");
    // Direct writes read back the partial block at the end when they do not hold it: O_RDWR.
    seg.fd = ::open((fs::path(options_.dir) / seg.row.path).c_str(),
                    (options_.direct_io ? O_RDWR : O_WRONLY) | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
    if (seg.fd >= 0 || errno != EEXIST) break;
  }
  if (seg.fd < 0) {
    const int err = errno;
    if (IsNoSpace(err)) SetDiskFull(true, absl::StrCat("cannot create a segment in '", sensor_dir.string(), "': ", std::strerror(err)));
    else {
      write_errors_.fetch_add(1, std::memory_order_relaxed);
      AVE_LOG(ERROR) << "recording: cannot create a segment in '" << sensor_dir.string() << "': " << std::strerror(err);
    }
    return nullptr;
  }
  SyncDir(sensor_dir);  // the new name survives a power cut once its rows are committed
  struct stat seg_stat {};
  seg.same_fs = ::fstat(seg.fd, &seg_stat) == 0 && seg_stat.st_dev == dir_dev_;
  if (options_.direct_io && direct_ok_) {
    seg.direct_fd = ::open((fs::path(options_.dir) / seg.row.path).c_str(), O_WRONLY | O_DIRECT | O_CLOEXEC);
    if (seg.direct_fd < 0) {
      // EINVAL: the filesystem does not take O_DIRECT (every later segment would be refused too);
      // anything else (out of descriptors, say) costs this segment its direct writes only.
      const int err = errno;
      if (err == EINVAL) direct_ok_ = false;
      AVE_LOG(WARNING) << "recording: O_DIRECT refused for '" << seg.row.path << "' (" << std::strerror(err) << "), "
                       << (err == EINVAL ? "writing through the page cache" : "this segment through the page cache");
    }
  }
  return &open_.emplace(sensor_id, std::move(seg)).first->second;
}

void Recorder::WriteItem(Item& item) {
  if (item.sweep) {
    v1::LidarSweepFrame meta = *item.sweep;
    meta.clear_foreground();
    SweepRow row{item.sensor_id, item.sweep->sequence(), item.capture_server_ns, item.received_ns, ""};
    meta.SerializeToString(&row.meta);
    batch_.sweeps.push_back(std::move(row));
    return;
  }
  const v1::SensorFrame& frame = *item.frame;
  const int64_t length = static_cast<int64_t>(frame.jpeg().size());
  if (disk_full_.load() && !probe_) {
    disk_full_skips_.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  if (!EnsureRoom(length)) {
    disk_full_skips_.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  OpenSegment* seg = SegmentFor(item.sensor_id, item.capture_server_ns, length);
  if (!seg) {
    disk_full_skips_.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  // While recording is stopped for a full disk, the one probing frame is written at once (it
  // decides whether recording resumes); otherwise the frame is placed and written with the
  // segment's other pending frames in one pwritev (WritePending, at the latest before the fdatasync
  // that precedes its row's commit).
  if (!disk_full_.load()) {
    if (seg->pending_bytes == 0) seg->pending_from = seg->written;
    seg->hold.push_back(item.frame);
    seg->pending_bytes += length;
  } else {
    if (const int err = WriteAll(seg->fd, frame.jpeg(), seg->written); err != 0) {
      if (::ftruncate(seg->fd, seg->written) != 0) {
        AVE_LOG(ERROR) << "recording: cannot truncate '" << seg->row.path << "' after a failed write";
      }
      probe_ = false;
      if (IsNoSpace(err)) {
        SetDiskFull(true, absl::StrCat("disk full writing '", seg->row.path, "': ", std::strerror(err)));
        disk_full_skips_.fetch_add(1, std::memory_order_relaxed);
      } else {
        write_errors_.fetch_add(1, std::memory_order_relaxed);
        AVE_LOG(ERROR) << "recording: write to '" << seg->row.path << "' failed: " << std::strerror(err);
      }
      return;
    }
    SetDiskFull(false, "a frame fits again");
  }
  probe_ = false;
  FrameRow row;
  row.segment_id = seg->row.id;
  row.segment_path = seg->row.path;
  row.sensor_id = item.sensor_id;
  row.sequence = frame.sequence();
  row.capture_server_ns = item.capture_server_ns;
  row.received_ns = item.received_ns;
  row.offset = seg->written;
  row.length = length;
  row.meta = FrameMetaBytes(frame);
  batch_.frames.push_back(std::move(row));
  seg->written += length;
  seg->row.end_ns = std::max(seg->row.end_ns, item.capture_server_ns);
  seg->dirty = true;
  if (seg->pending_bytes >= kPendingMaxBytes || seg->hold.size() >= kMaxIov) WritePending(*seg);
}

void Recorder::WritePending(OpenSegment& seg) {
  if (seg.hold.empty()) return;
  std::vector<iovec> iov;
  iov.reserve(seg.hold.size());
  for (const auto& frame : seg.hold) {
    iov.push_back({const_cast<char*>(frame->jpeg().data()), frame->jpeg().size()});
  }
  const int64_t end = seg.pending_from + seg.pending_bytes;
  if (reserve_ && end > seg.allocated) {
    const int64_t want = std::max(end, std::min(options_.segment_max_bytes, seg.allocated + kReserveBytes));
    if (::fallocate(seg.fd, FALLOC_FL_KEEP_SIZE, seg.allocated, want - seg.allocated) != 0 &&
        (errno == EOPNOTSUPP || errno == ENOSYS)) {
      reserve_ = false;
    }
    // A failed reservation (a full disk) is not retried for these bytes: the write says whether they fit.
    seg.allocated = want;
  }
  int err = 0;
  if (seg.direct_fd < 0 || !WritePendingDirect(seg, &err)) err = WriteAllV(seg.fd, iov, seg.pending_from);
  const size_t frames = seg.hold.size();
  seg.hold.clear();
  seg.pending_bytes = 0;
  if (err == 0) return;
  // None of this batch's frames of the segment is kept: bytes cut back, rows dropped.
  if (::ftruncate(seg.fd, seg.pending_from) != 0) {
    AVE_LOG(ERROR) << "recording: cannot truncate '" << seg.row.path << "' after a failed write";
  }
  seg.written = seg.pending_from;
  const std::string& failed_path = seg.row.path;
  const int64_t from = seg.pending_from;
  std::erase_if(batch_.frames,
                [&failed_path, from](const FrameRow& f) { return f.segment_path == failed_path && f.offset >= from; });
  probe_ = false;
  if (IsNoSpace(err)) {
    SetDiskFull(true, absl::StrCat("disk full writing '", seg.row.path, "': ", std::strerror(err)));
    disk_full_skips_.fetch_add(frames, std::memory_order_relaxed);
  } else {
    write_errors_.fetch_add(frames, std::memory_order_relaxed);
    AVE_LOG(ERROR) << "recording: write to '" << seg.row.path << "' failed: " << std::strerror(err);
  }
}

bool Recorder::WritePendingDirect(OpenSegment& seg, int* err) {
  // [block_start, end) rounded up to whole blocks: the partial block before the batch (already
  // written: the same bytes again), the batch's frames, zeros after them (the next batch's bytes
  // replace them; the file's length past `written` is cut when the segment closes, or by Open's
  // repair after a crash, as for fallocate's reservation).
  const int64_t block_start = seg.pending_from / kDirectAlign * kDirectAlign;
  const int64_t end = seg.pending_from + seg.pending_bytes;
  const size_t head = static_cast<size_t>(seg.pending_from - block_start);
  const size_t length = static_cast<size_t>((end - block_start + kDirectAlign - 1) / kDirectAlign * kDirectAlign);
  if (length > direct_cap_) {
    void* buf = nullptr;
    if (::posix_memalign(&buf, kDirectAlign, length) != 0) return false;
    std::free(direct_buf_);
    direct_buf_ = static_cast<char*>(buf);
    direct_cap_ = length;
  }
  char* out = direct_buf_;
  if (head > 0) {
    if (seg.tail_from == block_start && seg.tail.size() == head) {
      std::memcpy(out, seg.tail.data(), head);
    } else if (::pread(seg.fd, out, head, block_start) != static_cast<ssize_t>(head)) {
      return false;  // (a buffered write since, e.g. a full disk's probe, and the block unreadable)
    }
  }
  size_t at = head;
  for (const auto& frame : seg.hold) {
    std::memcpy(out + at, frame->jpeg().data(), frame->jpeg().size());
    at += frame->jpeg().size();
  }
  std::memset(out + at, 0, length - at);
  for (size_t done = 0; done < length;) {
    const ssize_t n = ::pwrite(seg.direct_fd, out + done, length - done, block_start + static_cast<int64_t>(done));
    if (n < 0 && errno == EINTR) continue;
    if (n < 0 && errno == EINVAL && done == 0) {
      // The filesystem or device wants another alignment: this segment goes through the page cache.
      AVE_LOG(WARNING) << "recording: O_DIRECT write to '" << seg.row.path << "' refused (" << std::strerror(errno)
                       << "), writing through the page cache";
      ::close(seg.direct_fd);
      seg.direct_fd = -1;
      direct_ok_ = false;
      return false;
    }
    if (n <= 0) {
      *err = n < 0 ? errno : EIO;
      seg.tail_from = -1;
      return true;
    }
    done += static_cast<size_t>(n);
  }
  direct_writes_.fetch_add(1, std::memory_order_relaxed);
  seg.tail_from = end / kDirectAlign * kDirectAlign;
  seg.tail.assign(out + (seg.tail_from - block_start), static_cast<size_t>(end - seg.tail_from));
  *err = 0;
  return true;
}

void Recorder::CloseFd(OpenSegment& seg) {
  if (seg.direct_fd >= 0) {
    ::close(seg.direct_fd);
    seg.direct_fd = -1;
  }
  if (seg.fd < 0) return;
  // At the same size, ftruncate still frees the blocks fallocate reserved past the end; after
  // direct writes it also cuts the zeros of the last block.
  if ((seg.allocated > seg.written || options_.direct_io) && ::ftruncate(seg.fd, seg.written) != 0) {
    AVE_LOG(WARNING) << "recording: cannot release the reserved tail of '" << seg.row.path << "': " << std::strerror(errno);
  }
  ::close(seg.fd);
  seg.fd = -1;
}

uint64_t Recorder::RecordedSequence(const std::string& sensor_id, int64_t since_received_ns) const {
  std::lock_guard lock(mu_);
  const auto it = recorded_sequence_.find(sensor_id);
  if (it == recorded_sequence_.end() || it->second.second < since_received_ns) return 0;
  return it->second.first;
}

void Recorder::FlushBatch() {
  const int64_t now_ns = NowNs();
  if (options_.objects_source && now_ns - last_objects_ns_ >= std::chrono::nanoseconds(options_.objects_period).count()) {
    last_objects_ns_ = now_ns;
    v1::SceneUpdate objects = options_.objects_source();
    if (objects.objects_size() > 0) {
      ObjectsRow row{objects.server_time_ns() ? objects.server_time_ns() : now_ns, ""};
      objects.SerializeToString(&row.objects);
      batch_.objects.push_back(std::move(row));
    }
  }
  // 1. the bytes on disk (syncfs or fdatasync), 2. then the rows that point at them (one transaction).
  std::map<std::string, int64_t> committed_before;
  for (auto& [id, seg] : open_) WritePending(seg);
  SyncSegments();
  for (auto& [id, seg] : open_) {
    if (!seg.dirty) continue;
    committed_before[seg.row.path] = seg.row.bytes;
    seg.row.bytes = seg.written;
    batch_.segments.push_back(&seg.row);
  }
  if (batch_.segments.empty() && batch_.frames.empty() && batch_.sweeps.empty() && batch_.objects.empty() &&
      batch_.sensors.empty()) {
    return;
  }
  const size_t frames = batch_.frames.size(), sweeps = batch_.sweeps.size(), objects = batch_.objects.size();
  int64_t new_bytes = 0;
  for (const FrameRow& f : batch_.frames) new_bytes += f.length;
  if (absl::Status s = index_->Commit(batch_); !s.ok()) {
    // Unindexed bytes stay in the files; the next commit's rows point past them, a restart cuts them.
    write_errors_.fetch_add(1, std::memory_order_relaxed);
    AVE_LOG(ERROR) << "recording: index commit failed (" << frames << " frames lost): " << s.message();
    for (auto& [id, seg] : open_) {
      if (auto it = committed_before.find(seg.row.path); it != committed_before.end()) seg.row.bytes = it->second;
    }
  } else {
    commits_.fetch_add(1, std::memory_order_relaxed);
    frames_recorded_.fetch_add(frames, std::memory_order_relaxed);
    bytes_recorded_.fetch_add(new_bytes, std::memory_order_relaxed);
    sweeps_recorded_.fetch_add(sweeps, std::memory_order_relaxed);
    objects_recorded_.fetch_add(objects, std::memory_order_relaxed);
    bytes_on_disk_ += new_bytes;
    // Rows are in arrival order: the last of each sensor is its newest (a restarted agent's
    // sequence may be lower than an earlier stream's).
    std::lock_guard lock(mu_);
    for (const FrameRow& f : batch_.frames) recorded_sequence_[f.sensor_id] = {f.sequence, f.received_ns};
    for (const SweepRow& w : batch_.sweeps) recorded_sequence_[w.sensor_id] = {w.sequence, w.received_ns};
  }
  for (auto& [id, seg] : open_) seg.dirty = false;
  batch_ = IndexBatch();
}

void Recorder::SyncSegments() {
  std::vector<OpenSegment*> need;
  size_t on_dir_fs = 0;
  for (auto& [id, seg] : open_) {
    if (!seg.dirty || seg.written <= seg.row.bytes) continue;
    need.push_back(&seg);
    if (seg.same_fs) ++on_dir_fs;
  }
  // One syncfs writes back every dirty inode of the filesystem and flushes the device's cache
  // once (ext4: the inode blocks in one pass, not one synchronous inode write per file); it is at
  // least as strong as an fdatasync of each file. Its error (Linux >= 5.8 reports writeback
  // errors of the whole filesystem) cannot name the file: every segment it covered fails.
  if (options_.sync_method == RecorderOptions::SyncMethod::kFilesystem && syncfs_ok_ && on_dir_fs >= 2) {
    syncs_.fetch_add(1, std::memory_order_relaxed);
    int err = ::syncfs(dir_fd_) == 0 ? 0 : errno;
    if (err == ENOSYS || err == EBADF) {
      syncfs_ok_ = false;  // per file from now on
      AVE_LOG(WARNING) << "recording: syncfs unavailable (" << std::strerror(err) << "), syncing each segment";
    } else {
      for (OpenSegment*& seg : need) {
        if (!seg->same_fs) continue;
        if (err != 0) SyncFailed(*seg, err);
        seg = nullptr;  // done
      }
    }
  }
  for (OpenSegment* seg : need) {
    if (!seg) continue;
    syncs_.fetch_add(1, std::memory_order_relaxed);
    if (::fdatasync(seg->fd) != 0) SyncFailed(*seg, errno);
  }
}

void Recorder::SyncFailed(OpenSegment& seg, int err) {
  // The batch's bytes of this segment may not be on disk: drop their rows and the bytes. (A named
  // copy of the path: clang 14, which builds the fuzz targets, cannot capture a structured binding
  // in a lambda.)
  const std::string& failed_path = seg.row.path;
  const size_t before = batch_.frames.size();
  std::erase_if(batch_.frames, [&failed_path](const FrameRow& f) { return f.segment_path == failed_path; });
  const size_t dropped = before - batch_.frames.size();
  if (::ftruncate(seg.fd, seg.row.bytes) != 0) AVE_LOG(ERROR) << "recording: cannot truncate '" << seg.row.path << "'";
  seg.written = seg.row.bytes;
  if (IsNoSpace(err)) {
    SetDiskFull(true, absl::StrCat("disk full syncing '", seg.row.path, "': ", std::strerror(err)));
    disk_full_skips_.fetch_add(dropped, std::memory_order_relaxed);
  } else {
    write_errors_.fetch_add(dropped, std::memory_order_relaxed);
    AVE_LOG(ERROR) << "recording: sync of '" << seg.row.path << "' failed (" << dropped
                   << " frames dropped): " << std::strerror(err);
  }
}

void Recorder::RunRetention(int64_t need_bytes) {
  const int64_t now_ns = NowNs();
  auto segments = index_->Segments();
  if (!segments.ok()) {
    AVE_LOG(ERROR) << "recording retention: " << segments.status().message();
    return;
  }
  const int64_t max_age_ns = std::chrono::nanoseconds(options_.max_age).count();
  int64_t total = 0;
  for (const SegmentRow& seg : *segments) total += seg.bytes;
  std::set<std::string> open_paths;
  for (const auto& [id, seg] : open_) {
    open_paths.insert(seg.row.path);  // being written, or closed and not yet committed so
    total += seg.written - seg.row.bytes;
  }
  int64_t oldest_kept_ns = now_ns;
  for (const SegmentRow& seg : *segments) {  // oldest first
    const bool deletable = !open_paths.count(seg.path);
    const bool too_old = max_age_ns > 0 && seg.end_ns < now_ns - max_age_ns;
    const bool over_budget = options_.max_bytes > 0 && total + need_bytes > options_.max_bytes;
    if (!deletable || !(too_old || over_budget)) {
      oldest_kept_ns = std::min(oldest_kept_ns, seg.start_ns);
      continue;
    }
    if (absl::Status s = index_->DeleteSegment(seg.id); !s.ok()) {
      AVE_LOG(ERROR) << "recording retention: " << s.message();
      return;
    }
    std::error_code ec;
    fs::remove(fs::path(options_.dir) / seg.path, ec);  // after its rows: a crash leaves an orphan, removed at start
    total -= seg.bytes;
    bytes_on_disk_ -= seg.bytes;
    segments_deleted_.fetch_add(1, std::memory_order_relaxed);
  }
  const int64_t metadata_before = max_age_ns > 0 ? std::min(oldest_kept_ns, now_ns - max_age_ns) : oldest_kept_ns;
  if (max_age_ns > 0 || segments_deleted_.load() > 0) {
    if (absl::Status s = index_->DeleteMetadataBefore(metadata_before); !s.ok()) {
      AVE_LOG(ERROR) << "recording retention: " << s.message();
    }
  }
  // A full disk or budget is retried once per flush: the next frame may write again.
  if (disk_full_.load()) probe_ = true;
}

RecorderStats Recorder::Stats() const {
  RecorderStats s;
  s.frames_recorded = frames_recorded_.load();
  s.bytes_recorded = bytes_recorded_.load();
  s.sweeps_recorded = sweeps_recorded_.load();
  s.objects_recorded = objects_recorded_.load();
  s.queue_drops = queue_drops_.load();
  s.disk_full_skips = disk_full_skips_.load();
  s.disk_full_events = disk_full_events_.load();
  s.write_errors = write_errors_.load();
  s.segments_deleted = segments_deleted_.load();
  s.commits = commits_.load();
  s.syncs = syncs_.load();
  s.direct_writes = direct_writes_.load();
  s.bytes_on_disk = bytes_on_disk_.load();
  s.disk_full = disk_full_.load();
  {
    std::lock_guard lock(mu_);
    s.queue_items = static_cast<int64_t>(queue_.size());
  }
  return s;
}

void Recorder::RenderPrometheus(std::string& out) const {
  const RecorderStats s = Stats();
  auto line = [&](const char* name, const char* type, const char* help, auto value) {
    absl::StrAppend(&out, "# HELP ", name, " ", help, "\n# TYPE ", name, " ", type, "\n", name, " ", value, "\n");
  };
  line("ave_record_frames_total", "counter", "JPEG frames recorded (written, synced and indexed).", s.frames_recorded);
  line("ave_record_bytes_total", "counter", "JPEG bytes recorded.", s.bytes_recorded);
  line("ave_record_sweeps_total", "counter", "LiDAR sweeps (tracks) recorded.", s.sweeps_recorded);
  line("ave_record_objects_total", "counter", "Fused-object snapshots recorded.", s.objects_recorded);
  line("ave_record_drops_total", "counter", "Frames dropped because the recorder queue was full.", s.queue_drops);
  line("ave_record_disk_full_skips_total", "counter", "Frames not recorded while the disk or budget was full.",
       s.disk_full_skips);
  line("ave_record_disk_full_events_total", "counter", "Times recording stopped for a full disk or budget.",
       s.disk_full_events);
  line("ave_record_write_errors_total", "counter", "Frames lost to other write, sync or index errors.", s.write_errors);
  line("ave_record_syncs_total", "counter", "syncfs or fdatasync calls that made segment bytes durable.", s.syncs);
  line("ave_record_direct_writes_total", "counter", "O_DIRECT writes of segment batches (the default; none with --record-buffered-io).",
       s.direct_writes);
  line("ave_record_segments_deleted_total", "counter", "Segments deleted by retention.", s.segments_deleted);
  line("ave_record_disk_full", "gauge", "1 while recording is stopped for a full disk or budget.", s.disk_full ? 1 : 0);
  line("ave_record_bytes_on_disk", "gauge", "Indexed segment bytes on disk.", s.bytes_on_disk);
  line("ave_record_queue_items", "gauge", "Frames and sweeps waiting for the recorder's writer.", s.queue_items);
}

}  // namespace ave::record
