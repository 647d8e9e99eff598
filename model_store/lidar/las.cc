#include "model_store/lidar/las.h"

#include <algorithm>
#include <bit>
#include <cctype>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>
#include <sstream>

#include "model_store/lidar/read_file.h"

namespace ave::model {
namespace {

static_assert(std::endian::native == std::endian::little, "the LAS codec assumes a little-endian host");

// Field offsets of the public header block (LAS 1.4 R15, table 3); 1.2 ends at 227, 1.3 at 235.
constexpr size_t kOffVersionMajor = 24, kOffHeaderSize = 94, kOffPointOffset = 96, kOffVlrCount = 100,
                 kOffFormat = 104, kOffRecordLength = 105, kOffLegacyCount = 107, kOffScale = 131, kOffOffset = 155,
                 kOffBounds = 179, kOffEvlrStart = 235, kOffCount64 = 247;
constexpr size_t kVlrHeaderBytes = 54;

size_t HeaderSizeFor(int minor) { return minor >= 4 ? 375 : minor == 3 ? 235 : 227; }

bool HasGpsTime(int format) { return format == 1 || format >= 3; }

template <typename T>
T Get(const char* p) {
  T v;
  std::memcpy(&v, p, sizeof(T));
  return v;
}
template <typename T>
void Put(std::string& out, T v) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  out.append(b, sizeof(T));
}
template <typename T>
void PutAt(std::string& out, size_t at, T v) {
  std::memcpy(out.data() + at, &v, sizeof(T));
}

absl::Status Bad(const std::string& name, size_t offset, const std::string& what) {
  return absl::InvalidArgumentError(name + ": byte offset " + std::to_string(offset) + ": " + what);
}

std::string Lower(std::string_view s) {
  std::string out(s);
  for (char& c : out) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return out;
}

struct Vlr {
  std::string user_id;
  uint16_t record_id = 0;
  std::string_view payload;
};

// The VLR chain from the end of the header to the point data; `out` may be null.
absl::StatusOr<size_t> WalkVlrs(std::string_view bytes, const std::string& name, size_t header_size, uint32_t vlr_count,
                                uint32_t point_offset, std::vector<Vlr>* out) {
  const char* p = bytes.data();
  size_t at = header_size;
  for (uint32_t i = 0; i < vlr_count; ++i) {
    if (at + kVlrHeaderBytes > point_offset) {
      return Bad(name, at, "VLR " + std::to_string(i) + " of " + std::to_string(vlr_count) + " runs past the point data offset " +
                               std::to_string(point_offset));
    }
    const uint16_t length = Get<uint16_t>(p + at + 20);
    if (at + kVlrHeaderBytes + length > point_offset) {
      return Bad(name, at + 20, "VLR " + std::to_string(i) + " payload of " + std::to_string(length) +
                                    " bytes runs past the point data offset " + std::to_string(point_offset));
    }
    if (out) {
      Vlr vlr;
      vlr.user_id.assign(p + at + 2, strnlen(p + at + 2, 16));
      vlr.record_id = Get<uint16_t>(p + at + 18);
      vlr.payload = bytes.substr(at + kVlrHeaderBytes, length);
      out->push_back(vlr);
    }
    at += kVlrHeaderBytes + length;
  }
  return at;
}

}  // namespace

uint16_t LasBaseRecordLength(int format) {
  switch (format) {
    case 0: return 20;
    case 1: return 28;
    case 2: return 26;
    case 3: return 34;
    case 4: return 57;  // format 1 + a 29-byte wave packet descriptor
    case 5: return 63;
    case 6: return 30;
    case 7: return 36;
    case 8: return 38;
    case 9: return 59;
    case 10: return 67;
    default: return 0;
  }
}

std::optional<std::pair<double, std::string>> LinearUnitFromEpsg(int code) {
  switch (code) {
    case 9001: return std::make_pair(1.0, std::string("metre"));
    case 9002: return std::make_pair(0.3048, std::string("foot"));
    case 9003: return std::make_pair(1200.0 / 3937.0, std::string("US survey foot"));
    case 9036: return std::make_pair(1000.0, std::string("kilometre"));
    default: return std::nullopt;
  }
}

