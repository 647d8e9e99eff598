#pragma once
// Pose/box metadata an agent keeps across an outage (MISSION part G, issue 8): bounded in memory,
// spilled to a file when the outage is long, replayed oldest first after the agent reconnects.
// JPEGs are not kept (latest-frame semantics: old video is worth nothing to a live viewer); the
// metadata is (tracks, poses).
#include <cstdint>
#include <deque>
#include <fstream>
#include <optional>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "ave/v1/ave.pb.h"

namespace ave {

struct MetadataBufferOptions {
  size_t max_in_memory = 4096;    // records kept in memory before spilling (~30 Hz: 2 min)
  std::string spill_path;         // file for the overflow; empty = no spill (drop the newest)
  size_t max_spilled = 1'000'000;  // records in the file at most; beyond, the newest are dropped
};

class MetadataBuffer {
 public:
  explicit MetadataBuffer(MetadataBufferOptions options);
  ~MetadataBuffer();

  // Keeps `frame`'s metadata (its JPEG is cleared, metadata_only set). Records stay in push order.
  void Push(v1::SensorFrame frame);
  // The oldest record, or nullopt when empty. DataLoss if the spill file is corrupt (the rest of
  // the file is then discarded).
  absl::StatusOr<std::optional<v1::SensorFrame>> Pop();
  // Puts back the record Pop just returned (its send failed), so it is replayed first next time.
  void Unpop(v1::SensorFrame frame);

  size_t size() const { return memory_.size() + spilled_ - read_; }
  size_t spilled() const { return spilled_ - read_; }
  uint64_t dropped() const { return dropped_; }

 private:
  MetadataBufferOptions options_;
  std::deque<v1::SensorFrame> memory_;  // older than every spilled record
  std::optional<v1::SensorFrame> unpopped_;
  std::ofstream out_;
  std::ifstream in_;
  size_t spilled_ = 0;  // records written to the file
  size_t read_ = 0;     // records read back from it
  uint64_t dropped_ = 0;
};

}  // namespace ave
