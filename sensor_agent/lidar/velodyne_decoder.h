#pragma once
// Velodyne data packets (the 1206-byte UDP payloads on port 2368) to sweeps, one per revolution
// (issue 16). Models: HDL-64E S2/S3 (upper 0xEEFF / lower 0xDDFF blocks, 64 lasers), HDL-32E
// (product id 0x21), VLP-16 (0x22; two firing sequences per block, the second's azimuth
// interpolated from the next block, per channel as the VLP-16 manual's firing timing gives).
//
// Packet: 12 blocks × (u16 flag, u16 azimuth 0.01°, 32 × (u16 distance, u8 intensity)), u32
// timestamp (µs past the hour), u8 return mode (0x37 strongest, 0x38 last, 0x39 dual), u8 product
// id. All little-endian. For the HDL-64E the last two bytes are status bytes, not checked.
// Dual return (VLP-16/HDL-32E): blocks come in pairs at one azimuth, the first holding the last
// return, the second the strongest (or the second strongest when the strongest is the last). Both
// are kept: the brighter gets return_index 0, the other 1; a pair that is the same return once.
//
// Returns with distance 0 (none), a corrected range <= 0 or beyond max_range_m are dropped; no
// point is ever NaN. A sweep is cut where the firing azimuth goes backwards (the wrap), also
// inside a packet; its t_ns is the arrival time of the packet holding its first firing. The
// HDL-64E S3's own dual-return layout is not decoded (its blocks are read as single returns).
#include <cstddef>
#include <cstdint>
#include <optional>
#include <vector>

#include "absl/status/status.h"
#include "sensor_agent/lidar/lidar_types.h"
#include "sensor_agent/lidar/velodyne_calibration.h"

namespace ave::lidar {

inline constexpr size_t kVelodynePacketBytes = 1206;
inline constexpr uint16_t kVelodyneDataPort = 2368;
inline constexpr uint16_t kVelodynePositionPort = 8308;

struct VelodyneDecoderOptions {
  // kUnknown: from the first packet (a 0xDDFF block: HDL-64E; else the product id).
  VelodyneModel model = VelodyneModel::kUnknown;
  // Unset: the model's built-in (DefaultVelodyneCalibration). A calibration that names a model
  // (16/32/64 lasers) must match the packets' product.
  std::optional<VelodyneCalibration> calibration;
  double max_range_m = 0;  // 0: the model's (VLP-16, HDL-32E 100 m; HDL-64E 120 m)
};

class VelodyneDecoder {
 public:
  explicit VelodyneDecoder(VelodyneDecoderOptions options);

  // Decodes one data packet that arrived at t_ns; sweeps it completes are appended to `done`.
  // A bad packet is rejected whole (nothing of it decoded) with an error naming the block and
  // field ("block 5: flag 0x1234 is not 0xEEFF/0xDDFF"); the caller adds the file and packet
  // index. The sweep in progress is kept, so decoding may go on with the next packet.
  absl::Status Add(const uint8_t* payload, size_t size, int64_t t_ns, std::vector<LidarSweep>& done);

  // The sweep in progress (end of a capture: it may be partial), if it holds any firing.
  std::optional<LidarSweep> Flush();

  // Known after the first packet.
  VelodyneModel model() const { return model_; }
  const VelodyneCalibration& calibration() const { return calibration_; }

 private:
  absl::Status Configure(const uint8_t* payload);
  void StartSweep(int64_t t_ns);
  void Firing(double azimuth_cdeg, int64_t t_ns, std::vector<LidarSweep>& done);
  struct FiringAzimuth {
    double rad = 0, sin = 0, cos = 1;
  };
  FiringAzimuth Azimuth(double azimuth_cdeg) const;  // azimuth_cdeg in [0, 72000)
  void Point(int laser, const FiringAzimuth& az, uint16_t raw, uint8_t intensity, uint8_t return_index);

  VelodyneDecoderOptions options_;
  VelodyneModel model_ = VelodyneModel::kUnknown;
  uint8_t product_ = 0;
  VelodyneCalibration calibration_;
  double max_range_m_ = 0;
  struct LaserTable {
    double cos_vert, sin_vert, cos_rot, sin_rot;
    uint16_t ring;
  };
  std::vector<LaserTable> lasers_;
  std::vector<float> ring_elevation_rad_;
  struct SinCosTable {
    std::vector<double> sin, cos;
  };
  static const SinCosTable& Table();
  const SinCosTable* table_;  // sin and cos per 0.01° of azimuth
  std::optional<LidarSweep> sweep_;
  double last_firing_cdeg_ = -1;
  int firings_in_sweep_ = 0;
  double last_vlp16_gap_cdeg_ = 20;  // azimuth between VLP-16 blocks (0.2° at 10 Hz) until one is seen
};

}  // namespace ave::lidar
