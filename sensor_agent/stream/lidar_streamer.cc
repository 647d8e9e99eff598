#include "sensor_agent/stream/lidar_streamer.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <thread>
#include <unordered_map>

#include <grpcpp/grpcpp.h>

#include "absl/strings/str_cat.h"
#include "ave/v1/ave.grpc.pb.h"
#include "fusion_server/core/convert.h"
#include "fusion_server/core/validation.h"
#include "model_store/common/log.h"
#include "sensor_agent/stream/link.h"
#include "sensor_agent/stream/agent_streamer.h"

namespace ave {
namespace {

using Clock = stream_link::Clock;
using stream_link::IsFatal;
using stream_link::JitteredWait;
using stream_link::PaceTo;
using stream_link::SleepUnlessStopped;

void PutLe16(std::string& out, uint16_t v) {
  out.push_back(static_cast<char>(v & 0xFF));
  out.push_back(static_cast<char>(v >> 8));
}

// Metres to int16 centimetres; nullopt outside ±327.67 m or not finite.
std::optional<int16_t> Centimetres(float m) {
  const float cm = std::round(m * 100.0f);
  if (!(cm >= -32767.0f && cm <= 32767.0f)) return std::nullopt;
  return static_cast<int16_t>(cm);
}

}  // namespace

std::string LidarStreamOptions::Check() const {
  if (server.empty()) return "server is empty";
  if (sensor_id.empty()) return "sensor_id is empty";
  if (keepalive.count() < 100 || keepalive.count() > 600000) return "keepalive must be 100 ms .. 10 min";
  if (backoff_initial.count() <= 0 || backoff_max < backoff_initial) return "backoff must be 0 < initial <= max";
  if (max_sweeps < 0) return "max_sweeps must be >= 0";
  if (!(duration_s >= 0)) return "duration_s must be >= 0";
  if (!(pace_hz >= 0 && pace_hz <= 1000)) return "pace_hz must be in [0, 1000]";
  if (world_from_sensor && (!world_from_sensor->translation.allFinite() ||
                            std::abs(world_from_sensor->rotation.norm() - 1) > 1e-6)) {
    return "world_from_sensor must be finite with a unit rotation";
  }
  return {};
}

v1::LidarSweepFrame SweepToWire(const lidar::LidarSweep& sweep, const lidar::FootTracks& tracks, bool send_points,
                                uint32_t max_points, int64_t* points_dropped) {
  v1::LidarSweepFrame out;
  out.set_capture_time_ns(sweep.t_ns);
  if (sweep.world_from_sensor) *out.mutable_world_from_sensor() = ToProto(*sweep.world_from_sensor);
  // Ground frame -> world: p_world = R p_ground + t with p_ground = (x, y, 0); the ground-plane
  // Jacobian of (x_world, y_world) is the top-left 2x2 of R (exact when the ground plane is level).
  const Eigen::Matrix3d r = tracks.world_from_ground.rotation.toRotationMatrix();
  const Eigen::Matrix2d j = r.topLeftCorner<2, 2>();
  std::unordered_map<uint32_t, uint16_t> label_of;  // track id -> 1-based index in out.tracks
  for (const lidar::FootTrack& t : tracks.tracks) {
    if (!t.confirmed || t.id == 0 || label_of.count(t.id) || out.tracks_size() >= 65535) continue;
    const Eigen::Vector3d p = tracks.world_from_ground * Eigen::Vector3d(t.xy_m.x(), t.xy_m.y(), 0);
    const Eigen::Vector2d v = j * t.velocity_mps;
    Eigen::Matrix2d c = j * t.covariance_m2 * j.transpose();
    c = 0.5 * (c + c.transpose()).eval();
    // The server would refuse the whole sweep: a non-finite track, or a velocity over its limit (a
    // tracker's estimate from two sweeps very close in time), is left out of this sweep instead.
    if (!p.allFinite() || !v.allFinite() || !c.allFinite()) continue;
    if (std::hypot(static_cast<float>(v.x()), static_cast<float>(v.y())) > kMaxTrackSpeedMps) continue;
    v1::FootTrack* w = out.add_tracks();
    w->set_track_id(t.id);
    w->mutable_position()->set_x(p.x());
    w->mutable_position()->set_y(p.y());
    w->mutable_position()->set_z(p.z());
    w->set_velocity_x_mps(static_cast<float>(v.x()));
    w->set_velocity_y_mps(static_cast<float>(v.y()));
    w->add_covariance(static_cast<float>(c(0, 0)));
    w->add_covariance(static_cast<float>(c(0, 1)));
    w->add_covariance(static_cast<float>(c(1, 1)));
    w->set_age_sweeps(static_cast<uint32_t>(std::max(0, t.age_frames)));
    label_of[t.id] = static_cast<uint16_t>(out.tracks_size());
  }
  int64_t dropped = 0;
  if (send_points && !label_of.empty() && tracks.point_track_id.size() == sweep.points.size()) {
    // Over the budget, every stride-th point of a streamed track goes (uniform over the sweep, so
    // every person keeps points; a cut at max_points would drop whole azimuth ranges).
    size_t eligible = 0;
    for (uint32_t id : tracks.point_track_id) eligible += id != 0 && label_of.count(id);
    const size_t stride = max_points == 0 ? 0 : std::max<size_t>(1, (eligible + max_points - 1) / max_points);
    std::string packed;
    packed.reserve(8 * std::min<size_t>(eligible, max_points));
    uint32_t count = 0;
    size_t seen = 0;
    for (size_t i = 0; i < sweep.points.size(); ++i) {
      const uint32_t id = tracks.point_track_id[i];
      if (id == 0) continue;
      auto label = label_of.find(id);
      const bool take = label != label_of.end() && stride > 0 && seen++ % stride == 0;
      const Eigen::Vector3f& p = sweep.points[i].p_in_sensor;
      const auto x = Centimetres(p.x()), y = Centimetres(p.y()), z = Centimetres(p.z());
      if (!take || !x || !y || !z || count >= max_points) {
        ++dropped;
        continue;
      }
      PutLe16(packed, static_cast<uint16_t>(*x));
      PutLe16(packed, static_cast<uint16_t>(*y));
      PutLe16(packed, static_cast<uint16_t>(*z));
      PutLe16(packed, label->second);
      ++count;
    }
    if (count > 0) {
      out.mutable_foreground()->set_count(count);
      out.mutable_foreground()->set_packed(std::move(packed));
    }
  }
  if (points_dropped) *points_dropped = dropped;
  return out;
}

LidarStreamer::LidarStreamer(LidarStreamOptions options, SweepSource source, lidar::SweepTracker tracker)
    : options_(std::move(options)), source_(std::move(source)), tracker_(std::move(tracker)) {}

LidarStreamStats LidarStreamer::stats() const {
  std::lock_guard lock(stats_mu_);
  return stats_;
}

absl::Status LidarStreamer::Run(const std::atomic<bool>& stop) {
  if (const std::string why = options_.Check(); !why.empty()) return absl::InvalidArgumentError("lidar agent: " + why);
  if (!source_ || !tracker_) return absl::InvalidArgumentError("lidar agent: a sweep source and a tracker are required");
  const std::string& id = options_.sensor_id;
  const std::function<int64_t()> clock = options_.clock ? options_.clock : [] { return NowNs(); };
  std::mt19937_64 rng(std::hash<std::string>{}(id) ^ static_cast<uint64_t>(Clock::now().time_since_epoch().count()));
  const auto started = Clock::now();
  auto backoff = options_.backoff_initial;
  uint64_t sequence = 0;
  int64_t sent_total = 0;
  bool source_done = false;
  std::mutex clock_mu;
  ClockOffsetEstimator estimator;
  auto limited = [&] {
    return (options_.max_sweeps > 0 && sent_total >= options_.max_sweeps) ||
           (options_.duration_s > 0 && Clock::now() - started >= std::chrono::duration<double>(options_.duration_s));
  };
  auto update = [&](auto&& f) {
    std::lock_guard lock(stats_mu_);
    f(stats_);
  };
  // The next sweep, tracked, as a wire message; nullopt when none this time (error or end).
  auto next_message = [&]() -> std::optional<v1::SensorMessage> {
    absl::StatusOr<lidar::LidarSweep> sweep = source_();
    if (!sweep.ok()) {
      if (sweep.status().code() == absl::StatusCode::kOutOfRange) {
        AVE_LOG(INFO) << "lidar '" << id << "': " << sweep.status().message();
        source_done = true;
      } else {
        AVE_LOG(WARNING) << "lidar '" << id << "': " << sweep.status().message();
        SleepUnlessStopped(std::chrono::milliseconds(200), stop);
      }
      return std::nullopt;
    }
    if (options_.stamp_on_arrival) sweep->t_ns = clock();
    if (!sweep->world_from_sensor && options_.world_from_sensor) sweep->world_from_sensor = options_.world_from_sensor;
    update([](LidarStreamStats& s) { ++s.sweeps_read; });
    absl::StatusOr<lidar::FootTracks> tracks = tracker_(*sweep);
    if (!tracks.ok()) {
      AVE_LOG(WARNING) << "lidar '" << id << "': tracker: " << tracks.status().message();
      update([](LidarStreamStats& s) { ++s.tracker_errors; });
      return std::nullopt;
    }
    int64_t dropped = 0;
    v1::SensorMessage message;
    *message.mutable_lidar_sweep() = SweepToWire(*sweep, *tracks, options_.send_points, options_.max_points, &dropped);
    message.mutable_lidar_sweep()->set_sequence(++sequence);
    update([&](LidarStreamStats& s) { s.points_dropped += dropped; });
    return message;
  };

  while (!stop.load() && !source_done) {
    const grpc::ChannelArguments args = stream_link::SensorChannelArgs(options_.keepalive);
    absl::StatusOr<std::shared_ptr<grpc::Channel>> channel = net::MakeChannel(options_.server, options_.tls, args);
    if (!channel.ok()) return absl::InvalidArgumentError(absl::StrCat("lidar '", id, "': ", channel.status().message()));
    auto stub = v1::SensorService::NewStub(*channel);
    grpc::ClientContext context;
    auto stream = stub->Stream(&context);
    update([](LidarStreamStats& s) { ++s.connects; });
    v1::SensorMessage hello;
    hello.mutable_hello()->set_camera_id(id);
    hello.mutable_hello()->set_token(options_.token);
    hello.mutable_hello()->set_software_version(options_.software_version);
    hello.mutable_hello()->set_kind(v1::SENSOR_KIND_ROTATING_LIDAR);
    bool healthy = stream->Write(hello);
    std::atomic<bool> acked_once{false};
    std::thread reader([&] {
      v1::SensorAck ack;
      while (stream->Read(&ack)) {
        const int64_t now = clock();
        acked_once = true;
        std::lock_guard clock_lock(clock_mu);
        estimator.Acked(ack.sequence(), ack.server_time_ns(), now);
        update([&](LidarStreamStats& s) {
          ++s.sweeps_acked;
          s.clock_offset_ns = estimator.offset_ns();
        });
      }
    });
    auto next_tick = Clock::now();
    while (healthy && !stop.load()) {
      if (limited()) {
        source_done = true;
        break;
      }
      std::optional<v1::SensorMessage> message = next_message();
      if (!message) {
        if (source_done) break;
        continue;
      }
      {
        std::lock_guard clock_lock(clock_mu);
        message->mutable_lidar_sweep()->set_clock_offset_ns(estimator.known() ? estimator.offset_ns() : 0);
        estimator.Sent(message->lidar_sweep().sequence(), clock());
      }
      if (!stream->Write(*message)) {
        update([](LidarStreamStats& s) { ++s.sweeps_dropped; });
        healthy = false;
        break;
      }
      ++sent_total;
      update([&](LidarStreamStats& s) {
        ++s.sweeps_sent;
        s.tracks_sent += message->lidar_sweep().tracks_size();
        s.points_sent += message->lidar_sweep().foreground().count();
      });
      if (acked_once) backoff = options_.backoff_initial;
      if (options_.pace_hz > 0) {
        PaceTo(next_tick, options_.pace_hz, stop);
      }
    }
    if (stop.load()) context.TryCancel();
    stream->WritesDone();
    const grpc::Status status = stream->Finish();
    reader.join();
    if (stop.load() || (source_done && status.ok())) break;
    if (!status.ok()) {
      update([&](LidarStreamStats& s) { s.last_error = status.error_message(); });
      if (IsFatal(status.error_code())) {
        AVE_LOG(ERROR) << "lidar '" << id << "': refused by the server: " << status.error_message();
        return absl::Status(static_cast<absl::StatusCode>(status.error_code()), status.error_message());
      }
      // The source's end, or --max-frames / --duration reached while the server is away: stop (as
      // the camera path does since issue 14; else the loop would reconnect without pause for ever).
      if (source_done || limited()) break;
      // Jittered exponential backoff; the tracker keeps seeing every sweep meanwhile (stable ids),
      // the sweeps themselves are dropped.
      const auto wait = JitteredWait(backoff, rng);
      AVE_LOG(WARNING) << "lidar '" << id << "': stream ended (" << status.error_message() << "); reconnecting in "
                       << wait.count() << " ms";
      const auto until = Clock::now() + wait;
      while (!stop.load() && Clock::now() < until && !limited() && !source_done) {
        if (next_message()) update([](LidarStreamStats& s) { ++s.sweeps_dropped; });
        if (options_.pace_hz > 0) {
          const auto tick = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / options_.pace_hz));
          SleepUnlessStopped(std::min<Clock::duration>(tick, until - Clock::now()), stop);
        }
      }
      backoff = std::min(options_.backoff_max, backoff * 2);
    }
  }
  const LidarStreamStats s = stats();
  AVE_LOG(INFO) << "lidar '" << id << "': stopped after " << s.sweeps_sent << " sweeps sent (" << s.tracks_sent
                << " tracks, " << s.points_sent << " points), " << s.sweeps_acked << " acked, " << s.connects
                << " connections";
  return absl::OkStatus();
}

absl::Status StreamLidar(const LidarStreamOptions& options, SweepSource source, lidar::SweepTracker tracker,
                         const std::atomic<bool>& stop, LidarStreamStats* stats) {
  LidarStreamer streamer(options, std::move(source), std::move(tracker));
  absl::Status status = streamer.Run(stop);
  if (stats) *stats = streamer.stats();
  return status;
}

}  // namespace ave
