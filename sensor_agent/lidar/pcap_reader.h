#pragma once
// A streaming reader of classic libpcap files (not pcapng): both byte orders, microsecond and
// nanosecond magic, LINKTYPE_ETHERNET (with 802.1Q tags), raw IPv4 and Linux cooked captures;
// IPv4/UDP is unwrapped so that callers see UDP payloads with their ports. One record in memory
// at a time (a long capture replays in constant memory). Errors name the file and the packet
// (1-based record index, as Wireshark numbers them) and the field.
#include <cstdint>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/statusor.h"

namespace ave::lidar {

struct PcapRecord {
  int64_t index = 0;   // 1-based
  int64_t t_ns = 0;    // capture time, since the epoch
  bool udp = false;    // an unfragmented IPv4/UDP datagram; the fields below are set only then
  uint16_t src_port = 0, dst_port = 0;
  const uint8_t* payload = nullptr;  // valid until the next call of Next()
  size_t payload_size = 0;
};

class PcapReader {
 public:
  static absl::StatusOr<std::unique_ptr<PcapReader>> Open(const std::string& path);
  // A capture already in memory (a fuzz input, a download); `name` stands for the path in errors.
  static absl::StatusOr<std::unique_ptr<PcapReader>> FromBytes(std::string bytes, const std::string& name);

  // The next record; false at the end of the file. A record cut short (a truncated file) is an
  // error naming its index.
  absl::StatusOr<bool> Next(PcapRecord& record);
  // Back to the first record (for looping a replay).
  absl::Status Rewind();
  const std::string& path() const { return path_; }

 private:
  PcapReader() = default;
  uint32_t U32(const uint8_t* p) const;

  std::string path_;
  std::unique_ptr<FILE, int (*)(FILE*)> file_{nullptr, &std::fclose};
  std::vector<char> io_buffer_;
  std::string bytes_;  // FromBytes: the capture the FILE reads (fmemopen)
  std::vector<uint8_t> record_;
  bool swapped_ = false;
  bool nanoseconds_ = false;
  uint32_t linktype_ = 0;
  int64_t index_ = 0;
};

}  // namespace ave::lidar
