// libFuzzer target (issue 14): the udp: LiDAR source itself, socket included. Each input opens
// udp:127.0.0.1:0 (OpenLidarSource, a real bound socket) and sends it datagrams over loopback;
// a reference VelodyneDecoder with the same options is fed the same datagrams directly. Byte 0
// picks the decoder options as ave_fuzz_velodyne_udp's does (bits 0-1 model unknown / HDL-64E /
// HDL-32E / VLP-16, bit 2 max range 30 m); then records, each led by a byte whose low 2 bits say:
//   0  a datagram of L = (next 2 bytes, big-endian) mod 65508 bytes (0..65507, the IPv4 UDP
//      maximum): the next byte says how many bytes follow (C, 0..255), repeated to fill it
//   1  a 1206-byte datagram from the next 1206 bytes (a shorter tail repeated to fill it)
//   2  a valid data packet written by the decoder tests' packet writer: 12 blocks 3° apart from
//      a running azimuth (a wrap every 10 packets completes a sweep), distances and intensities
//      from the next byte, the product id of the chosen model (VLP-16 when unknown)
//   3  an empty datagram
// Checks: the source returns exactly the reference's events in order: a sweep with the same
// points (every one passing CheckSweep) for each sweep the reference completes, and DataLoss
// "udp:127.0.0.1:0: packet N: <the decoder's reason>" for each datagram it refuses, N counting
// datagrams from 1, after which valid packets still make sweeps. Deterministic: the target calls
// Next() only when the reference says the datagrams sent hold an event, so Next() waits for a
// datagram that is on its way, never for time (the source's idle timeout is 60 s: reaching it
// means a datagram was lost, which fails). At most 16 datagrams are left unread in the socket
// (an empty datagram, refused, drains them), well inside its receive buffer.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <memory>
#include <string>
#include <variant>
#include <vector>

#include "model_store/common/log.h"
#include "sensor_agent/fuzz/sweep_checks.h"
#include "sensor_agent/lidar/lidar_source.h"
#include "sensor_agent/lidar/velodyne_decoder.h"
#include "sensor_agent/lidar/velodyne_test_packets.h"

namespace {

using ave::lidar::LidarSweep;
using ave::lidar::VelodyneModel;

constexpr size_t kMaxDatagram = 65507;
constexpr int kMaxUnread = 16;

[[noreturn]] void Fail(const std::string& what) {
  std::fprintf(stderr, "velodyne udp socket fuzz: %s\n", what.c_str());
  std::abort();
}

bool SamePoints(const LidarSweep& a, const LidarSweep& b) {
  if (a.rings != b.rings || a.ring_elevation_rad != b.ring_elevation_rad || a.points.size() != b.points.size()) return false;
  for (size_t i = 0; i < a.points.size(); ++i) {
    const ave::lidar::SweepPoint &p = a.points[i], &q = b.points[i];
    if (p.p_in_sensor != q.p_in_sensor || p.range_m != q.range_m || p.intensity != q.intensity || p.azimuth_rad != q.azimuth_rad ||
        p.ring != q.ring || p.return_index != q.return_index) {
      return false;
    }
  }
  return true;
}

class Sender {
 public:
  Sender() : fd_(::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0)) {
    if (fd_ < 0) Fail(std::string("socket: ") + std::strerror(errno));
  }
  void Send(int port, const std::string& datagram) const {
    sockaddr_in to{};
    to.sin_family = AF_INET;
    to.sin_port = htons(static_cast<uint16_t>(port));
    to.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    const ssize_t n = ::sendto(fd_, datagram.data(), datagram.size(), 0, reinterpret_cast<const sockaddr*>(&to), sizeof to);
    if (n != static_cast<ssize_t>(datagram.size())) {
      Fail("sendto of " + std::to_string(datagram.size()) + " bytes: " + std::strerror(errno));
    }
  }

 private:
  int fd_;
};

