#include "fusion_server/record/replay.h"

#include <algorithm>
#include <set>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "fusion_server/core/convert.h"
#include "fusion_server/record/recorder.h"

namespace ave::record {
namespace {

constexpr int64_t kPage = 512;

template <typename Row>
std::pair<std::string, uint64_t> Key(const Row& row) {
  return {row.sensor_id, row.sequence};
}

// Pages one ordered stream: rows at the previous page's last instant that were already taken are
// dropped; a page full of one instant moves on past it.
template <typename Row, typename Query>
absl::Status NextPage(Query query, int64_t to_ns, int64_t& from_ns, bool& done, std::vector<Row>& rows, size_t& pos,
                      std::set<std::pair<std::string, uint64_t>>& seen) {
  rows.clear();
  pos = 0;
  while (!done && rows.empty()) {
    absl::StatusOr<std::vector<Row>> page = query(from_ns, to_ns, kPage);
    if (!page.ok()) return page.status();
    const bool full = static_cast<int64_t>(page->size()) == kPage;
    if (!full) done = true;
    if (page->empty()) break;
    const int64_t last_ns = page->back().capture_server_ns;
    std::set<std::pair<std::string, uint64_t>> next_seen;
    for (Row& row : *page) {
      if (row.capture_server_ns == from_ns && seen.count(Key(row))) continue;
      if (row.capture_server_ns == last_ns) next_seen.insert(Key(row));
      rows.push_back(std::move(row));
    }
    if (rows.empty() && full) {
      from_ns = last_ns + 1;  // a whole page of one instant, all taken already
      seen.clear();
      continue;
    }
    from_ns = last_ns;
    if (page->front().capture_server_ns == last_ns) next_seen.insert(seen.begin(), seen.end());
    seen = std::move(next_seen);
  }
  return absl::OkStatus();
}

std::string Time(int64_t ns) { return absl::StrCat(ns / 1'000'000'000, ".", absl::Dec(ns % 1'000'000'000 / 1'000'000, absl::kZeroPad3), " s"); }

}  // namespace

std::string EntryBytes(const CameraEntry& entry) {
  v1::Camera c;
  c.set_id(entry.id);
  c.set_name(entry.name);
  if (entry.kind == SensorKind::kCamera) *c.mutable_intrinsics() = ToProto(entry.intrinsics);
  *c.mutable_mounting_pose() = ToProto(entry.mounting_pose);
  c.set_source_url(entry.source_url);
  c.set_enabled(entry.enabled);
  c.set_kind(entry.kind == SensorKind::kRotatingLidar ? v1::SENSOR_KIND_ROTATING_LIDAR : v1::SENSOR_KIND_CAMERA);
  return c.SerializeAsString();
}

absl::StatusOr<CameraEntry> EntryFromBytes(const std::string& bytes) {
  v1::Camera c;
  if (!c.ParseFromString(bytes)) return absl::DataLossError("recorded sensor entry: not an ave.v1.Camera");
  CameraEntry e;
  e.id = c.id();
  e.name = c.name();
  e.kind = c.kind() == v1::SENSOR_KIND_ROTATING_LIDAR ? SensorKind::kRotatingLidar : SensorKind::kCamera;
  if (e.kind == SensorKind::kCamera) e.intrinsics = FromProto(c.intrinsics());
  e.mounting_pose = FromProto(c.mounting_pose());
  e.source_url = c.source_url();
  e.enabled = true;  // replay shows what was recorded, whatever the registry says now
  return e;
}

