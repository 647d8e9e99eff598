#include "sensor_agent/lidar/lidar_source.h"

#include <arpa/inet.h>
#include <malloc.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <deque>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "sensor_agent/lidar/pcap_reader.h"
#include "sensor_agent/lidar/sim_sweep.h"
#include "sensor_agent/lidar/velodyne_decoder.h"
#include "sensor_agent/sim/rotating_lidar.h"
#include "sensor_agent/sim/scenario.h"

namespace ave::lidar {
namespace {


bool StartsWith(const std::string& s, const std::string& prefix) { return s.rfind(prefix, 0) == 0; }

// ---- sim:SCENARIO#LIDAR ----

class SimLidarSource final : public LidarSource {
 public:
  SimLidarSource(std::unique_ptr<sim::Scenario> scenario, const sim::RotatingLidarSpec& spec, const LidarSourceOptions& options)
      : scenario_(std::move(scenario)),
        simulator_(scenario_->world, spec, scenario_->effects, scenario_->seed, options.sim_world_from_sensor_rotation),
        options_(options),
        world_from_sensor_(Eigen::Quaterniond(options.sim_world_from_sensor_rotation), spec.position_m) {}

  absl::StatusOr<LidarSweep> Next() override {
    const double t_s = options_.sim_start_s + static_cast<double>(index_++) / simulator_.spec().rate_hz;
    LidarSweep sweep = SweepFromSimFrame(simulator_.Frame(t_s), simulator_.spec(), world_from_sensor_);
    sweep.t_ns = static_cast<int64_t>(std::llround(t_s * 1e9));
    return sweep;
  }
  std::string description() const override { return "simulated " + scenario_->name + " rotating LiDAR " + simulator_.spec().id; }
  bool live() const override { return false; }
  double rate_hz() const override { return simulator_.spec().rate_hz; }

 private:
  std::unique_ptr<sim::Scenario> scenario_;  // the simulator holds a reference to its world
  sim::RotatingLidarSimulator simulator_;
  LidarSourceOptions options_;
  Rigid3d world_from_sensor_;
  int64_t index_ = 0;
};

// ---- shared by pcap: and udp: ----

absl::StatusOr<VelodyneDecoderOptions> DecoderOptions(const LidarSourceOptions& options) {
  VelodyneDecoderOptions d;
  d.model = options.model;
  d.max_range_m = options.max_range_m;
  if (!options.calibration_file.empty()) {
    absl::StatusOr<VelodyneCalibration> c = ReadVelodyneCalibration(options.calibration_file);
    if (!c.ok()) return c.status();
    d.calibration = *std::move(c);
  }
  return d;
}

// ---- pcap:FILE ----

class PcapLidarSource final : public LidarSource {
 public:
  PcapLidarSource(std::unique_ptr<PcapReader> reader, const VelodyneDecoderOptions& decoder, const LidarSourceOptions& options)
      : reader_(std::move(reader)), decoder_(decoder), options_(options) {}

  absl::StatusOr<LidarSweep> Next() override {
    while (ready_.empty() && error_.ok() && !ended_) Pump();
    if (!ready_.empty()) {
      LidarSweep sweep = std::move(ready_.front());
      ready_.pop_front();
      sweep.world_from_sensor = options_.world_from_sensor;
      ++sweeps_;
      return sweep;
    }
    if (!error_.ok()) return error_;
    return absl::OutOfRangeError(absl::StrCat(reader_->path(), ": end of capture after ", sweeps_, " sweeps"));
  }
  std::string description() const override { return "pcap:" + reader_->path(); }
  bool live() const override { return false; }
  double rate_hz() const override { return 10; }

 private:
  // Reads records until a sweep completes, the file ends or a packet is bad. At the end or on an
  // error the sweep in progress is returned too (everything decoded before the bad packet).
  void Pump() {
    PcapRecord record;
    std::vector<LidarSweep> done;
    while (done.empty()) {
      absl::StatusOr<bool> more = reader_->Next(record);
      if (!more.ok() || !*more) {
        if (!more.ok()) error_ = more.status();
        else ended_ = true;
        if (std::optional<LidarSweep> last = decoder_.Flush()) done.push_back(*std::move(last));
        break;
      }
      if (!record.udp || record.dst_port != kVelodyneDataPort) continue;  // position packets (8308) and the rest
      absl::Status s = decoder_.Add(record.payload, record.payload_size, record.t_ns, done);
      if (!s.ok()) {
        error_ = absl::Status(s.code() == absl::StatusCode::kInvalidArgument ? absl::StatusCode::kDataLoss : s.code(),
                              absl::StrCat(reader_->path(), ": packet ", record.index, ": ", s.message()));
        if (std::optional<LidarSweep> last = decoder_.Flush()) done.push_back(*std::move(last));
        break;
      }
    }
    for (LidarSweep& s : done) ready_.push_back(std::move(s));
  }