std::optional<std::pair<double, std::string>> LinearUnitFromWkt(std::string_view wkt) {
  // The first UNIT whose name is not angular is the projected CRS's linear unit (in WKT1 the
  // GEOGCS's angular unit comes first; in a COMPD_CS the horizontal CRS precedes the vertical).
  size_t at = 0;
  while ((at = wkt.find("UNIT[", at)) != std::string_view::npos) {
    at += 5;
    const size_t q1 = wkt.find('"', at);
    if (q1 == std::string_view::npos || q1 > at + 1) continue;
    const size_t q2 = wkt.find('"', q1 + 1);
    if (q2 == std::string_view::npos) break;
    const std::string name(wkt.substr(q1 + 1, q2 - q1 - 1));
    const size_t comma = wkt.find(',', q2);
    if (comma == std::string_view::npos) break;
    const std::string lname = Lower(name);
    if (lname.find("degree") != std::string::npos || lname.find("radian") != std::string::npos ||
        lname.find("grad") != std::string::npos || lname.find("arc") != std::string::npos) {
      continue;
    }
    std::istringstream number(std::string(wkt.substr(comma + 1, 32)));
    double factor = 0;
    if (number >> factor && std::isfinite(factor) && factor > 0) return std::make_pair(factor, name);
  }
  return std::nullopt;
}

absl::StatusOr<LasLayout> ParseLasLayout(std::string_view bytes, const std::string& name) {
  const char* p = bytes.data();
  const size_t size = bytes.size();
  if (size < 4 || std::memcmp(p, "LASF", 4) != 0) return Bad(name, 0, "not a LAS file (no 'LASF' signature)");
  if (size < 227) {
    return Bad(name, size, "truncated header: the file ends after " + std::to_string(size) + " bytes, a LAS header needs 227");
  }
  LasLayout layout;
  LasHeaderInfo& info = layout.info;
  const int major = static_cast<uint8_t>(p[kOffVersionMajor]);
  const int minor = static_cast<uint8_t>(p[kOffVersionMajor + 1]);
  if (major != 1 || minor < 2 || minor > 4) {
    return Bad(name, kOffVersionMajor, "LAS version " + std::to_string(major) + "." + std::to_string(minor) +
                                           " is not supported (1.2-1.4)");
  }
  info.version_minor = static_cast<uint8_t>(minor);
  const uint16_t header_size = Get<uint16_t>(p + kOffHeaderSize);
  if (header_size < HeaderSizeFor(minor)) {
    return Bad(name, kOffHeaderSize, "header size " + std::to_string(header_size) + " is below the " +
                                         std::to_string(HeaderSizeFor(minor)) + " bytes LAS 1." + std::to_string(minor) + " needs");
  }
  if (size < header_size) {
    return Bad(name, size, "truncated header: the file ends after " + std::to_string(size) + " bytes, the header declares " +
                               std::to_string(header_size));
  }
  const uint32_t point_offset = Get<uint32_t>(p + kOffPointOffset);
  if (point_offset < header_size || point_offset > size) {
    return Bad(name, kOffPointOffset, "offset to point data " + std::to_string(point_offset) + " lies outside [" +
                                          std::to_string(header_size) + ", " + std::to_string(size) + "]");
  }
  // Bit 7 of the format byte marks LAZ compression (laszip convention).
  const uint8_t format_byte = static_cast<uint8_t>(p[kOffFormat]);
  if (format_byte & 0x80) return Bad(name, kOffFormat, "compressed (LAZ) point data is not supported");

  info.point_format = format_byte;
  const uint16_t base_length = LasBaseRecordLength(format_byte);
  if (base_length == 0) {
    return Bad(name, kOffFormat, "unknown or unsupported point data record format " + std::to_string(format_byte) +
                                     " (supported: 0-10)");
  }
  info.record_length = Get<uint16_t>(p + kOffRecordLength);
  if (info.record_length < base_length) {
    return Bad(name, kOffRecordLength, "point record length " + std::to_string(info.record_length) + " is shorter than the " +
                                           std::to_string(base_length) + " bytes format " + std::to_string(format_byte) + " needs");
  }
  const uint32_t legacy_count = Get<uint32_t>(p + kOffLegacyCount);
  uint64_t count = legacy_count;
  size_t count_field = kOffLegacyCount;
  uint64_t evlr_start = 0;
  if (minor >= 4) {
    const uint64_t count64 = Get<uint64_t>(p + kOffCount64);
    if (count64 != 0 || format_byte >= 6) {
      count = count64;
      count_field = kOffCount64;
    }
    if (legacy_count != 0 && count64 != legacy_count) {
      return Bad(name, kOffLegacyCount, "legacy point count " + std::to_string(legacy_count) +
                                            " disagrees with the 64-bit count " + std::to_string(count64));
    }
    evlr_start = Get<uint64_t>(p + kOffEvlrStart);
  }
  info.point_count = count;
  for (int i = 0; i < 3; ++i) {
    info.scale[i] = Get<double>(p + kOffScale + 8 * i);
    info.offset[i] = Get<double>(p + kOffOffset + 8 * i);
    if (!std::isfinite(info.scale[i]) || info.scale[i] == 0) {
      return Bad(name, kOffScale + 8 * i, "scale factor " + std::to_string(info.scale[i]) + " must be finite and non-zero");
    }
    if (!std::isfinite(info.offset[i])) return Bad(name, kOffOffset + 8 * i, "offset must be finite");
  }
  // Point data must fit the file exactly, up to the extended VLRs (1.4) when there are any.
  const uint64_t data_end_limit = evlr_start != 0 ? evlr_start : size;
  if (evlr_start != 0 && (evlr_start < point_offset || evlr_start > size)) {
    return Bad(name, kOffEvlrStart, "start of the extended VLRs " + std::to_string(evlr_start) + " lies outside the file");
  }
  const uint64_t available = data_end_limit - point_offset;
  if (count > available / info.record_length) {
    return Bad(name, size, "truncated point data: the header (byte " + std::to_string(count_field) + ") declares " +
                               std::to_string(count) + " points of " + std::to_string(info.record_length) +
                               " bytes from byte " + std::to_string(point_offset) + ", but only " +
                               std::to_string(available / info.record_length) + " whole records fit");
  }
  if (available - count * info.record_length >= info.record_length) {
    return Bad(name, point_offset + count * info.record_length,
               "the header (byte " + std::to_string(count_field) + ") declares " + std::to_string(count) + " points but " +
                   std::to_string(available / info.record_length) + " records of " + std::to_string(info.record_length) +
                   " bytes follow");
  }
  const uint32_t vlr_count = Get<uint32_t>(p + kOffVlrCount);
  absl::StatusOr<size_t> vlrs_end = WalkVlrs(bytes, name, header_size, vlr_count, point_offset, nullptr);
  if (!vlrs_end.ok()) return vlrs_end.status();
  layout.header_size = header_size;
  layout.point_offset = point_offset;
  layout.vlr_count = vlr_count;
  layout.evlr_start = evlr_start;
  layout.vlrs_end = *vlrs_end;
  return layout;
}