absl::StatusOr<std::unique_ptr<ReplaySession>> ReplaySession::Open(const ReplayOptions& options,
                                                                   const std::vector<CameraEntry>& registry,
                                                                   std::shared_ptr<const TerrainModel> terrain) {
  if (options.to_ns <= options.from_ns) {
    return absl::InvalidArgumentError(absl::StrCat("replay: end time ", options.to_ns, " must be after start time ",
                                                   options.from_ns));
  }
  std::unique_ptr<ReplaySession> session(new ReplaySession());
  session->options_ = options;
  auto index = RecordIndex::Open(options.store_path);
  if (!index.ok()) return index.status();
  session->index_ = *std::move(index);
  session->state_ = std::make_unique<SceneState>(options.scene);
  if (terrain) session->state_->SetTerrain(std::move(terrain));

  // Sensors: the recorded entries first (as they were), the live registry for the rest.
  std::map<std::string, CameraEntry> entries;
  for (const CameraEntry& e : registry) entries[e.id] = e;
  auto recorded = session->index_->Sensors();
  if (!recorded.ok()) return recorded.status();
  for (const auto& [id, bytes] : *recorded) {
    auto e = EntryFromBytes(bytes);
    if (!e.ok()) return absl::DataLossError(absl::StrCat("recorded sensor '", id, "': ", e.status().message()));
    entries[id] = *std::move(e);
  }
  auto spans = session->index_->Spans();
  if (!spans.ok()) return spans.status();
  std::set<std::string> recorded_ids;
  for (const RecordedSpan& span : *spans) recorded_ids.insert(span.sensor_id);
  for (const auto& [id, bytes] : *recorded) recorded_ids.insert(id);
  std::vector<std::string> ids = options.sensor_ids;
  if (ids.empty()) ids.assign(recorded_ids.begin(), recorded_ids.end());
  for (const std::string& id : ids) {
    auto it = entries.find(id);
    if (it == entries.end()) continue;  // never registered nor recorded: nothing to show
    CameraEntry entry = it->second;
    entry.enabled = true;
    session->state_->UpsertCamera(entry);
    if (entry.kind == SensorKind::kCamera) session->state_->StreamOpened(id, entry.intrinsics);
    else session->state_->StreamOpened(id);
    session->kinds_[id] = entry.kind;
    session->sensor_ids_.push_back(id);
  }
  session->frames_from_ns_ = session->sweeps_from_ns_ = options.from_ns;
  // An empty range answers clearly: which cameras, which range, and what was recorded.
  auto any_frames = session->index_->Frames(session->sensor_ids_, options.from_ns, options.to_ns, 1);
  if (!any_frames.ok()) return any_frames.status();
  auto any_sweeps = session->index_->Sweeps(session->sensor_ids_, options.from_ns, options.to_ns, 1);
  if (!any_sweeps.ok()) return any_sweeps.status();
  if (session->sensor_ids_.empty() || (any_frames->empty() && any_sweeps->empty())) {
    std::vector<std::string> described;
    for (const RecordedSpan& span : *spans) {
      if (!options.sensor_ids.empty() &&
          std::find(options.sensor_ids.begin(), options.sensor_ids.end(), span.sensor_id) == options.sensor_ids.end()) {
        continue;
      }
      described.push_back(absl::StrCat(span.sensor_id, " ", Time(span.first_ns), " .. ", Time(span.last_ns), " (",
                                       span.frames, " frames)"));
    }
    return absl::NotFoundError(absl::StrCat(
        "replay: nothing recorded for ", options.sensor_ids.empty() ? std::string("any camera") : absl::StrJoin(options.sensor_ids, ", "),
        " between ", Time(options.from_ns), " and ", Time(options.to_ns), "; recorded: ",
        described.empty() ? std::string("nothing") : absl::StrJoin(described, "; ")));
  }
  if (absl::Status s = session->Seek(); !s.ok()) return s;
  return session;
}

absl::Status ReplaySession::Seek() {
  // The image each camera showed at the start, then the warm-up frames (metadata only) in order.
  auto latest = index_->LatestBefore(sensor_ids_, options_.from_ns);
  if (!latest.ok()) return latest.status();
  std::set<std::pair<std::string, uint64_t>> with_jpeg;
  for (const FrameRow& row : *latest) with_jpeg.insert(Key(row));
  const int64_t warm_from = options_.from_ns - std::chrono::nanoseconds(options_.warmup).count();
  for (const FrameRow& row : *latest) {
    if (row.capture_server_ns < warm_from) Feed(row, true);
  }
  int64_t from_ns = warm_from;
  bool done = false;
  std::set<std::pair<std::string, uint64_t>> seen;
  std::vector<FrameRow> rows;
  size_t pos = 0;
  auto query = [&](int64_t a, int64_t b, int64_t n) { return index_->Frames(sensor_ids_, a, b, n); };
  while (!done) {
    if (absl::Status s = NextPage(query, options_.from_ns, from_ns, done, rows, pos, seen); !s.ok()) return s;
    for (const FrameRow& row : rows) Feed(row, with_jpeg.count(Key(row)) > 0);
  }
  // LiDAR tracks of the warm-up window.
  auto sweeps = index_->Sweeps(sensor_ids_, warm_from, options_.from_ns, 1 << 20);
  if (!sweeps.ok()) return sweeps.status();
  for (const SweepRow& row : *sweeps) Feed(row);
  gaps_.clear();  // gaps before the start are not this replay's
  frames_replayed_ = 0;
  return absl::OkStatus();
}