// Takes up to `take` bytes from the input and repeats them to exactly `want` (zeros if none).
std::string Fill(const uint8_t* data, size_t size, size_t& at, size_t take, size_t want) {
  take = std::min({take, want, size - at});
  std::string out(want, '\0');
  for (size_t i = 0; take > 0 && i < want; ++i) out[i] = static_cast<char>(data[at + i % take]);
  at += take;
  return out;
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  ave::log::MinLevel() = ave::log::Level::kWARNING;
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const Sender sender;
  if (size < 1) return 0;
  constexpr VelodyneModel kModels[] = {VelodyneModel::kUnknown, VelodyneModel::kHdl64e, VelodyneModel::kHdl32e, VelodyneModel::kVlp16};
  ave::lidar::LidarSourceOptions options;
  options.model = kModels[data[0] & 3];
  options.max_range_m = (data[0] & 4) ? 30 : 0;
  options.udp_idle_timeout_s = 60;
  const std::string spec = "udp:127.0.0.1:0";
  absl::StatusOr<std::unique_ptr<ave::lidar::LidarSource>> source = ave::lidar::OpenLidarSource(spec, options);
  if (!source.ok()) Fail("cannot open " + spec + ": " + std::string(source.status().message()));
  const int port = (*source)->bound_port();
  if (port <= 0) Fail("no bound port");

  ave::lidar::VelodyneDecoderOptions decoder_options;
  decoder_options.model = options.model;
  decoder_options.max_range_m = options.max_range_m;
  ave::lidar::VelodyneDecoder reference(decoder_options);
  const uint8_t product = options.model == VelodyneModel::kHdl32e ? 0x21 : 0x22;

  using Event = std::variant<LidarSweep, std::string>;  // a sweep, or the message of a refusal
  int64_t datagrams = 0, sweeps = 0, refused = 0;
  int unread = 0;
  int azimuth_cdeg = 0;
  uint32_t timestamp_us = 0;
  const auto deliver = [&](const std::string& datagram) {
    sender.Send(port, datagram);
    ++datagrams;
    std::vector<LidarSweep> done;
    const absl::Status s = reference.Add(reinterpret_cast<const uint8_t*>(datagram.data()), datagram.size(), 1, done);
    std::deque<Event> expected;
    if (!s.ok()) {
      if (s.message().empty()) Fail("a refusal without a message");
      expected.emplace_back(spec + ": packet " + std::to_string(datagrams) + ": " + std::string(s.message()));
    }
    for (LidarSweep& sweep : done) expected.emplace_back(std::move(sweep));
    if (expected.empty()) {
      ++unread;
      return;
    }
    unread = 0;
    for (const Event& e : expected) {
      absl::StatusOr<LidarSweep> got = (*source)->Next();
      if (const std::string* message = std::get_if<std::string>(&e)) {
        ++refused;
        if (got.ok()) Fail("datagram " + std::to_string(datagrams) + ": a sweep where the decoder refused: " + *message);
        if (got.status().code() != absl::StatusCode::kDataLoss || got.status().message() != *message) {
          Fail("datagram " + std::to_string(datagrams) + ": got '" + got.status().ToString() + "', expected DataLoss '" + *message + "'");
        }
        continue;
      }
      const LidarSweep& want = std::get<LidarSweep>(e);
      ++sweeps;
      if (!got.ok()) Fail("datagram " + std::to_string(datagrams) + ": expected a sweep, got " + got.status().ToString());
      if (!SamePoints(*got, want)) Fail("datagram " + std::to_string(datagrams) + ": the sweep differs from the decoder's");
      if (got->world_from_sensor.has_value()) Fail("a pose that was not registered");
      const double max_range_m =
          options.max_range_m > 0 ? options.max_range_m : reference.model() == VelodyneModel::kHdl64e ? 120.0 : 100.0;
      ave::lidar::fuzz::CheckSweep(*got, max_range_m, static_cast<int>(reference.calibration().lasers.size()));
    }
  };

  size_t at = 1;
  while (at < size) {
    const uint8_t kind = data[at++] & 3;
    if (kind == 0) {
      size_t length = 0;
      for (int i = 0; i < 2 && at < size; ++i) length = (length << 8) | data[at++];
      const size_t content = at < size ? data[at++] : 0;
      deliver(Fill(data, size, at, content, length % (kMaxDatagram + 1)));
    } else if (kind == 1) {
      deliver(Fill(data, size, at, ave::lidar::kVelodynePacketBytes, ave::lidar::kVelodynePacketBytes));
    } else if (kind == 2) {
      const uint8_t b = at < size ? data[at++] : 0;
      std::array<ave::lidar::testing::TestBlock, 12> blocks = ave::lidar::testing::EmptyBlocks(azimuth_cdeg, 300);
      for (ave::lidar::testing::TestBlock& block : blocks) {
        for (size_t c = 0; c < block.channels.size(); ++c) {
          block.channels[c].distance = static_cast<uint16_t>(1000 + 10 * ((b + c) & 0xFF));  // 2 to 7 m
          block.channels[c].intensity = static_cast<uint8_t>(b ^ c);
        }
      }
      azimuth_cdeg = (azimuth_cdeg + 3600) % 36000;
      timestamp_us += 1327;
      deliver(ave::lidar::testing::MakePacket(blocks, 0x37, product, timestamp_us));
    } else {
      deliver(std::string());
    }
    if (unread >= kMaxUnread) deliver(std::string());  // refused: Next() reads up to it
  }
  if (unread > 0) deliver(std::string());
  if (refused + sweeps == 0 && datagrams > 0) Fail("datagrams sent but no event");
  static const bool verbose = std::getenv("AVE_FUZZ_VERBOSE") != nullptr;  // what a seed exercises
  if (verbose) std::fprintf(stderr, "%lld datagrams: %lld sweeps, %lld refused\n", static_cast<long long>(datagrams),
                            static_cast<long long>(sweeps), static_cast<long long>(refused));
  return 0;
}