absl::StatusOr<PointCloud> ParseLas(std::string_view bytes, const std::string& name, const LasReadOptions& options,
                                    LasHeaderInfo* info_out) {
  absl::StatusOr<LasLayout> layout = ParseLasLayout(bytes, name);
  if (!layout.ok()) return layout.status();
  const char* p = bytes.data();
  LasHeaderInfo info = layout->info;
  const uint64_t count = info.point_count;
  const uint8_t format_byte = info.point_format;
  const uint32_t point_offset = layout->point_offset;

  // VLRs between the header and the point data: the CRS and its unit.
  std::vector<Vlr> vlrs;
  if (absl::StatusOr<size_t> end = WalkVlrs(bytes, name, layout->header_size, layout->vlr_count, point_offset, &vlrs); !end.ok()) {
    return end.status();
  }

  PointCloud cloud;
  double unit_xy = 1, unit_z = 1;
  info.unit_source = "default";
  for (const Vlr& vlr : vlrs) {
    if (vlr.user_id != "LASF_Projection") continue;
    if (vlr.record_id == 2112) {
      const std::string_view text(vlr.payload.data(), strnlen(vlr.payload.data(), vlr.payload.size()));
      if (auto unit = LinearUnitFromWkt(text)) {
        unit_xy = unit_z = unit->first;
        cloud.unit_name = unit->second;
        info.unit_source = "wkt";
      }
    } else if (vlr.record_id == 34735 && vlr.payload.size() >= 8 && info.unit_source != "wkt") {
      // GeoKeyDirectoryTag: 4 shorts of header, then (key, location, count, value) entries.
      const uint16_t keys = Get<uint16_t>(vlr.payload.data() + 6);
      for (uint16_t k = 0; k < keys && 8 + 8 * (static_cast<size_t>(k) + 1) <= vlr.payload.size(); ++k) {
        const char* e = vlr.payload.data() + 8 + 8 * k;
        const uint16_t key = Get<uint16_t>(e), location = Get<uint16_t>(e + 2), value = Get<uint16_t>(e + 6);
        if (location != 0) continue;
        const auto unit = LinearUnitFromEpsg(value);
        if (!unit) continue;
        if (key == 3076) {  // ProjLinearUnitsGeoKey
          unit_xy = unit_z = unit->first;  // keys are sorted: a VerticalUnitsGeoKey below overrides z
          cloud.unit_name = unit->second;
          info.unit_source = "geotiff";
        } else if (key == 4099) {  // VerticalUnitsGeoKey
          unit_z = unit->first;
        }
      }
    }
  }
  if (options.unit_to_metres) {
    if (!std::isfinite(*options.unit_to_metres) || *options.unit_to_metres <= 0) {
      return absl::InvalidArgumentError(name + ": unit override must be finite and > 0");
    }
    unit_xy = unit_z = *options.unit_to_metres;
    cloud.unit_name = "override";
    info.unit_source = "override";
  }
  cloud.unit_to_metres = unit_xy;
  const Eigen::Vector3d unit(unit_xy, unit_xy, unit_z);

  // Local origin (file units): the header offset when the header's bounds lie within 10 km of
  // it (the usual case), else the bounds' centre; whole units, so local values stay exact.
  Eigen::Vector3d lo, hi;
  for (int i = 0; i < 3; ++i) {
    hi[i] = Get<double>(p + kOffBounds + 16 * i);
    lo[i] = Get<double>(p + kOffBounds + 16 * i + 8);
  }
  Eigen::Vector3d origin_units = info.offset.array().round();
  const bool bounds_ok = lo.allFinite() && hi.allFinite() && (hi - lo).minCoeff() >= 0;
  if (bounds_ok && ((lo - info.offset).cwiseAbs().maxCoeff() > 1e4 || (hi - info.offset).cwiseAbs().maxCoeff() > 1e4)) {
    const Eigen::Vector3d centre = (0.5 * lo + 0.5 * hi).array().round();
    if (centre.allFinite()) origin_units = centre;
  }
  cloud.origin = origin_units.cwiseProduct(unit);
  if (!cloud.origin.allFinite()) {
    // A finite header offset or bounds centre times a linear unit can still overflow.
    return absl::InvalidArgumentError(name + ": the local origin (header offset or bounds centre x linear unit " +
                                      std::to_string(unit_xy) + ") is not finite");
  }
  // world - origin = (X * scale + (offset - origin)) * unit: no two large numbers meet.
  const Eigen::Vector3d shift = info.offset - origin_units;

  const int f = format_byte;
  const bool extended = f >= 6;
  cloud.xyz.reserve(count);
  cloud.intensity.reserve(count);
  cloud.classification.reserve(count);
  cloud.point_source_id.reserve(count);
  cloud.return_number.reserve(count);
  cloud.number_of_returns.reserve(count);
  if (HasGpsTime(f)) cloud.gps_time.reserve(count);
  const char* record = p + point_offset;
  for (uint64_t k = 0; k < count; ++k, record += info.record_length) {
    Eigen::Vector3d local;
    for (int i = 0; i < 3; ++i) local[i] = (Get<int32_t>(record + 4 * i) * info.scale[i] + shift[i]) * unit[i];
    if (!local.allFinite() || local.cwiseAbs().maxCoeff() > 1e7) {
      if (cloud.rejected_non_finite++ == 0) {  // from now on points and records differ: say which is which
        cloud.record_index.resize(cloud.xyz.size());
        for (size_t i = 0; i < cloud.record_index.size(); ++i) cloud.record_index[i] = i;
      }
      continue;
    }
    if (cloud.rejected_non_finite) cloud.record_index.push_back(k);
    cloud.xyz.push_back(local.cast<float>());
    cloud.intensity.push_back(Get<uint16_t>(record + 12));
    const uint8_t returns = static_cast<uint8_t>(record[14]);
    if (extended) {
      cloud.return_number.push_back(returns & 0x0F);
      cloud.number_of_returns.push_back(returns >> 4);
      cloud.classification.push_back(static_cast<uint8_t>(record[16]));
      cloud.point_source_id.push_back(Get<uint16_t>(record + 20));
      cloud.gps_time.push_back(Get<double>(record + 22));
    } else {
      cloud.return_number.push_back(returns & 0x07);
      cloud.number_of_returns.push_back((returns >> 3) & 0x07);
      cloud.classification.push_back(static_cast<uint8_t>(record[15]) & 0x1F);
      cloud.point_source_id.push_back(Get<uint16_t>(record + 18));
      if (HasGpsTime(f)) cloud.gps_time.push_back(Get<double>(record + 20));
    }
  }
  cloud.source.format = "las";
  cloud.source.size_bytes = bytes.size();
  cloud.source.fingerprint = Fingerprint64(bytes);
  if (info_out) *info_out = info;
  return cloud;
}