void ReplaySession::NoteGap(const FrameRow& row, const std::string& reason) {
  for (auto it = gaps_.rbegin(); it != gaps_.rend(); ++it) {
    if (it->camera_id() != row.sensor_id) continue;
    if (it->reason() == reason) {
      it->set_to_ns(row.capture_server_ns);
      it->set_frames(it->frames() + 1);
      return;
    }
    break;
  }
  v1::ReplayGap gap;
  gap.set_camera_id(row.sensor_id);
  gap.set_from_ns(row.capture_server_ns);
  gap.set_to_ns(row.capture_server_ns);
  gap.set_frames(1);
  gap.set_reason(reason);
  gaps_.push_back(std::move(gap));
}

void ReplaySession::Feed(const FrameRow& row, bool with_jpeg) {
  auto frame = std::make_shared<v1::SensorFrame>();
  if (!frame->ParseFromString(row.meta)) {
    NoteGap(row, "index row metadata unreadable");
    return;
  }
  if (with_jpeg) {
    absl::StatusOr<std::string> bytes = ReadSegmentBytes(options_.dir, row.segment_path, row.offset, row.length);
    if (!bytes.ok()) {
      NoteGap(row, std::string(bytes.status().message()));
      return;
    }
    frame->set_jpeg(*std::move(bytes));
  }
  if (state_->AcceptFrame(row.sensor_id, std::move(frame), row.received_ns, /*session=*/1).ok() && with_jpeg) {
    ++frames_replayed_;
  }
}

void ReplaySession::Feed(const SweepRow& row) {
  auto sweep = std::make_shared<v1::LidarSweepFrame>();
  if (!sweep->ParseFromString(row.meta)) return;
  state_->AcceptLidarSweep(row.sensor_id, std::move(sweep), row.received_ns, /*session=*/1).IgnoreError();
}

absl::Status ReplaySession::Refill() {
  if (frame_pos_ == frames_.size() && !frames_done_) {
    auto query = [&](int64_t a, int64_t b, int64_t n) { return index_->Frames(sensor_ids_, a, b, n); };
    if (absl::Status s = NextPage(query, options_.to_ns, frames_from_ns_, frames_done_, frames_, frame_pos_,
                                  seen_at_boundary_);
        !s.ok()) {
      return s;
    }
  }
  if (sweep_pos_ == sweeps_.size() && !sweeps_done_) {
    std::vector<std::string> lidars;
    for (const auto& [id, kind] : kinds_) {
      if (kind == SensorKind::kRotatingLidar) lidars.push_back(id);
    }
    if (lidars.empty()) {
      sweeps_done_ = true;
      sweeps_.clear();
      sweep_pos_ = 0;
    } else {
      // Sweeps of one instant are rare (a few LiDARs): paging by time alone, seen rows skipped.
      std::set<std::pair<std::string, uint64_t>> seen;
      auto query = [&](int64_t a, int64_t b, int64_t n) { return index_->Sweeps(lidars, a, b, n); };
      if (sweeps_from_ns_ > options_.from_ns && !sweeps_.empty()) {
        for (const SweepRow& row : sweeps_) {
          if (row.capture_server_ns == sweeps_from_ns_) seen.insert(Key(row));
        }
      }
      if (absl::Status s = NextPage(query, options_.to_ns, sweeps_from_ns_, sweeps_done_, sweeps_, sweep_pos_, seen);
          !s.ok()) {
        return s;
      }
    }
  }
  return absl::OkStatus();
}

absl::StatusOr<std::optional<int64_t>> ReplaySession::NextEventNs() {
  if (absl::Status s = Refill(); !s.ok()) return s;
  std::optional<int64_t> next;
  if (frame_pos_ < frames_.size()) next = frames_[frame_pos_].capture_server_ns;
  if (sweep_pos_ < sweeps_.size()) {
    const int64_t t = sweeps_[sweep_pos_].capture_server_ns;
    if (!next || t < *next) next = t;
  }
  return next;
}

absl::StatusOr<size_t> ReplaySession::AdvanceTo(int64_t until_ns) {
  size_t fed = 0;
  for (;;) {
    absl::StatusOr<std::optional<int64_t>> next = NextEventNs();
    if (!next.ok()) return next.status();
    if (!*next || **next > until_ns) return fed;
    const bool frame_first = frame_pos_ < frames_.size() &&
                             (sweep_pos_ >= sweeps_.size() || frames_[frame_pos_].capture_server_ns <= sweeps_[sweep_pos_].capture_server_ns);
    if (frame_first) Feed(frames_[frame_pos_++], true);
    else Feed(sweeps_[sweep_pos_++]);
    ++fed;
  }
}

std::vector<v1::ReplayGap> ReplaySession::TakeGaps() { return std::exchange(gaps_, {}); }

}  // namespace ave::record
