// SceneService.Replay (issue 18): the recorded scene, as live viewers saw it, paced at a rate.
//
// Pause, step and seek are re-requests, not a bidirectional control stream: a seek costs one indexed
// probe per camera plus the warm-up (milliseconds, see ave-bench record), a paused viewer then holds
// no server state at all, and a viewer consumes a replay through exactly the server-streaming
// path it uses for live updates. Stepping is max_updates: one update per recorded frame, as fast as
// the viewer reads them.
#include <algorithm>
#include <cmath>
#include <thread>

#include <google/protobuf/arena.h>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "fusion_server/core/validation.h"
#include "fusion_server/record/replay.h"
#include "fusion_server/service/services.h"
#include "model_store/common/log.h"

namespace ave::internal {
namespace {

grpc::Status CheckReplayRequest(const v1::ReplayRequest& request) {
  if (request.viewer_id().size() > 128) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "viewer_id longer than 128 characters");
  }
  if (request.camera_ids_size() > 4096) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "camera_ids: at most 4096 cameras per replay");
  }
  for (const std::string& id : request.camera_ids()) {
    if (!IsValidCameraId(id)) {
      return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                          "camera_ids: '" + id.substr(0, 80) + "' is not a camera id ([A-Za-z0-9_.-], 1..64)");
    }
  }
  if (!request.purpose().empty() && request.purpose() != "export") {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "purpose: must be empty or \"export\"");
  }
  if (request.end_time_ns() <= request.start_time_ns()) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                        absl::StrCat("end_time_ns (", request.end_time_ns(), ") must be after start_time_ns (",
                                     request.start_time_ns(), ")"));
  }
  const float rate = request.rate();
  if (!(std::isfinite(rate) && (rate == 0 || (rate >= 0.25f && rate <= 16.0f)))) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "rate: must be 0 (1x) or 0.25 .. 16");
  }
  if (const float r = request.max_rate_hz(); !(std::isfinite(r) && (r == 0 || r >= 0.1f))) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "max_rate_hz: must be 0 (server default) or at least 0.1 Hz");
  }
  return grpc::Status::OK;
}

}  // namespace

grpc::Status SceneServiceImpl::Replay(grpc::ServerContext* context, const v1::ReplayRequest* request,
                                      grpc::ServerWriter<v1::SceneUpdate>* writer) {
  Principal principal;
  if (grpc::Status s = AuthorizeCall(shared_, *context, Action::kSubscribe, {}, {}, &principal); !s.ok()) return s;
  if (grpc::Status s = CheckReplayRequest(*request); !s.ok()) return s;
  ViewerCursor cursor;
  if (grpc::Status s = SelectionViews(request->views(), chunks_, floor_z_, cursor); !s.ok()) return s;
  if (!shared_.recorder) {
    return grpc::Status(grpc::StatusCode::FAILED_PRECONDITION, "this server does not record (start it with --record-dir)");
  }
  const std::vector<std::string> camera_ids(request->camera_ids().begin(), request->camera_ids().end());
  const double rate = request->rate() > 0 ? request->rate() : 1.0;
  const std::string viewer = request->viewer_id().empty() ? context->peer() : request->viewer_id();

  // Every replay request is audited: who, which cameras, which range (refused ones included).
  const std::string actor = absl::StrCat(RoleName(principal.role), ":", principal.token_id,
                                         principal.bootstrap ? " (bootstrap)" : "", "@", context->peer());
  const std::string cameras_text = camera_ids.empty() ? std::string("*") : absl::StrJoin(camera_ids, ",");
  const std::string range_json =
      absl::StrCat("{\"viewer\":\"", viewer.size() <= 128 ? viewer : viewer.substr(0, 128), "\",\"cameras\":\"",
                   cameras_text, "\",\"from_ns\":", request->start_time_ns(), ",\"to_ns\":", request->end_time_ns(),
                   ",\"rate\":", rate, "}");
  if (auto s = shared_.store.AppendAudit(actor, request->purpose() == "export" ? "Export" : "Replay", cameras_text, "",
                                        range_json);
      !s.ok()) {
    AVE_LOG(ERROR) << "audit write failed: " << s.status().message();
  }

  record::ReplayOptions ro;
  ro.store_path = options_.store_path;
  ro.dir = options_.record_dir;
  ro.sensor_ids = camera_ids;
  ro.from_ns = request->start_time_ns();
  ro.to_ns = request->end_time_ns();
  ro.scene = options_.scene;
  std::vector<CameraEntry> registry;
  for (const std::string& id : state_.CameraIds()) {
    if (std::optional<CameraEntry> entry = state_.FindCamera(id)) registry.push_back(*std::move(entry));
  }
  const auto opened_at = std::chrono::steady_clock::now();
  absl::StatusOr<std::unique_ptr<record::ReplaySession>> session =
      record::ReplaySession::Open(ro, registry, state_.terrain());
  if (!session.ok()) return ToGrpc(session.status());
  record::ReplaySession& replay = **session;
  AVE_LOG(INFO) << "viewer '" << viewer << "' replays " << cameras_text << " from " << ro.from_ns << " to " << ro.to_ns
                << " at " << rate << "x (seek "
                << std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - opened_at).count()
                << " ms)";

  const float rate_hz = std::min(options_.max_viewer_rate_hz,
                                 request->max_rate_hz() > 0 ? request->max_rate_hz() : options_.default_viewer_rate_hz);
  const auto min_interval = std::chrono::microseconds(static_cast<int64_t>(1e6 / rate_hz));
  const bool stepping = request->max_updates() > 0;
  const auto wall0 = std::chrono::steady_clock::now();
  int64_t replay_ns = ro.from_ns;
  uint32_t sent = 0;
  for (bool end = false; !end && !context->IsCancelled() && !state_.shut_down();) {
    absl::StatusOr<std::optional<int64_t>> next = replay.NextEventNs();
    if (!next.ok()) return ToGrpc(next.status());
    if (stepping) {
      if (*next) replay_ns = **next;
    } else {
      const double elapsed_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
      replay_ns = std::min<int64_t>(ro.from_ns + static_cast<int64_t>(elapsed_s * rate * 1e9), ro.to_ns - 1);
      if (!*next) replay_ns = ro.to_ns - 1;  // nothing more recorded in range: finish now
    }
    absl::StatusOr<size_t> fed = replay.AdvanceTo(replay_ns);
    if (!fed.ok()) return ToGrpc(fed.status());
    next = replay.NextEventNs();
    if (!next.ok()) return ToGrpc(next.status());
    end = !*next || replay_ns >= ro.to_ns - 1 || (stepping && sent + 1 >= request->max_updates());

    google::protobuf::Arena arena;
    v1::SceneUpdate& update = *google::protobuf::Arena::CreateMessage<v1::SceneUpdate>(&arena);
    replay.state().BuildUpdate(camera_ids, request->include_jpeg(), replay_ns, cursor, update);
    if (!chunks_.empty()) update.set_static_model_version(chunks_[0].version());
    v1::ReplayStatus* status = update.mutable_replay();
    status->set_replay_time_ns(replay_ns);
    status->set_rate(static_cast<float>(rate));
    for (v1::ReplayGap& gap : replay.TakeGaps()) *status->add_gaps() = std::move(gap);
    status->set_end(end);
    status->set_frames_replayed(replay.frames_replayed());
    if (!writer->Write(update)) break;
    ++sent;
    if (end || stepping) continue;
    // Sleep until the next recorded event is due (at most a second, to refresh camera status ages
    // and notice a cancelled call), but no sooner than the viewer's update interval.
    auto wake = std::chrono::steady_clock::now() + min_interval;
    if (*next) {
      const auto due = wall0 + std::chrono::nanoseconds(static_cast<int64_t>((**next - ro.from_ns) / rate));
      wake = std::max(wake, std::min(due, std::chrono::steady_clock::now() + std::chrono::seconds(1)));
    }
    std::this_thread::sleep_until(wake);
  }
  AVE_LOG(INFO) << "viewer '" << viewer << "' replay ended after " << sent << " updates, "
                << replay.frames_replayed() << " frames";
  return grpc::Status::OK;
}

