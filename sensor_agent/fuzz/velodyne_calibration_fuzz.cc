// libFuzzer target: Velodyne calibration text. Byte 0 picks the parser (even: db.xml, odd: ROS
// YAML), the rest is the file. Checks: an accepted calibration passes its own Check(); then an
// HDL-64E-layout packet with a return on every laser the calibration has, at azimuths 0, 359.99°
// and between and at ranges from 2 mm to the 16-bit maximum, decodes with that calibration into
// points that pass CheckSweep (finite, range in (0, 120 m], azimuth in [0, 2π), ring < lasers).
#include <cstdint>
#include <string>
#include <vector>

#include "model_store/common/log.h"
#include "sensor_agent/fuzz/sweep_checks.h"
#include "sensor_agent/lidar/velodyne_calibration.h"
#include "sensor_agent/lidar/velodyne_decoder.h"

namespace {

void PutLe16(std::string& s, uint16_t v) {
  s.push_back(static_cast<char>(v & 0xFF));
  s.push_back(static_cast<char>(v >> 8));
}

// Six upper/lower block pairs; laser ids beyond the calibration stay empty (the decoder refuses
// returns from lasers the calibration lacks).
std::string Hdl64Packet(size_t lasers) {
  constexpr uint16_t kAzimuths[6] = {0, 1, 9000, 18000, 27000, 35999};
  constexpr uint16_t kDistances[4] = {1, 500, 60000, 65535};
  std::string s;
  for (int b = 0; b < 12; ++b) {
    const bool lower = b % 2 == 1;
    PutLe16(s, lower ? 0xDDFF : 0xEEFF);
    PutLe16(s, kAzimuths[b / 2]);
    for (int c = 0; c < 32; ++c) {
      const size_t laser = (lower ? 32 : 0) + c;
      PutLe16(s, laser < lasers ? kDistances[(b + c) % 4] : 0);
      s.push_back(static_cast<char>(c * 8));
    }
  }
  s.append(6, '\0');
  return s;
}

}  // namespace

// The HDL-64E-without-db.xml notice would be printed for every input.
extern "C" int LLVMFuzzerInitialize(int*, char***) {
  ave::log::MinLevel() = ave::log::Level::kWARNING;
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  const std::string text(reinterpret_cast<const char*>(data + 1), size - 1);
  absl::StatusOr<ave::lidar::VelodyneCalibration> calibration =
      data[0] % 2 == 0 ? ave::lidar::ParseVelodyneDbXml(text, "fuzz.xml") : ave::lidar::ParseVelodyneYaml(text, "fuzz.yaml");
  if (!calibration.ok()) {
    if (calibration.status().message().empty()) ave::lidar::fuzz::Fail("an error without a message", 0);
    return 0;
  }
  if (const std::string why = calibration->Check(); !why.empty()) ave::lidar::fuzz::Fail("an accepted calibration fails Check()", 0);
  const size_t lasers = calibration->lasers.size();
  ave::lidar::VelodyneDecoderOptions options;
  options.model = ave::lidar::VelodyneModel::kHdl64e;
  options.calibration = *calibration;
  ave::lidar::VelodyneDecoder decoder(options);
  const std::string packet = Hdl64Packet(lasers);
  std::vector<ave::lidar::LidarSweep> done;
  const absl::Status s = decoder.Add(reinterpret_cast<const uint8_t*>(packet.data()), packet.size(), 0, done);
  if (!s.ok()) {
    std::fprintf(stderr, "a packet within the calibration's lasers was refused: %s\n", s.ToString().c_str());
    std::abort();
  }
  if (auto last = decoder.Flush()) done.push_back(*std::move(last));
  for (const ave::lidar::LidarSweep& sweep : done) ave::lidar::fuzz::CheckSweep(sweep, 120.0, static_cast<int>(lasers));
  return 0;
}
