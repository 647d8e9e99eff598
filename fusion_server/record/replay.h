#pragma once
// Replay of a recorded interval (issue 18), pure of gRPC: the recorded frames and sweeps are fed,
// in server capture-clock order, into a private SceneState holding the recorded sensors and the
// live server's terrain, so a replay's SceneUpdates come out of the same BuildUpdate (matrices,
// status, object fusion and paths, data selection) as live ones did.
//
// Seeking: the newest frame of each camera before the start (one indexed probe per camera) gives
// the image shown at the start; the frames of the `warmup` before it are fed without their JPEGs
// (not read) so that objects and their paths stand as they did live.
//
// Gaps: a frame whose segment file is gone or shorter than indexed is skipped and reported as a
// gap (consecutive ones of a camera merged); the replay goes on.
#include <chrono>
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "ave/v1/ave.pb.h"
#include "fusion_server/core/scene_state.h"
#include "fusion_server/record/record_index.h"

namespace ave::record {

// A registry entry as recorded (ave.v1.Camera bytes) and back.
std::string EntryBytes(const CameraEntry& entry);
absl::StatusOr<CameraEntry> EntryFromBytes(const std::string& bytes);

struct ReplayOptions {
  std::string store_path;  // the model store file holding the index
  std::string dir;         // the recording directory
  std::vector<std::string> sensor_ids;  // empty = every recorded sensor
  int64_t from_ns = 0, to_ns = 0;       // server clock, [from, to)
  std::chrono::seconds warmup{10};
  SceneStateOptions scene;
};

class ReplaySession {
 public:
  // `registry`: the live registry (for sensors recorded before their entry was); `terrain`: the
  // live state's ground (may be null). NotFound naming the cameras and range when nothing was
  // recorded there (with the recorded spans); InvalidArgument for an empty or reversed range.
  static absl::StatusOr<std::unique_ptr<ReplaySession>> Open(const ReplayOptions& options,
                                                             const std::vector<CameraEntry>& registry,
                                                             std::shared_ptr<const TerrainModel> terrain);

  // Server time of the next recorded frame or sweep in range; nullopt when the range is done.
  absl::StatusOr<std::optional<int64_t>> NextEventNs();
  // Feeds every recorded event with time <= until_ns (and < to_ns) into the state; returns how many.
  absl::StatusOr<size_t> AdvanceTo(int64_t until_ns);

  SceneState& state() { return *state_; }
  std::vector<v1::ReplayGap> TakeGaps();
  uint64_t frames_replayed() const { return frames_replayed_; }
  const std::vector<std::string>& sensor_ids() const { return sensor_ids_; }  // those replayed

 private:
  ReplaySession() = default;
  absl::Status Seek();
  absl::Status Refill();
  void Feed(const FrameRow& row, bool with_jpeg);
  void Feed(const SweepRow& row);
  void NoteGap(const FrameRow& row, const std::string& reason);

  ReplayOptions options_;
  std::unique_ptr<RecordIndex> index_;
  std::unique_ptr<SceneState> state_;
  std::vector<std::string> sensor_ids_;
  std::map<std::string, SensorKind> kinds_;
  // Pages of the two ordered streams and where the next page starts.
  std::vector<FrameRow> frames_;
  size_t frame_pos_ = 0;
  std::vector<SweepRow> sweeps_;
  size_t sweep_pos_ = 0;
  int64_t frames_from_ns_ = 0, sweeps_from_ns_ = 0;
  bool frames_done_ = false, sweeps_done_ = false;
  std::set<std::pair<std::string, uint64_t>> seen_at_boundary_;  // rows of the last page's last instant
  std::vector<v1::ReplayGap> gaps_;
  uint64_t frames_replayed_ = 0;
};

}  // namespace ave::record
