#pragma once
// Where a LiDAR agent's sweeps come from (issue 16), beside the camera FrameSource
// (sensor_agent/source/frame_source.h):
//   sim:SCENARIO#LIDAR  a scenario's rotating LiDAR through the simulator (sweeps generated on
//                       demand, deterministic, paced by the caller; truth attached)
//   pcap:FILE           a Velodyne capture (HDL-64E, HDL-32E, VLP-16; port 2368 data); its first
//                       and last sweeps may be partial (a capture starts and stops mid-turn)
//   udp:PORT, udp:ADDR:PORT  live Velodyne packets on a UDP socket (PORT 0: an ephemeral port)
#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include <Eigen/Core>

#include "absl/status/statusor.h"
#include "model_store/geometry/rigid3.h"
#include "sensor_agent/lidar/lidar_types.h"
#include "sensor_agent/lidar/velodyne_calibration.h"

namespace ave::lidar {

class LidarSource {
 public:
  virtual ~LidarSource() = default;
  // The next revolution. OutOfRange at the end of a finite source. A capture that turns bad
  // (truncated, corrupted, wrong model) first returns every sweep decoded before the bad packet,
  // then an error naming the file, the packet and the field.
  virtual absl::StatusOr<LidarSweep> Next() = 0;
  virtual std::string description() const = 0;
  // True when the device delivers sweeps at its own rate (udp:); false when the caller paces them.
  virtual bool live() const = 0;
  // Nominal revolutions per second: the scenario's rate; 10 (the Velodyne default) for pcap:/udp:.
  virtual double rate_hz() const = 0;
  // udp: sources: the port the socket is bound to (the ephemeral one for udp:0); 0 otherwise.
  virtual int bound_port() const { return 0; }
};

struct LidarSourceOptions {
  double sim_start_s = 0;  // scenario time of the first simulated sweep
  // Tilt of a simulated sensor (the scenario's is level): world_from_sensor's rotation.
  Eigen::Matrix3d sim_world_from_sensor_rotation = Eigen::Matrix3d::Identity();
  // Registered mounting pose of a real sensor (pcap:, udp:), attached to every sweep.
  std::optional<Rigid3d> world_from_sensor;
  // Velodyne db.xml or ROS YAML; empty: the model's built-in calibration.
  std::string calibration_file;
  VelodyneModel model = VelodyneModel::kUnknown;  // kUnknown: from the packets
  double max_range_m = 0;                         // 0: the model's
  // udp: Next() answers Unavailable after this long without a packet (the caller may call again).
  double udp_idle_timeout_s = 2;
  // Empty when usable; otherwise names the first bad field.
  std::string Check() const;
};

// Whether `spec` names a LiDAR source: pcap: and udp: do; sim:SCENARIO#ID does when the scenario
// has a rotating LiDAR with that id (the scenario knows; its cameras stay camera sources).
absl::StatusOr<bool> IsLidarSourceSpec(const std::string& spec);

absl::StatusOr<std::unique_ptr<LidarSource>> OpenLidarSource(const std::string& spec, const LidarSourceOptions& options);

class PcapReader;
// What pcap:FILE opens, for a reader opened elsewhere (PcapReader::FromBytes: tests, the fuzzer).
absl::StatusOr<std::unique_ptr<LidarSource>> OpenPcapLidarSource(std::unique_ptr<PcapReader> reader, const LidarSourceOptions& options);

// Process-wide (for executables, not libraries): keeps freed blocks of up to 64 MiB in the heap
// instead of handing them back to the kernel. A sweep's points are one ~4 MB block (HDL-64E);
// with glibc's defaults each new sweep page-faults it in again, which costs ~40 % of the decode
// (ave-bench lidar-decode). Memory stays flat: one or two sweeps' worth is kept.
void KeepSweepBuffersInProcess();

}  // namespace ave::lidar