  std::unique_ptr<PcapReader> reader_;
  VelodyneDecoder decoder_;
  LidarSourceOptions options_;
  std::deque<LidarSweep> ready_;
  absl::Status error_;
  bool ended_ = false;
  int64_t sweeps_ = 0;
};

// ---- udp:[ADDR:]PORT ----

class UdpLidarSource final : public LidarSource {
 public:
  UdpLidarSource(int fd, std::string spec, int port, const VelodyneDecoderOptions& decoder, const LidarSourceOptions& options)
      : fd_(fd), spec_(std::move(spec)), port_(port), decoder_(decoder), options_(options), buffer_(65536) {}
  ~UdpLidarSource() override { ::close(fd_); }

  absl::StatusOr<LidarSweep> Next() override {
    while (ready_.empty()) {
      pollfd p{fd_, POLLIN, 0};
      const int timeout_ms = static_cast<int>(std::ceil(options_.udp_idle_timeout_s * 1000));
      const int r = ::poll(&p, 1, timeout_ms);
      if (r < 0 && errno == EINTR) continue;
      if (r < 0) return absl::UnavailableError(absl::StrCat(spec_, ": poll: ", std::strerror(errno)));
      if (r == 0) {
        return absl::UnavailableError(absl::StrCat(spec_, ": no packet for ", options_.udp_idle_timeout_s, " s (", packets_, " so far)"));
      }
      const ssize_t n = ::recv(fd_, buffer_.data(), buffer_.size(), 0);
      if (n < 0) {
        if (errno == EINTR || errno == EAGAIN) continue;
        return absl::UnavailableError(absl::StrCat(spec_, ": recv: ", std::strerror(errno)));
      }
      ++packets_;
      const int64_t t_ns =
          std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch()).count();
      std::vector<LidarSweep> done;
      absl::Status s = decoder_.Add(buffer_.data(), static_cast<size_t>(n), t_ns, done);
      for (LidarSweep& sweep : done) ready_.push_back(std::move(sweep));
      // The bad datagram is dropped whole; the stream goes on with the next one.
      if (!s.ok()) return absl::DataLossError(absl::StrCat(spec_, ": packet ", packets_, ": ", s.message()));
    }
    LidarSweep sweep = std::move(ready_.front());
    ready_.pop_front();
    sweep.world_from_sensor = options_.world_from_sensor;
    return sweep;
  }
  std::string description() const override { return absl::StrCat(spec_, " (port ", port_, ")"); }
  bool live() const override { return true; }
  double rate_hz() const override { return 10; }
  int bound_port() const override { return port_; }

 private:
  int fd_;
  std::string spec_;
  int port_;
  VelodyneDecoder decoder_;
  LidarSourceOptions options_;
  std::vector<uint8_t> buffer_;
  std::deque<LidarSweep> ready_;
  int64_t packets_ = 0;
};

absl::StatusOr<std::unique_ptr<LidarSource>> OpenUdp(const std::string& spec, const LidarSourceOptions& options) {
  const std::string rest = spec.substr(4);
  const size_t colon = rest.rfind(':');
  const std::string addr = colon == std::string::npos ? "0.0.0.0" : rest.substr(0, colon);
  const std::string port_text = colon == std::string::npos ? rest : rest.substr(colon + 1);
  int port = 0;
  if (!absl::SimpleAtoi(port_text, &port) || port < 0 || port > 65535) {
    return absl::InvalidArgumentError(absl::StrCat("source '", spec, "': port '", port_text, "' is not in [0, 65535]"));
  }
  sockaddr_in sa{};
  sa.sin_family = AF_INET;
  sa.sin_port = htons(static_cast<uint16_t>(port));
  if (::inet_pton(AF_INET, addr.c_str(), &sa.sin_addr) != 1) {
    return absl::InvalidArgumentError(absl::StrCat("source '", spec, "': address '", addr, "' is not an IPv4 address"));
  }
  absl::StatusOr<VelodyneDecoderOptions> decoder = DecoderOptions(options);
  if (!decoder.ok()) return decoder.status();
  const int fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return absl::UnavailableError(absl::StrCat("source '", spec, "': socket: ", std::strerror(errno)));
  const int one = 1;
  ::setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof(one));
  const int rcvbuf = 8 << 20;  // an HDL-64E sends ~3 MB/s: room for a few hundred ms of lag
  ::setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &rcvbuf, sizeof(rcvbuf));
  if (::bind(fd, reinterpret_cast<sockaddr*>(&sa), sizeof(sa)) != 0) {
    const std::string why = std::strerror(errno);
    ::close(fd);
    return absl::UnavailableError(absl::StrCat("source '", spec, "': bind ", addr, ":", port, ": ", why));
  }
  socklen_t len = sizeof(sa);
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&sa), &len);
  return std::make_unique<UdpLidarSource>(fd, spec, ntohs(sa.sin_port), *decoder, options);
}

