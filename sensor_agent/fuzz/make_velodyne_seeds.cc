// Writes the synthetic seeds of the Velodyne fuzz targets (VLP-16 single and dual return, HDL-32E
// in a big-endian nanosecond capture, HDL-64E upper/lower blocks, position and non-UDP records
// between data packets; calibration texts) with the test packet writer the decoder tests use.
//   build-fuzz/bin/ave_make_velodyne_seeds sensor_agent/fuzz/corpus
// The simulator's seed (sim_courtyard_*.pcap) is a cut of `ave-sim rotating-lidar` output; see
// docs/RELIABILITY.md, "Fuzzing".
#include <fstream>
#include <iostream>
#include <string>

#include "sensor_agent/lidar/velodyne_test_packets.h"

namespace {

using namespace ave::lidar::testing;

// Blocks from `start` by `step` with a return on every channel of the first `lasers` (ranges and
// intensities varying with the channel).
std::array<TestBlock, 12> Blocks(int start_cdeg, int step_cdeg, int lasers, uint16_t flag = 0xEEFF) {
  std::array<TestBlock, 12> b = EmptyBlocks(start_cdeg, step_cdeg, flag);
  for (TestBlock& block : b) {
    for (int c = 0; c < 32; ++c) {
      if (c % 16 < lasers) block.channels[c] = {static_cast<uint16_t>(1000 + 97 * c), static_cast<uint8_t>(8 * c)};
    }
  }
  return b;
}

void Write(const std::string& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary).write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::cerr << "usage: ave_make_velodyne_seeds CORPUS_DIR (writes velodyne_pcap/, velodyne_udp/, velodyne_calibration/)\n";
    return 2;
  }
  const std::string dir = argv[1];
  const int64_t t0 = 1'700'000'000'000'000'000;

  // VLP-16, strongest return, three packets across the azimuth wrap, a position packet and an ARP
  // frame between them.
  TestPcapWriter vlp16;
  vlp16.Udp(MakePacket(Blocks(35200, 40, 16)), t0);
  vlp16.Udp(std::string(512, '\0'), t0 + 100'000, 8308);
  vlp16.Raw(std::string(42, '\x06'), t0 + 200'000);
  vlp16.Udp(MakePacket(Blocks(35680, 40, 16)), t0 + 1'300'000);
  vlp16.Udp(MakePacket(Blocks(160, 40, 16)), t0 + 2'600'000);
  Write(dir + "/velodyne_pcap/vlp16_strongest_wrap.pcap", vlp16.bytes());

  // VLP-16 dual return: block pairs at one azimuth, the second pair member differing.
  TestPcapWriter dual;
  std::array<TestBlock, 12> pairs = Blocks(0, 0, 16);
  for (int b = 0; b < 12; ++b) {
    pairs[b].azimuth_cdeg = static_cast<uint16_t>((b / 2) * 40);
    if (b % 2 == 1) pairs[b].channels[3] = {4000, 250};
  }
  dual.Udp(MakePacket(pairs, 0x39, 0x22), t0);
  Write(dir + "/velodyne_pcap/vlp16_dual.pcap", dual.bytes());

  // HDL-32E in a big-endian capture with nanosecond timestamps.
  TestPcapWriter hdl32({.big_endian = true, .nanoseconds = true});
  hdl32.Udp(MakePacket(Blocks(35900, 16, 32), 0x37, 0x21), t0);
  hdl32.Udp(MakePacket(Blocks(92, 16, 32), 0x38, 0x21), t0 + 550'000);
  Write(dir + "/velodyne_pcap/hdl32e_be_ns.pcap", hdl32.bytes());

  // HDL-64E: alternating upper (0xEEFF) and lower (0xDDFF) blocks at one azimuth per pair.
  std::array<TestBlock, 12> hdl64 = Blocks(0, 0, 32);
  for (int b = 0; b < 12; ++b) {
    hdl64[b].flag = b % 2 ? 0xDDFF : 0xEEFF;
    hdl64[b].azimuth_cdeg = static_cast<uint16_t>(35950 + (b / 2) * 17) % 36000;
  }
  TestPcapWriter hdl64_pcap;
  hdl64_pcap.Udp(MakePacket(hdl64, 0, 0), t0);
  Write(dir + "/velodyne_pcap/hdl64e.pcap", hdl64_pcap.bytes());

  // UDP: an options byte, then datagrams.
  Write(dir + "/velodyne_udp/vlp16_model_from_packets", std::string(1, '\0') + MakePacket(Blocks(35680, 40, 16)) +
                                                             MakePacket(Blocks(160, 40, 16)));
  Write(dir + "/velodyne_udp/vlp16_dual_30m", std::string(1, '\x07') + MakePacket(pairs, 0x39, 0x22));
  Write(dir + "/velodyne_udp/hdl32e_then_short", std::string(1, '\x02') + MakePacket(Blocks(35900, 16, 32), 0x37, 0x21) +
                                                      std::string(100, '\xFF'));
  Write(dir + "/velodyne_udp/hdl64e", std::string(1, '\x01') + MakePacket(hdl64, 0, 0));

  // Calibration: byte 0 even for db.xml, odd for ROS YAML.
  std::string xml = std::string(1, '\0') + "<?xml version=\"1.0\"?><boost_serialization><DB><distLSB_>0.2</distLSB_><points_>";
  for (int id = 0; id < 4; ++id) {
    xml += "<item><px><id_>" + std::to_string(id) + "</id_><rotCorrection_>-5.1</rotCorrection_><vertCorrection_>" +
           std::to_string(-8 + 2 * id) +
           "</vertCorrection_><distCorrection_>111.5</distCorrection_><distCorrectionX_>1</distCorrectionX_>"
           "<vertOffsetCorrection_>21.5</vertOffsetCorrection_><horizOffsetCorrection_>-2.6</horizOffsetCorrection_></px></item>";
  }
  xml += "</points_></DB></boost_serialization>";
  Write(dir + "/velodyne_calibration/db_4_lasers.xml", xml);
  std::string yaml = "\x01lasers:\n";
  for (int id = 0; id < 4; ++id) {
    yaml += "- {dist_correction: 1.2, horiz_offset_correction: 0.026, laser_id: " + std::to_string(id) +
            ", rot_correction: -0.09, vert_correction: " + std::to_string(-0.1 + 0.05 * id) + ", vert_offset_correction: 0.2}\n";
  }
  yaml += "num_lasers: 4\ndistance_resolution: 0.002\n";
  Write(dir + "/velodyne_calibration/ros_4_lasers.yaml", yaml);
  return 0;
}