// The time line's data: index rows only (no image, pose or object leaves the server), so not
// audited; a panel polls it every few seconds.
grpc::Status SceneServiceImpl::RecordedSpans(grpc::ServerContext* context, const v1::RecordedSpansRequest* request,
                                             v1::RecordedSpansResponse* response) {
  if (grpc::Status s = AuthorizeCall(shared_, *context, Action::kSubscribe, {}, {}, nullptr); !s.ok()) return s;
  if (request->camera_ids_size() > 4096) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "camera_ids: at most 4096 cameras");
  }
  for (const std::string& id : request->camera_ids()) {
    if (!IsValidCameraId(id)) {
      return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                          "camera_ids: '" + id.substr(0, 80) + "' is not a camera id ([A-Za-z0-9_.-], 1..64)");
    }
  }
  if (request->merge_gap_ns() < 0) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "merge_gap_ns: must be 0 (2 s) or positive");
  }
  if (!shared_.recorder) {
    return grpc::Status(grpc::StatusCode::FAILED_PRECONDITION, "this server does not record (start it with --record-dir)");
  }
  absl::StatusOr<std::unique_ptr<record::RecordIndex>> index = record::RecordIndex::Open(options_.store_path);
  if (!index.ok()) return ToGrpc(index.status());
  absl::StatusOr<std::vector<record::SegmentRow>> segments = (*index)->Segments();
  if (!segments.ok()) return ToGrpc(segments.status());
  absl::StatusOr<std::vector<record::RecordedSpan>> spans = (*index)->Spans();
  if (!spans.ok()) return ToGrpc(spans.status());
  const std::vector<std::string> ids(request->camera_ids().begin(), request->camera_ids().end());
  const int64_t gap_ns = request->merge_gap_ns() > 0 ? request->merge_gap_ns() : 2'000'000'000;
  for (const record::RecordedIntervals& sensor : record::MergeSegmentIntervals(*std::move(segments), ids, gap_ns)) {
    v1::RecordedCamera& camera = *response->add_cameras();
    camera.set_camera_id(sensor.sensor_id);
    for (const auto& [from_ns, to_ns] : sensor.intervals) {
      v1::RecordedInterval& interval = *camera.add_intervals();
      interval.set_from_ns(from_ns);
      interval.set_to_ns(to_ns);
    }
    for (const record::RecordedSpan& span : *spans) {
      if (span.sensor_id == sensor.sensor_id) camera.set_frames(static_cast<uint64_t>(span.frames));
    }
  }
  response->set_server_time_ns(NowNs());
  return grpc::Status::OK;
}

}  // namespace ave::internal