absl::StatusOr<std::pair<std::unique_ptr<sim::Scenario>, const sim::RotatingLidarSpec*>> FindSimLidar(const std::string& spec) {
  const std::string rest = spec.substr(4);
  const size_t hash = rest.find('#');
  if (hash == std::string::npos) return absl::InvalidArgumentError(absl::StrCat("source '", spec, "': expected sim:SCENARIO#ID"));
  absl::StatusOr<sim::Scenario> scenario = sim::LoadScenario(rest.substr(0, hash));
  if (!scenario.ok()) {
    return absl::Status(scenario.status().code(), absl::StrCat("source '", spec, "': ", scenario.status().message()));
  }
  auto owned = std::make_unique<sim::Scenario>(*std::move(scenario));
  const std::string id = rest.substr(hash + 1);
  const sim::RotatingLidarSpec* found = nullptr;
  for (const sim::RotatingLidarSpec& l : owned->rotating_lidars) {
    if (l.id == id) found = &l;
  }
  return std::make_pair(std::move(owned), found);
}

}  // namespace

std::string LidarSourceOptions::Check() const {
  if (!std::isfinite(sim_start_s)) return "sim_start_s must be finite";
  const Eigen::Matrix3d& r = sim_world_from_sensor_rotation;
  if (!r.allFinite() || !(r.transpose() * r).isIdentity(1e-6) || r.determinant() < 0) {
    return "sim_world_from_sensor_rotation must be a rotation";
  }
  if (world_from_sensor && (!world_from_sensor->translation.allFinite() || !world_from_sensor->rotation.coeffs().allFinite())) {
    return "world_from_sensor must be finite";
  }
  if (!(max_range_m >= 0 && max_range_m <= 1000)) return "max_range_m must be in [0, 1000]";
  if (!(udp_idle_timeout_s > 0 && udp_idle_timeout_s <= 3600)) return "udp_idle_timeout_s must be in (0, 3600]";
  return {};
}

void KeepSweepBuffersInProcess() {
  mallopt(M_MMAP_THRESHOLD, 64 << 20);
  mallopt(M_TRIM_THRESHOLD, 128 << 20);
}

absl::StatusOr<bool> IsLidarSourceSpec(const std::string& spec) {
  if (StartsWith(spec, "pcap:") || StartsWith(spec, "udp:")) return true;
  if (!StartsWith(spec, "sim:")) return false;
  auto found = FindSimLidar(spec);
  if (!found.ok()) return found.status();
  return found->second != nullptr;
}

absl::StatusOr<std::unique_ptr<LidarSource>> OpenLidarSource(const std::string& spec, const LidarSourceOptions& options) {
  if (const std::string why = options.Check(); !why.empty()) {
    return absl::InvalidArgumentError(absl::StrCat("source '", spec, "': ", why));
  }
  if (StartsWith(spec, "sim:")) {
    auto found = FindSimLidar(spec);
    if (!found.ok()) return found.status();
    if (!found->second) {
      return absl::NotFoundError(absl::StrCat("source '", spec, "': the scenario has no rotating LiDAR with that id"));
    }
    if (const std::string why = found->second->Check(); !why.empty()) {
      return absl::InvalidArgumentError(absl::StrCat("source '", spec, "': ", why));
    }
    const sim::RotatingLidarSpec lidar = *found->second;
    return std::make_unique<SimLidarSource>(std::move(found->first), lidar, options);
  }
  if (StartsWith(spec, "pcap:")) {
    absl::StatusOr<std::unique_ptr<PcapReader>> reader = PcapReader::Open(spec.substr(5));
    if (!reader.ok()) return reader.status();
    return OpenPcapLidarSource(*std::move(reader), options);
  }
  if (StartsWith(spec, "udp:")) return OpenUdp(spec, options);
  return absl::InvalidArgumentError(absl::StrCat("source '", spec, "': not a LiDAR source (sim:SCENARIO#LIDAR, pcap:FILE, udp:[ADDR:]PORT)"));
}

absl::StatusOr<std::unique_ptr<LidarSource>> OpenPcapLidarSource(std::unique_ptr<PcapReader> reader, const LidarSourceOptions& options) {
  const std::string spec = "pcap:" + reader->path();
  if (const std::string why = options.Check(); !why.empty()) {
    return absl::InvalidArgumentError(absl::StrCat("source '", spec, "': ", why));
  }
  absl::StatusOr<VelodyneDecoderOptions> decoder = DecoderOptions(options);
  if (!decoder.ok()) return decoder.status();
  return std::make_unique<PcapLidarSource>(std::move(reader), *decoder, options);
}

}  // namespace ave::lidar
