// libFuzzer target: the udp: path's decoding, without the socket. Byte 0 picks the decoder options
// (bits 0-1: model unknown / HDL-64E / HDL-32E / VLP-16; bit 2: max_range_m 30 instead of the
// model's); the rest is cut into 1206-byte datagrams, a shorter tail being one more datagram.
// Each goes through VelodyneDecoder::Add as UdpLidarSource does: a bad datagram is rejected whole
// and decoding goes on with the next. Checks: every point of every sweep (completed, then the
// flushed one) passes CheckSweep; a rejected datagram adds no point to the sweep in progress.
#include <cstdint>
#include <string>
#include <vector>

#include "model_store/common/log.h"
#include "sensor_agent/fuzz/sweep_checks.h"
#include "sensor_agent/lidar/velodyne_decoder.h"

// The HDL-64E-without-db.xml notice would be printed for every input.
extern "C" int LLVMFuzzerInitialize(int*, char***) {
  ave::log::MinLevel() = ave::log::Level::kWARNING;
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using ave::lidar::VelodyneModel;
  if (size < 1) return 0;
  ave::lidar::VelodyneDecoderOptions options;
  constexpr VelodyneModel kModels[] = {VelodyneModel::kUnknown, VelodyneModel::kHdl64e, VelodyneModel::kHdl32e, VelodyneModel::kVlp16};
  options.model = kModels[data[0] & 3];
  options.max_range_m = (data[0] & 4) ? 30 : 0;
  ave::lidar::VelodyneDecoder decoder(options);
  std::vector<ave::lidar::LidarSweep> done;
  int64_t t_ns = 1'700'000'000'000'000'000;
  size_t points_done = 0;
  for (size_t at = 1; at < size; at += ave::lidar::kVelodynePacketBytes) {
    const size_t n = std::min(ave::lidar::kVelodynePacketBytes, size - at);
    const size_t before = done.size();
    const absl::Status s = decoder.Add(data + at, n, t_ns, done);
    t_ns += 1'000'000;
    if (!s.ok() && done.size() != before) ave::lidar::fuzz::Fail("a rejected datagram completed a sweep", done.size() - before);
    if (!s.ok() && s.message().empty()) ave::lidar::fuzz::Fail("an error without a message", 0);
    for (size_t i = before; i < done.size(); ++i) points_done += done[i].points.size();
  }
  std::optional<ave::lidar::LidarSweep> last = decoder.Flush();
  if (last) done.push_back(*std::move(last));
  if (done.empty()) return 0;
  const double max_range_m = options.max_range_m > 0 ? options.max_range_m : decoder.model() == VelodyneModel::kHdl64e ? 120.0 : 100.0;
  const int rings = static_cast<int>(decoder.calibration().lasers.size());
  for (const ave::lidar::LidarSweep& sweep : done) ave::lidar::fuzz::CheckSweep(sweep, max_range_m, rings);
  return 0;
}
