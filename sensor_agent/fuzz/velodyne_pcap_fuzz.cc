// libFuzzer target: the input is a whole pcap file, read from memory (PcapReader::FromBytes) and
// replayed through the pcap: LiDAR source (OpenPcapLidarSource, the VelodyneDecoder) to its end.
// Checks beyond "no crash" (sanitizers): every point of every sweep passes CheckSweep; an error
// after the capture opened names the packet ("packet N: ..."), comes after every sweep decoded
// before the bad packet (the points returned equal those of the reader and decoder driven
// directly up to that packet), and stays (no sweep after it).
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>
#include <vector>

#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "model_store/common/log.h"
#include "sensor_agent/fuzz/sweep_checks.h"
#include "sensor_agent/lidar/lidar_source.h"
#include "sensor_agent/lidar/pcap_reader.h"
#include "sensor_agent/lidar/velodyne_decoder.h"

namespace {

using ave::lidar::LidarSweep;
using ave::lidar::PcapReader;
using ave::lidar::VelodyneDecoder;

constexpr char kName[] = "fuzz.pcap";

// "fuzz.pcap: packet N: ..." with N >= 1.
bool NamesThePacket(const std::string& message) {
  const std::string prefix = std::string(kName) + ": packet ";
  if (!absl::StartsWith(message, prefix)) return false;
  const std::string rest = message.substr(prefix.size());
  int64_t index = 0;
  return absl::SimpleAtoi(rest.substr(0, rest.find(':')), &index) && index >= 1;
}

// The points the pcap: source must return: the reader and decoder driven directly, stopping at the
// first bad record or packet (what Pump does, without the source's bookkeeping).
size_t ExpectedPoints(const std::string& bytes) {
  auto reader = PcapReader::FromBytes(bytes, kName);
  if (!reader.ok()) return 0;
  VelodyneDecoder decoder({});
  std::vector<LidarSweep> done;
  ave::lidar::PcapRecord record;
  while (true) {
    absl::StatusOr<bool> more = (*reader)->Next(record);
    if (!more.ok() || !*more) break;
    if (!record.udp || record.dst_port != ave::lidar::kVelodyneDataPort) continue;
    if (!decoder.Add(record.payload, record.payload_size, record.t_ns, done).ok()) break;
  }
  if (auto last = decoder.Flush()) done.push_back(*std::move(last));
  size_t points = 0;
  for (const LidarSweep& s : done) points += s.points.size();
  return points;
}

}  // namespace

// The HDL-64E-without-db.xml notice would be printed for every input.
extern "C" int LLVMFuzzerInitialize(int*, char***) {
  ave::log::MinLevel() = ave::log::Level::kWARNING;
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string bytes(reinterpret_cast<const char*>(data), size);
  auto reader = PcapReader::FromBytes(bytes, kName);
  if (!reader.ok()) return 0;  // global header: nothing decoded, no packet to name
  auto source = ave::lidar::OpenPcapLidarSource(*std::move(reader), {});
  if (!source.ok()) ave::lidar::fuzz::Fail("OpenPcapLidarSource with default options failed", 0);

  // Default options: the model and its built-in calibration come from the packets, so the laser
  // count says the model (VLP-16 16, HDL-32E 32, HDL-64E 64) and with it the maximum range.
  size_t points = 0;
  absl::Status end;
  while (true) {
    absl::StatusOr<LidarSweep> sweep = (*source)->Next();
    if (!sweep.ok()) {
      end = sweep.status();
      break;
    }
    const int rings = sweep->rings;
    if (rings != 16 && rings != 32 && rings != 64) ave::lidar::fuzz::Fail("rings is not 16, 32 or 64", rings);
    ave::lidar::fuzz::CheckSweep(*sweep, rings == 64 ? 120.0 : 100.0, rings);
    points += sweep->points.size();
  }
  if (!absl::IsOutOfRange(end) && !NamesThePacket(std::string(end.message()))) {
    std::fprintf(stderr, "error does not name the packet: %s\n", end.ToString().c_str());
    std::abort();
  }
  absl::StatusOr<LidarSweep> after = (*source)->Next();
  if (after.ok() || after.status() != end) ave::lidar::fuzz::Fail("the source went on after its end or error", after.ok());
  if (points != ExpectedPoints(bytes)) ave::lidar::fuzz::Fail("points returned differ from the decoder's up to the error", points);
  return 0;
}
