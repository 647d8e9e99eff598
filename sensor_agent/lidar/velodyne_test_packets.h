#pragma once
// Test-only: writes Velodyne data packets and pcap files, so decoder tests synthesise their input
// (VLP-16, HDL-32E, HDL-64E; any byte order and timestamp resolution) instead of loading captures.
#include <array>
#include <cstdint>
#include <fstream>
#include <string>
#include <vector>

namespace ave::lidar::testing {

struct TestChannel {
  uint16_t distance = 0;  // 2 mm units, 0 = no return
  uint8_t intensity = 0;
};

struct TestBlock {
  uint16_t flag = 0xEEFF;
  uint16_t azimuth_cdeg = 0;
  std::array<TestChannel, 32> channels{};
};

inline void PutLe16(std::string& s, uint16_t v) {
  s.push_back(static_cast<char>(v & 0xFF));
  s.push_back(static_cast<char>(v >> 8));
}
inline void PutLe32(std::string& s, uint32_t v) {
  for (int i = 0; i < 4; ++i) s.push_back(static_cast<char>((v >> (8 * i)) & 0xFF));
}
inline void PutBe16(std::string& s, uint16_t v) {
  s.push_back(static_cast<char>(v >> 8));
  s.push_back(static_cast<char>(v & 0xFF));
}
inline void PutBe32(std::string& s, uint32_t v) {
  for (int i = 3; i >= 0; --i) s.push_back(static_cast<char>((v >> (8 * i)) & 0xFF));
}

// 1206 bytes: 12 blocks, u32 timestamp, return mode, product id.
inline std::string MakePacket(const std::array<TestBlock, 12>& blocks, uint8_t return_mode = 0x37, uint8_t product = 0x22,
                              uint32_t timestamp_us = 0) {
  std::string s;
  for (const TestBlock& b : blocks) {
    PutLe16(s, b.flag);
    PutLe16(s, b.azimuth_cdeg);
    for (const TestChannel& c : b.channels) {
      PutLe16(s, c.distance);
      s.push_back(static_cast<char>(c.intensity));
    }
  }
  PutLe32(s, timestamp_us);
  s.push_back(static_cast<char>(return_mode));
  s.push_back(static_cast<char>(product));
  return s;
}

// Blocks at azimuth start + i * step (mod 36000), all channels empty.
inline std::array<TestBlock, 12> EmptyBlocks(int start_cdeg, int step_cdeg, uint16_t flag = 0xEEFF) {
  std::array<TestBlock, 12> b{};
  for (int i = 0; i < 12; ++i) {
    b[i].flag = flag;
    b[i].azimuth_cdeg = static_cast<uint16_t>(((start_cdeg + i * step_cdeg) % 36000 + 36000) % 36000);
  }
  return b;
}

struct PcapOptions {
  bool big_endian = false;
  bool nanoseconds = false;
};

class TestPcapWriter {
 public:
  explicit TestPcapWriter(PcapOptions options = {}) : options_(options) {
    U32(options_.nanoseconds ? 0xA1B23C4D : 0xA1B2C3D4);
    U16(2);
    U16(4);
    U32(0);
    U32(0);
    U32(65535);
    U32(1);
  }
  // One Ethernet/IPv4/UDP record carrying `payload` to `port`.
  void Udp(const std::string& payload, int64_t t_ns, uint16_t port = 2368) {
    std::string f(12, '\xFF');
    PutBe16(f, 0x0800);
    f.push_back(0x45);
    f.push_back(0);
    PutBe16(f, static_cast<uint16_t>(28 + payload.size()));
    PutBe16(f, 0);
    PutBe16(f, 0x4000);
    f.push_back(64);
    f.push_back(17);
    PutBe16(f, 0);
    PutBe32(f, 0xC0A801C9);
    PutBe32(f, 0xFFFFFFFF);
    PutBe16(f, port);
    PutBe16(f, port);
    PutBe16(f, static_cast<uint16_t>(8 + payload.size()));
    PutBe16(f, 0);
    f += payload;
    Raw(f, t_ns);
  }
  // A record with arbitrary bytes (e.g. an ARP frame).
  void Raw(const std::string& frame, int64_t t_ns) {
    U32(static_cast<uint32_t>(t_ns / 1'000'000'000));
    U32(static_cast<uint32_t>(options_.nanoseconds ? t_ns % 1'000'000'000 : (t_ns % 1'000'000'000) / 1000));
    U32(static_cast<uint32_t>(frame.size()));
    U32(static_cast<uint32_t>(frame.size()));
    bytes_ += frame;
  }
  const std::string& bytes() const { return bytes_; }
  bool Write(const std::string& path, size_t truncate_to = std::string::npos) const {
    std::ofstream out(path, std::ios::binary);
    out.write(bytes_.data(), static_cast<std::streamsize>(std::min(truncate_to, bytes_.size())));
    return static_cast<bool>(out);
  }

 private:
  void U16(uint16_t v) { options_.big_endian ? PutBe16(bytes_, v) : PutLe16(bytes_, v); }
  void U32(uint32_t v) { options_.big_endian ? PutBe32(bytes_, v) : PutLe32(bytes_, v); }
  PcapOptions options_;
  std::string bytes_;
};

}  // namespace ave::lidar::testing
