#include "sensor_agent/stream/agent_streamer.h"

#include <algorithm>
#include <filesystem>
#include <random>
#include <thread>

#include <grpcpp/grpcpp.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "ave/v1/ave.grpc.pb.h"
#include "fusion_server/core/convert.h"
#include "model_store/common/log.h"
#include "sensor_agent/stream/link.h"
#include "sensor_agent/stream/metadata_buffer.h"

namespace ave {
namespace {

using Clock = stream_link::Clock;
using stream_link::IsFatal;
using stream_link::JitteredWait;
using stream_link::PaceTo;
using stream_link::SleepUnlessStopped;

}  // namespace

void ClockOffsetEstimator::Sent(uint64_t sequence, int64_t local_ns) { sent_[sequence % kRing] = {sequence, local_ns}; }

bool ClockOffsetEstimator::Acked(uint64_t sequence, int64_t server_ns, int64_t local_ns) {
  const auto& [seq, sent_ns] = sent_[sequence % kRing];
  if (seq != sequence || local_ns < sent_ns) return false;
  const int64_t rtt = local_ns - sent_ns;
  samples_.emplace_back(rtt, server_ns - (sent_ns + rtt / 2));
  if (samples_.size() > window_) samples_.erase(samples_.begin());
  const auto best = std::min_element(samples_.begin(), samples_.end());
  rtt_ns_ = best->first;
  offset_ns_ = best->second;
  known_ = true;
  return true;
}

std::string AgentOptions::Check() const {
  if (server.empty()) return "server is empty";
  if (absl::Status s = net::CheckClientTransport(server, tls); !s.ok()) return std::string(s.message());
  if (camera_id.empty()) return "camera_id is empty";
  if (!(fps > 0 && fps <= 240)) return "fps must be in (0, 240]";
  if (jpeg_quality < 1 || jpeg_quality > 100) return "jpeg_quality must be in 1..100";
  if (pace_max_lag.count() < 0) return "pace_max_lag must be >= 0";
  if (keepalive.count() < 100 || keepalive.count() > 600000) return "keepalive must be 100 ms .. 10 min";
  if (max_frames < 0) return "max_frames must be >= 0";
  if (!(duration_s >= 0)) return "duration_s must be >= 0";
  if (backoff_initial.count() <= 0 || backoff_max < backoff_initial) return "backoff must be 0 < initial <= max";
  if (source_retry_initial.count() <= 0 || source_retry_max < source_retry_initial) {
    return "source retry must be 0 < initial <= max";
  }
  if (metadata_in_memory == 0) return "metadata_in_memory must be > 0";
  return {};
}

AgentStreamer::AgentStreamer(AgentOptions options, std::unique_ptr<FrameSource> source)
    : options_(std::move(options)), source_(std::move(source)) {}

AgentStats AgentStreamer::stats() const {
  std::lock_guard lock(stats_mu_);
  return stats_;
}

absl::Status AgentStreamer::Run(const std::atomic<bool>& stop) {
  if (const std::string why = options_.Check(); !why.empty()) return absl::InvalidArgumentError("agent: " + why);
  const std::string& id = options_.camera_id;
  const std::function<int64_t()> clock = options_.clock ? options_.clock : [] { return NowNs(); };
  std::mt19937_64 rng(std::hash<std::string>{}(id) ^ static_cast<uint64_t>(Clock::now().time_since_epoch().count()));
  const auto started = Clock::now();
  auto backoff = options_.backoff_initial;
  // A source that stops delivering: retried with a doubling wait, logged at each doubling, then
  // every source_log_every; its outages and their length go to the stats and the summary line.
  struct SourceDown {
    AgentStreamer& self;
    const std::string& id;
    const std::atomic<bool>& stop;
    int64_t failures = 0;  // in the current outage
    Clock::time_point since, last_log;
    std::chrono::milliseconds wait{0}, last_wait{0};
    void Failed(std::string_view why) {
      const auto now = Clock::now();
      const AgentOptions& o = self.options_;
      if (failures == 0) {
        since = now;
        wait = o.source_retry_initial;
        last_wait = std::chrono::milliseconds(0);
        std::lock_guard lock(self.stats_mu_);
        ++self.stats_.source_outages;
      }
      ++failures;
      {
        std::lock_guard lock(self.stats_mu_);
        ++self.stats_.source_errors;
        self.stats_.last_error = std::string(why);
      }
      // Logged while the wait grows (its last step included), then every source_log_every.
      const bool growing = failures == 1 || wait < o.source_retry_max || last_wait < o.source_retry_max;
      last_wait = wait;
      if (growing || now - last_log >= o.source_log_every) {
        last_log = now;
        AVE_LOG(WARNING) << "camera '" << id << "': " << why << " (" << failures << " failed read"
                         << (failures == 1 ? "" : "s") << " in "
                         << absl::StrFormat("%.1f", std::chrono::duration<double>(now - since).count())
                         << " s; next try in " << wait.count() << " ms)";
      }
      SleepUnlessStopped(wait, stop);
      wait = std::min(o.source_retry_max, wait * 2);
    }
    void Delivered() {
      if (failures == 0) return;
      const double down = std::chrono::duration<double>(Clock::now() - since).count();
      AVE_LOG(INFO) << "camera '" << id << "': source back after " << absl::StrFormat("%.1f", down) << " s ("
                    << failures << " failed reads)";
      std::lock_guard lock(self.stats_mu_);
      self.stats_.source_down_s += down;
      failures = 0;
    }
  } source_down{*this, id, stop};
  uint64_t sequence = 0;
  int64_t sent_total = 0;
  bool source_done = false;
  std::string spill = options_.spill_path;
  if (spill.empty()) {
    spill = (std::filesystem::temp_directory_path() / absl::StrCat("ave-agent-", id, "-", ::getpid(), ".meta")).string();
  } else if (spill == "-") {
    spill.clear();
  } else if (const std::filesystem::path folder = std::filesystem::path(spill).parent_path();
             !folder.empty() && !std::filesystem::is_directory(folder)) {
    // Otherwise the first long outage would drop its records silently (counted only).
    return absl::InvalidArgumentError(absl::StrCat("camera '", id, "': --spill ", spill, ": no folder ", folder.string()));
  }
  MetadataBuffer buffer({.max_in_memory = options_.metadata_in_memory,
                         .spill_path = spill,
                         .max_spilled = options_.metadata_max_spilled});
  std::mutex clock_mu;
  ClockOffsetEstimator estimator;
  std::atomic<float> hint_fps{0};
  std::atomic<int> hint_quality{0};
  auto limited = [&](Clock::time_point now) {
    return (options_.max_frames > 0 && sent_total >= options_.max_frames) ||
           (options_.duration_s > 0 && now - started >= std::chrono::duration<double>(options_.duration_s));
  };
  auto pace = [&] { return hint_fps.load() > 0 ? std::min<double>(options_.fps, hint_fps.load()) : options_.fps; };
  // One frame's metadata as a SensorFrame (no JPEG yet), with the next sequence number.
  auto metadata_of = [&](const CapturedFrame& frame) {
    v1::SensorFrame out;
    out.set_capture_time_ns(frame.capture_time_ns);
    out.set_sequence(++sequence);
    if (frame.world_from_camera) {
      *out.mutable_pose() = ToProto(*frame.world_from_camera);
      for (double c : frame.pose_covariance) out.mutable_pose()->add_covariance(c);
    } else if (options_.mounting_pose) {
      *out.mutable_pose() = ToProto(*options_.mounting_pose);
    }
    if (options_.detector) {
      for (const FrameBox& box : options_.detector(frame)) {
        v1::DetectedBox* b = out.add_boxes();
        b->set_track_id(box.track_id);
        b->set_score(box.score);
        for (const auto& c : box.corners) {
          v1::Point2* p = b->add_corners();
          p->set_x(c[0]);
          p->set_y(c[1]);
        }
      }
    }
    return out;
  };
  auto note_buffered = [&] {
    std::lock_guard lock(stats_mu_);
    ++stats_.metadata_buffered;
    stats_.metadata_dropped = static_cast<int64_t>(buffer.dropped());
  };

  while (!stop.load() && !source_done) {
    const grpc::ChannelArguments args = stream_link::SensorChannelArgs(options_.keepalive);
    absl::StatusOr<std::shared_ptr<grpc::Channel>> channel = net::MakeChannel(options_.server, options_.tls, args);
    if (!channel.ok()) return absl::InvalidArgumentError(absl::StrCat("camera '", id, "': ", channel.status().message()));
    auto stub = v1::SensorService::NewStub(*channel);
    grpc::ClientContext context;
    auto stream = stub->Stream(&context);
    {
      std::lock_guard lock(stats_mu_);
      ++stats_.connects;
    }

    v1::SensorMessage hello;
    hello.mutable_hello()->set_camera_id(id);
    hello.mutable_hello()->set_token(options_.token);
    *hello.mutable_hello()->mutable_intrinsics() = ToProto(source_->intrinsics());
    hello.mutable_hello()->set_software_version(options_.software_version);
    bool healthy = stream->Write(hello);

    // Acks, flow-control hints and clock samples arrive on their own thread.
    std::atomic<bool> acked_once{false};
    std::thread reader([&] {
      v1::SensorAck ack;
      while (stream->Read(&ack)) {
        const int64_t now = clock();
        hint_fps = ack.hint().max_fps();
        hint_quality = static_cast<int>(ack.hint().jpeg_quality());
        acked_once = true;
        std::lock_guard clock_lock(clock_mu);
        estimator.Acked(ack.sequence(), ack.server_time_ns(), now);
        std::lock_guard lock(stats_mu_);
        ++stats_.frames_acked;
        stats_.clock_offset_ns = estimator.offset_ns();
        stats_.clock_rtt_ns = estimator.rtt_ns();
        stats_.hint_fps = hint_fps;
        stats_.recorded_sequence = std::max(stats_.recorded_sequence, ack.recorded_sequence());
      }
    });
    auto send = [&](v1::SensorMessage& message) {
      {
        std::lock_guard clock_lock(clock_mu);
        message.mutable_frame()->set_clock_offset_ns(estimator.known() ? estimator.offset_ns() : 0);
        estimator.Sent(message.frame().sequence(), clock());
      }
      return stream->Write(message);
    };

    // Replay what was buffered during the outage, oldest first, before any live frame.
    while (healthy && !stop.load()) {
      absl::StatusOr<std::optional<v1::SensorFrame>> record = buffer.Pop();
      if (!record.ok()) {
        AVE_LOG(ERROR) << "camera '" << id << "': " << record.status().message();
        continue;
      }
      if (!record->has_value()) break;
      v1::SensorMessage message;
      *message.mutable_frame() = **record;
      if (!send(message)) {
        buffer.Unpop(std::move(**record));
        healthy = false;
        break;
      }
      std::lock_guard lock(stats_mu_);
      ++stats_.metadata_replayed;
    }

    auto next_tick = Clock::now();
    while (healthy && !stop.load()) {
      if (limited(Clock::now())) {
        source_done = true;
        break;
      }
      absl::StatusOr<CapturedFrame> frame = source_->Next();
      if (!frame.ok()) {
        if (frame.status().code() == absl::StatusCode::kOutOfRange) {
          AVE_LOG(INFO) << "camera '" << id << "': " << frame.status().message();
          source_done = true;
          break;
        }
        source_down.Failed(std::string(frame.status().message()));
        continue;
      }
      source_down.Delivered();
      {
        std::lock_guard lock(stats_mu_);
        ++stats_.frames_captured;
      }
      const int quality = hint_quality.load() > 0 ? hint_quality.load() : options_.jpeg_quality;
      // A source that delivers JPEG (pre-rendered sim footage: the camera's own bytes) is sent as
      // it came unless a lower quality is asked (the server's hint, to save bandwidth): encoding
      // its decoded image at a higher quality would cost CPU and bytes and add no detail.
      std::vector<uchar> jpeg;
      if (!frame->jpeg.empty() && frame->jpeg_quality <= quality) {
        jpeg = std::move(frame->jpeg);
      } else {
        const cv::Mat image(frame->height, frame->width, CV_8UC3, frame->bgr.data());
        if (!cv::imencode(".jpg", image, jpeg, {cv::IMWRITE_JPEG_QUALITY, quality})) {
          AVE_LOG(ERROR) << "camera '" << id << "': JPEG encoding failed";
          continue;
        }
      }
      v1::SensorMessage message;
      *message.mutable_frame() = metadata_of(*frame);
      message.mutable_frame()->set_jpeg(jpeg.data(), jpeg.size());
      if (!send(message)) {
        buffer.Push(std::move(*message.mutable_frame()));  // the link broke: keep its metadata
        note_buffered();
        healthy = false;
        break;
      }
      ++sent_total;
      {
        std::lock_guard lock(stats_mu_);
        ++stats_.frames_sent;
        stats_.bytes_sent += static_cast<int64_t>(jpeg.size());
      }
      if (acked_once) backoff = options_.backoff_initial;  // the link works again
      // Pace non-live sources: the slower of our rate and the server's hint.
      if (!source_->live()) {
        PaceTo(next_tick, pace(), stop, options_.pace_max_lag);
      }
    }

    if (stop.load()) context.TryCancel();
    stream->WritesDone();
    const grpc::Status status = stream->Finish();
    reader.join();
    if (stop.load() || (source_done && status.ok())) break;
    if (!status.ok()) {
      {
        std::lock_guard lock(stats_mu_);
        stats_.last_error = status.error_message();
      }
      if (IsFatal(status.error_code())) {
        AVE_LOG(ERROR) << "camera '" << id << "': refused by the server: " << status.error_message();
        return absl::Status(static_cast<absl::StatusCode>(status.error_code()), status.error_message());
      }
      // --max-frames / --duration reached while the server is away: stop (the backoff below would
      // return at once and the loop reconnect without pause, for ever; found for issue 14).
      if (source_done || limited(Clock::now())) break;
      // Jittered exponential backoff: a random wait in [backoff/2, backoff], then double it. The
      // camera keeps capturing meanwhile; each frame's metadata goes to the buffer.
      const auto wait = JitteredWait(backoff, rng);
      AVE_LOG(WARNING) << "camera '" << id << "': stream ended (" << status.error_message() << "); reconnecting in "
                       << wait.count() << " ms (" << buffer.size() << " metadata records buffered)";
      const auto until = Clock::now() + wait;
      while (!stop.load() && Clock::now() < until && !limited(Clock::now())) {
        absl::StatusOr<CapturedFrame> frame = source_->Next();
        if (frame.ok()) {
          buffer.Push(metadata_of(*frame));
          note_buffered();
        } else if (frame.status().code() == absl::StatusCode::kOutOfRange) {
          source_done = true;
          break;
        }
        const auto tick = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / pace()));
        SleepUnlessStopped(std::min<Clock::duration>(tick, until - Clock::now()), stop);
      }
      backoff = std::min(options_.backoff_max, backoff * 2);
    }
  }
  {
    std::lock_guard lock(stats_mu_);
    stats_.source_drop_outs = source_->drop_outs();
    stats_.source_reconnects = source_->reconnects();
  }
  const AgentStats s = stats();
  AVE_LOG(INFO) << "camera '" << id << "': stopped after " << s.frames_sent << " frames sent, " << s.frames_acked
                << " acked, " << s.connects << " connections, " << s.metadata_replayed << "/" << s.metadata_buffered
                << " buffered metadata records replayed; source: " << s.source_outages << " outages ("
                << absl::StrFormat("%.1f", s.source_down_s) << " s down, " << s.source_errors << " failed reads), "
                << s.source_drop_outs << " drop-outs, " << s.source_reconnects << " reconnects";
  return absl::OkStatus();
}

}  // namespace ave
