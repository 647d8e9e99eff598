#include "fusion_server/admin/export.h"

#include <algorithm>
#include <vector>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

#include "absl/strings/str_cat.h"
#include "model_store/image/image_decode.h"
#include "ave/v1/ave.grpc.pb.h"
#include "fusion_server/admin/admin_client.h"

namespace ave {

absl::StatusOr<ExportResult> ExportClip(std::shared_ptr<grpc::Channel> channel, const std::string& token,
                                        const ExportRequest& request) {
  const std::string ext = request.out_path.size() > 4 ? request.out_path.substr(request.out_path.size() - 4) : "";
  if (ext != ".mkv" && ext != ".avi") {
    return absl::InvalidArgumentError("export --out '" + request.out_path + "': must end in .mkv or .avi (Motion-JPEG)");
  }
  auto stub = v1::SceneService::NewStub(channel);
  grpc::ClientContext context;
  context.AddMetadata("authorization", "Bearer " + token);
  v1::ReplayRequest replay;
  replay.set_viewer_id("ave-admin export");
  replay.add_camera_ids(request.camera_id);
  replay.set_start_time_ns(request.from_ns);
  replay.set_end_time_ns(request.to_ns);
  replay.set_include_jpeg(true);
  replay.set_max_updates(1u << 30);  // stepping: every recorded frame, as fast as we read
  replay.set_purpose("export");
  auto reader = stub->Replay(&context, replay);
  // The JPEGs as recorded, with their capture times: the frame rate is known only at the end.
  std::vector<std::pair<int64_t, std::string>> frames;
  ExportResult result;
  v1::SceneUpdate update;
  while (reader->Read(&update)) {
    for (auto& cam : *update.mutable_cameras()) {
      if (cam.camera_id() != request.camera_id || cam.jpeg().empty()) continue;
      frames.emplace_back(cam.frame_capture_server_time_ns(), std::move(*cam.mutable_jpeg()));
    }
    for (const auto& gap : update.replay().gaps()) result.gaps += static_cast<int>(gap.frames());
  }
  if (absl::Status s = FromGrpc(reader->Finish()); !s.ok()) return s;
  if (frames.empty()) {
    return absl::NotFoundError(absl::StrCat("export: camera '", request.camera_id, "' has no readable frame between ",
                                            request.from_ns, " and ", request.to_ns));
  }
  result.fps = 15;
  if (frames.size() > 1) {
    const double span_s = (frames.back().first - frames.front().first) * 1e-9;
    if (span_s > 0) result.fps = std::clamp((frames.size() - 1) / span_s, 0.1, 240.0);
  }
  cv::VideoWriter writer;
  for (const auto& [t_ns, jpeg] : frames) {
    // Recorded bytes are a sensor's JPEG: the checked decoder (issue 14) refuses a size that
    // disagrees with its header or is over the limits, counted as a gap like any undecodable one.
    const absl::StatusOr<cv::Mat> decoded = image::DecodeImage(jpeg, image::Channels::kColor);
    const cv::Mat image = decoded.ok() ? *decoded : cv::Mat();
    if (image.empty()) {
      ++result.gaps;
      continue;
    }
    if (!writer.isOpened()) {
      result.width = image.cols;
      result.height = image.rows;
      if (!writer.open(request.out_path, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), result.fps, image.size())) {
        return absl::UnavailableError("export: OpenCV cannot write '" + request.out_path + "' (MJPG)");
      }
      writer.set(cv::VIDEOWRITER_PROP_QUALITY, 100);
    }
    if (image.cols != result.width || image.rows != result.height) {
      ++result.gaps;  // a size change mid-clip (camera reconfigured): left out, not rescaled
      continue;
    }
    writer.write(image);
    ++result.frames;
  }
  writer.release();
  return result;
}

}  // namespace ave
