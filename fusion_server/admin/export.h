#pragma once
// `ave-admin export` (issue 18): one camera's recorded frames over an interval, fetched through
// SceneService.Replay (stepped: every recorded frame, in order; audited by the server as
// "Export"), decoded and written with OpenCV's VideoWriter as Motion-JPEG (MJPG at quality 100)
// in the container the output's extension names (.mkv or .avi), at the recorded frame rate.
#include <cstdint>
#include <memory>
#include <string>

#include <grpcpp/grpcpp.h>

#include "absl/status/statusor.h"

namespace ave {

struct ExportRequest {
  std::string camera_id;
  int64_t from_ns = 0, to_ns = 0;  // server clock, ns since the Unix epoch
  std::string out_path;            // .mkv or .avi
};

struct ExportResult {
  int frames = 0;
  double fps = 0;
  int width = 0, height = 0;
  int gaps = 0;  // recorded frames the server could not read (deleted segments)
};

absl::StatusOr<ExportResult> ExportClip(std::shared_ptr<grpc::Channel> channel, const std::string& token,
                                        const ExportRequest& request);

}  // namespace ave