absl::StatusOr<PointCloud> ReadLas(const std::string& path, const LasReadOptions& options, LasHeaderInfo* info) {
  absl::StatusOr<std::string> bytes = ReadWholeFile(path);
  if (!bytes.ok()) return bytes.status();
  absl::StatusOr<PointCloud> cloud = ParseLas(*bytes, path, options, info);
  if (cloud.ok()) cloud->source.path = path;
  return cloud;
}

absl::StatusOr<std::string> EncodeLas(const PointCloud& cloud, const std::vector<uint8_t>& classification,
                                      const LasWriteOptions& options) {
  const int f = options.point_format;
  const uint16_t base = LasBaseRecordLength(f);
  if (base == 0) return absl::InvalidArgumentError("LAS writer: point format " + std::to_string(f) + " is not supported");
  if (options.version_minor < 2 || options.version_minor > 4) return absl::InvalidArgumentError("LAS writer: version 1.2-1.4 only");
  if (f >= 6 && options.version_minor < 4) return absl::InvalidArgumentError("LAS writer: formats 6-10 need LAS 1.4");
  if (f >= 4 && options.version_minor < 3) return absl::InvalidArgumentError("LAS writer: formats 4 and 5 need LAS 1.3");
  if (!(options.scale > 0) || !(options.unit_to_metres > 0)) return absl::InvalidArgumentError("LAS writer: scale and unit must be > 0");
  const size_t n = cloud.size();
  if (!classification.empty() && classification.size() != n) {
    return absl::InvalidArgumentError("LAS writer: " + std::to_string(classification.size()) + " classes for " +
                                      std::to_string(n) + " points");
  }
  auto attr = [n](const auto& v, size_t k) { return v.size() == n ? v[k] : typename std::decay_t<decltype(v)>::value_type{}; };

  std::string vlrs;
  uint32_t vlr_count = 0;
  auto add_vlr = [&](uint16_t record_id, const std::string& payload) {
    Put<uint16_t>(vlrs, 0);
    std::string user = "LASF_Projection";
    user.resize(16, '\0');
    vlrs += user;
    Put<uint16_t>(vlrs, record_id);
    Put<uint16_t>(vlrs, static_cast<uint16_t>(payload.size()));
    vlrs.append(32, '\0');
    vlrs += payload;
    ++vlr_count;
  };
  if (!options.wkt.empty()) add_vlr(2112, options.wkt + '\0');
  if (options.geotiff_linear_unit) {
    std::string keys;
    for (uint16_t v : {uint16_t{1}, uint16_t{1}, uint16_t{0}, uint16_t{1}, uint16_t{3076}, uint16_t{0}, uint16_t{1},
                       static_cast<uint16_t>(*options.geotiff_linear_unit)}) {
      Put<uint16_t>(keys, v);
    }
    add_vlr(34735, keys);
  }

  // Coordinates in file units; the offset is the origin in file units, rounded.
  const double unit = options.unit_to_metres;
  const Eigen::Vector3d offset = (cloud.origin / unit).array().round();
  const Eigen::Vector3d shift = cloud.origin / unit - offset;
  const uint16_t record_length = static_cast<uint16_t>(base + options.extra_bytes);
  const size_t header_size = HeaderSizeFor(options.version_minor);
  std::string out(header_size, '\0');
  std::memcpy(out.data(), "LASF", 4);
  PutAt<uint16_t>(out, 6, f >= 6 ? 0x0010 : 0);
  out[24] = 1;
  out[25] = static_cast<char>(options.version_minor);
  std::memcpy(out.data() + 58, "ave-model", 9);
  PutAt<uint16_t>(out, kOffHeaderSize, static_cast<uint16_t>(header_size));
  PutAt<uint32_t>(out, kOffPointOffset, static_cast<uint32_t>(header_size + vlrs.size()));
  PutAt<uint32_t>(out, kOffVlrCount, vlr_count);
  out[kOffFormat] = static_cast<char>(f);
  PutAt<uint16_t>(out, kOffRecordLength, record_length);
  if (f < 6) PutAt<uint32_t>(out, kOffLegacyCount, static_cast<uint32_t>(std::min<size_t>(n, UINT32_MAX)));
  if (options.version_minor >= 4) PutAt<uint64_t>(out, kOffCount64, n);
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(INFINITY), hi = -lo;
  std::string records;
  records.reserve(n * record_length);
  for (size_t k = 0; k < n; ++k) {
    const Eigen::Vector3d local = cloud.xyz[k].cast<double>() / unit + shift;
    for (int i = 0; i < 3; ++i) {
      const double q = std::round(local[i] / options.scale);
      if (!(std::abs(q) < 2147483647.0)) {
        return absl::InvalidArgumentError("LAS writer: point " + std::to_string(k) + " does not fit the int32 range at scale " +
                                          std::to_string(options.scale));
      }
      Put<int32_t>(records, static_cast<int32_t>(q));
      lo[i] = std::min(lo[i], offset[i] + q * options.scale);
      hi[i] = std::max(hi[i], offset[i] + q * options.scale);
    }
    Put<uint16_t>(records, attr(cloud.intensity, k));
    const uint8_t ret = std::max<uint8_t>(1, attr(cloud.return_number, k));
    const uint8_t nret = std::max<uint8_t>(ret, attr(cloud.number_of_returns, k));
    const uint8_t cls = classification.empty() ? attr(cloud.classification, k) : classification[k];
    const uint16_t source = attr(cloud.point_source_id, k);
    const double gps = attr(cloud.gps_time, k);
    if (f >= 6) {
      Put<uint8_t>(records, static_cast<uint8_t>((ret & 0x0F) | (nret << 4)));
      Put<uint8_t>(records, 0);
      Put<uint8_t>(records, cls);
      Put<uint8_t>(records, 0);    // user data
      Put<int16_t>(records, 0);    // scan angle
      Put<uint16_t>(records, source);
      Put<double>(records, gps);
      records.append(base - 30, '\0');  // RGB (7), RGB + NIR (8), wave packet (9, 10)
    } else {
      Put<uint8_t>(records, static_cast<uint8_t>((ret & 0x07) | ((nret & 0x07) << 3)));
      Put<uint8_t>(records, static_cast<uint8_t>(std::min<uint8_t>(cls, 31)));
      Put<int8_t>(records, 0);   // scan angle rank
      Put<uint8_t>(records, 0);  // user data
      Put<uint16_t>(records, source);
      if (HasGpsTime(f)) Put<double>(records, gps);
      records.append(base - (HasGpsTime(f) ? 28 : 20), '\0');  // RGB (2, 3), wave packet (4, 5)
    }
    records.append(options.extra_bytes, '\0');
  }
  for (int i = 0; i < 3; ++i) {
    PutAt<double>(out, kOffScale + 8 * i, options.scale);
    PutAt<double>(out, kOffOffset + 8 * i, offset[i]);
    PutAt<double>(out, kOffBounds + 16 * i, n ? hi[i] : offset[i]);
    PutAt<double>(out, kOffBounds + 16 * i + 8, n ? lo[i] : offset[i]);
  }
  out += vlrs;
  out += records;
  return out;
}

absl::Status WriteLas(const PointCloud& cloud, const std::vector<uint8_t>& classification, const std::string& path,
                      const LasWriteOptions& options) {
  absl::StatusOr<std::string> bytes = EncodeLas(cloud, classification, options);
  if (!bytes.ok()) return bytes.status();
  return WriteWholeFile(path, *bytes);
}

}  // namespace ave::model
