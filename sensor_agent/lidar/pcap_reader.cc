#include "sensor_agent/lidar/pcap_reader.h"

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace ave::lidar {
namespace {

constexpr size_t kGlobalHeaderBytes = 24;
constexpr size_t kRecordHeaderBytes = 16;
constexpr uint32_t kMaxRecordBytes = 256 * 1024;
constexpr uint32_t kLinkEthernet = 1, kLinkRaw = 101, kLinkIpv4 = 228, kLinkLinuxSll = 113;

uint16_t Be16(const uint8_t* p) { return static_cast<uint16_t>((p[0] << 8) | p[1]); }

}  // namespace

uint32_t PcapReader::U32(const uint8_t* p) const {
  const uint32_t le = static_cast<uint32_t>(p[0]) | (static_cast<uint32_t>(p[1]) << 8) | (static_cast<uint32_t>(p[2]) << 16) |
                      (static_cast<uint32_t>(p[3]) << 24);
  return swapped_ ? __builtin_bswap32(le) : le;
}

absl::StatusOr<std::unique_ptr<PcapReader>> PcapReader::Open(const std::string& path) {
  std::unique_ptr<PcapReader> r(new PcapReader());
  r->path_ = path;
  r->file_.reset(std::fopen(path.c_str(), "rb"));
  if (!r->file_) return absl::NotFoundError(absl::StrCat(path, ": cannot open"));
  r->io_buffer_.resize(1 << 20);
  std::setvbuf(r->file_.get(), r->io_buffer_.data(), _IOFBF, r->io_buffer_.size());
  if (absl::Status s = r->Rewind(); !s.ok()) return s;
  return r;
}

absl::StatusOr<std::unique_ptr<PcapReader>> PcapReader::FromBytes(std::string bytes, const std::string& name) {
  // fmemopen refuses a zero-sized buffer: say what an empty file would.
  if (bytes.empty()) return absl::InvalidArgumentError(absl::StrCat(name, ": global header: 0 of 24 bytes (empty or not a pcap file)"));
  std::unique_ptr<PcapReader> r(new PcapReader());
  r->path_ = name;
  r->bytes_ = std::move(bytes);
  r->file_.reset(fmemopen(r->bytes_.data(), r->bytes_.size(), "rb"));
  if (!r->file_) return absl::InternalError(absl::StrCat(name, ": fmemopen failed"));
  if (absl::Status s = r->Rewind(); !s.ok()) return s;
  return r;
}

absl::Status PcapReader::Rewind() {
  std::rewind(file_.get());
  index_ = 0;
  uint8_t h[kGlobalHeaderBytes];
  const size_t got = std::fread(h, 1, sizeof(h), file_.get());
  if (got < 4) return absl::InvalidArgumentError(absl::StrCat(path_, ": global header: ", got, " of 24 bytes (empty or not a pcap file)"));
  const uint32_t magic = static_cast<uint32_t>(h[0]) | (h[1] << 8) | (h[2] << 16) | (static_cast<uint32_t>(h[3]) << 24);
  switch (magic) {
    case 0xA1B2C3D4: swapped_ = false; nanoseconds_ = false; break;
    case 0xA1B23C4D: swapped_ = false; nanoseconds_ = true; break;
    case 0xD4C3B2A1: swapped_ = true; nanoseconds_ = false; break;
    case 0x4D3CB2A1: swapped_ = true; nanoseconds_ = true; break;
    case 0x0A0D0D0A:
      return absl::InvalidArgumentError(absl::StrCat(path_, ": a pcapng file; convert it with `editcap -F pcap`"));
    default:
      return absl::InvalidArgumentError(absl::StrFormat("%s: global header: magic 0x%08X is not a pcap magic", path_, magic));
  }
  if (got < kGlobalHeaderBytes) return absl::InvalidArgumentError(absl::StrCat(path_, ": global header truncated: ", got, " of 24 bytes"));
  linktype_ = U32(h + 20) & 0x0FFFFFFF;
  if (linktype_ != kLinkEthernet && linktype_ != kLinkRaw && linktype_ != kLinkIpv4 && linktype_ != kLinkLinuxSll) {
    return absl::InvalidArgumentError(absl::StrCat(path_, ": global header: link type ", linktype_,
                                                   " is not Ethernet (1), raw IP (101, 228) or Linux cooked (113)"));
  }
  return absl::OkStatus();
}

absl::StatusOr<bool> PcapReader::Next(PcapRecord& record) {
  uint8_t h[kRecordHeaderBytes];
  const size_t got = std::fread(h, 1, sizeof(h), file_.get());
  const int64_t index = index_ + 1;
  if (got == 0) {
    if (std::ferror(file_.get())) return absl::DataLossError(absl::StrCat(path_, ": packet ", index, ": read error"));
    return false;
  }
  if (got < kRecordHeaderBytes) {
    return absl::DataLossError(absl::StrCat(path_, ": packet ", index, ": record header truncated (", got, " of 16 bytes)"));
  }
  const uint32_t incl = U32(h + 8), orig = U32(h + 12);
  if (incl > kMaxRecordBytes) {
    return absl::DataLossError(absl::StrCat(path_, ": packet ", index, ": captured length ", incl, " exceeds ", kMaxRecordBytes,
                                            " bytes (corrupted record header)"));
  }
  record_.resize(incl);
  const size_t data = std::fread(record_.data(), 1, incl, file_.get());
  if (data < incl) {
    return absl::DataLossError(absl::StrCat(path_, ": packet ", index, ": record truncated (", data, " of ", incl, " bytes)"));
  }
  index_ = index;
  record = PcapRecord{};
  record.index = index;
  const uint32_t frac = U32(h + 4);
  record.t_ns = static_cast<int64_t>(U32(h)) * 1'000'000'000 + (nanoseconds_ ? frac : static_cast<int64_t>(frac) * 1000);
  (void)orig;

  // Link layer -> IPv4.
  const uint8_t* p = record_.data();
  size_t n = incl;
  if (linktype_ == kLinkEthernet) {
    if (n < 14) return true;
    uint16_t ethertype = Be16(p + 12);
    size_t off = 14;
    while ((ethertype == 0x8100 || ethertype == 0x88A8) && n >= off + 4) {
      ethertype = Be16(p + off + 2);
      off += 4;
    }
    if (ethertype != 0x0800) return true;
    p += off;
    n -= off;
  } else if (linktype_ == kLinkLinuxSll) {
    if (n < 16 || Be16(p + 14) != 0x0800) return true;
    p += 16;
    n -= 16;
  }
  if (n < 20 || (p[0] >> 4) != 4) return true;
  const size_t ihl = static_cast<size_t>(p[0] & 0x0F) * 4;
  const uint16_t fragment = Be16(p + 6);
  if (ihl < 20 || n < ihl + 8 || p[9] != 17 || (fragment & 0x3FFF) != 0) return true;
  const size_t ip_total = Be16(p + 2);
  const uint8_t* udp = p + ihl;
  const size_t udp_len = Be16(udp + 4);
  if (udp_len < 8) return true;
  record.udp = true;
  record.src_port = Be16(udp);
  record.dst_port = Be16(udp + 2);
  record.payload = udp + 8;
  // The UDP length says what was sent; the capture may hold less (a snap length) or pad more.
  size_t avail = n - ihl - 8;
  if (ip_total >= ihl + 8) avail = std::min(avail, ip_total - ihl - 8);
  record.payload_size = std::min(avail, udp_len - 8);
  return true;
}

}  // namespace ave::lidar
