#include "model_store/avatar/avatar_blob.h"

#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iterator>

#include "absl/strings/str_cat.h"
#include "model_store/common/le_bytes.h"

namespace ave::avatar {
namespace {

constexpr char kMagic[4] = {'A', 'V', 'E', 'A'};
constexpr size_t kMaxNameBytes = 256;
// A sequence file is a few MB; anything past this is not one (and is not read into memory).
constexpr uint64_t kMaxBlobBytes = uint64_t{2} << 30;

std::string CheckFrame(const AvatarFrame& f, const std::string& at) {
  const size_t n = f.positions_m.size();
  if (n > UINT32_MAX) return at + ".positions_m has too many vertices";
  if (f.normals.size() != n)
    return absl::StrCat(at, ".normals has ", f.normals.size(), " entries for ", n, " positions");
  if (f.uv.size() != n) return absl::StrCat(at, ".uv has ", f.uv.size(), " entries for ", n, " positions");
  if (f.indices.size() % 3 != 0) return absl::StrCat(at, ".indices has ", f.indices.size(), " entries, not a multiple of 3");
  for (size_t i = 0; i < n; ++i) {
    if (!f.positions_m[i].allFinite()) return absl::StrCat(at, ".positions_m[", i, "] is not finite");
    if (!f.normals[i].allFinite()) return absl::StrCat(at, ".normals[", i, "] is not finite");
    const Eigen::Vector2f& uv = f.uv[i];
    if (!(uv.x() >= 0.f && uv.x() <= 1.f && uv.y() >= 0.f && uv.y() <= 1.f))
      return absl::StrCat(at, ".uv[", i, "] is outside [0, 1]");
  }
  for (size_t i = 0; i < f.indices.size(); ++i) {
    if (f.indices[i] >= n) return absl::StrCat(at, ".indices[", i, "] = ", f.indices[i], " is out of range (", n, " positions)");
  }
  if (f.atlas_width < 0 || f.atlas_height < 0 || f.atlas_width > kMaxAtlasSide || f.atlas_height > kMaxAtlasSide)
    return absl::StrCat(at, ".atlas is ", f.atlas_width, "x", f.atlas_height, ", outside 0..", kMaxAtlasSide);
  const size_t atlas_bytes = static_cast<size_t>(f.atlas_width) * static_cast<size_t>(f.atlas_height) * 3;
  if (f.atlas_rgb.size() != atlas_bytes)
    return absl::StrCat(at, ".atlas_rgb has ", f.atlas_rgb.size(), " bytes, ", f.atlas_width, "x", f.atlas_height,
                        " RGB needs ", atlas_bytes);
  return {};
}

}  // namespace

std::string CheckAvatarSequence(const AvatarSequence& s) {
  if (s.name.empty()) return "name is empty";
  if (s.name.size() > kMaxNameBytes) return absl::StrCat("name has ", s.name.size(), " bytes, at most ", kMaxNameBytes);
  for (char c : s.name) {
    if (static_cast<unsigned char>(c) < 0x20) return "name contains a control character";
  }
  if (!(std::isfinite(s.frame_period_s) && s.frame_period_s > 0))
    return absl::StrCat("frame_period_s = ", s.frame_period_s, " must be finite and > 0");
  if (!(std::isfinite(s.stride_m) && s.stride_m >= 0))
    return absl::StrCat("stride_m = ", s.stride_m, " must be finite and >= 0");
  if (s.frames.empty()) return "frames is empty (one frame at least)";
  if (s.frames.size() > UINT32_MAX) return "too many frames";
  for (size_t i = 0; i < s.frames.size(); ++i) {
    if (std::string why = CheckFrame(s.frames[i], absl::StrCat("frames[", i, "]")); !why.empty()) return why;
  }
  return {};
}

absl::StatusOr<std::string> EncodeAvatarSequence(const AvatarSequence& s, std::string_view context) {
  if (std::string why = CheckAvatarSequence(s); !why.empty())
    return absl::InvalidArgumentError(absl::StrCat(std::string(context), ": avatar sequence ", why));
  std::string out(kMagic, 4);
  bytes::PutLe<uint32_t>(out, kAvatarBlobVersion);
  bytes::PutLe<uint32_t>(out, static_cast<uint32_t>(s.name.size()));
  out += s.name;
  bytes::PutF64(out, s.frame_period_s);
  bytes::PutF64(out, s.stride_m);
  bytes::PutLe<uint32_t>(out, static_cast<uint32_t>(s.frames.size()));
  for (const AvatarFrame& f : s.frames) {
    bytes::PutLe<uint64_t>(out, f.positions_m.size());
    bytes::PutLe<uint64_t>(out, f.indices.size());
    bytes::PutLe<uint32_t>(out, static_cast<uint32_t>(f.atlas_width));
    bytes::PutLe<uint32_t>(out, static_cast<uint32_t>(f.atlas_height));
    for (const auto* arr : {&f.positions_m, &f.normals}) {
      for (const Eigen::Vector3f& v : *arr) {
        for (int i = 0; i < 3; ++i) bytes::PutF32(out, v[i]);
      }
    }
    for (const Eigen::Vector2f& v : f.uv) {
      bytes::PutF32(out, v.x());
      bytes::PutF32(out, v.y());
    }
    for (uint32_t i : f.indices) bytes::PutLe<uint32_t>(out, i);
    out.append(reinterpret_cast<const char*>(f.atlas_rgb.data()), f.atlas_rgb.size());
  }
  return out;
}

absl::StatusOr<AvatarSequence> DecodeAvatarSequence(std::string_view blob, std::string_view context) {
  bytes::LeReader r(blob);
  auto loss = [&](const std::string& why) {
    return absl::DataLossError(absl::StrCat(std::string(context), ": avatar sequence ", why, " (at byte ", r.offset(), ")"));
  };
  std::string_view magic;
  if (!r.GetBytes(4, magic) || std::memcmp(magic.data(), kMagic, 4) != 0)
    return loss("does not start with magic \"AVEA\"");
  uint32_t version = 0, name_bytes = 0, frame_count = 0;
  if (!r.Get(version)) return loss("is truncated (version)");
  if (version != kAvatarBlobVersion)
    return loss(absl::StrCat("has format version ", version, ", this build reads ", kAvatarBlobVersion));
  std::string_view name;
  if (!r.Get(name_bytes) || name_bytes > kMaxNameBytes || !r.GetBytes(name_bytes, name))
    return loss("has a truncated or oversized name");
  AvatarSequence s;
  s.name = std::string(name);
  if (!r.GetF64(s.frame_period_s) || !r.GetF64(s.stride_m) || !r.Get(frame_count)) return loss("is truncated (header)");
  // Each frame takes at least 24 bytes of counts: bound the count before reserving.
  if (frame_count > r.remaining() / 24) return loss(absl::StrCat("claims ", frame_count, " frames, more than its bytes hold"));
  s.frames.resize(frame_count);
  for (uint32_t k = 0; k < frame_count; ++k) {
    AvatarFrame& f = s.frames[k];
    uint64_t n = 0, ni = 0;
    uint32_t w = 0, h = 0;
    if (!(r.Get(n) && r.Get(ni) && r.Get(w) && r.Get(h))) return loss(absl::StrCat("is truncated (frames[", k, "] counts)"));
    if (w > static_cast<uint32_t>(kMaxAtlasSide) || h > static_cast<uint32_t>(kMaxAtlasSide))
      return loss(absl::StrCat("frames[", k, "] has an atlas of ", w, "x", h));
    // Bound every count by the bytes left before multiplying, so corrupt counts cannot overflow.
    const uint64_t left = r.remaining();
    const uint64_t atlas_bytes = uint64_t{w} * h * 3;
    if (n > left / 32 + 1 || ni > left / 4 + 1 || atlas_bytes > left || 32 * n + 4 * ni + atlas_bytes > left)
      return loss(absl::StrCat("frames[", k, "] claims ", n, " vertices, ", ni, " indices and a ", w, "x", h,
                               " atlas, more than the ", left, " bytes left"));
    f.atlas_width = static_cast<int>(w);
    f.atlas_height = static_cast<int>(h);
    f.positions_m.resize(n);
    f.normals.resize(n);
    f.uv.resize(n);
    for (auto* arr : {&f.positions_m, &f.normals}) {
      for (Eigen::Vector3f& v : *arr) {
        for (int i = 0; i < 3; ++i) r.GetF32(v[i]);
      }
    }
    for (Eigen::Vector2f& v : f.uv) {
      r.GetF32(v.x());
      r.GetF32(v.y());
    }
    f.indices.resize(ni);
    for (uint32_t& i : f.indices) r.Get(i);
    std::string_view atlas;
    r.GetBytes(atlas_bytes, atlas);
    f.atlas_rgb.assign(atlas.begin(), atlas.end());
  }
  if (r.remaining() != 0) return loss(absl::StrCat("has ", r.remaining(), " trailing bytes"));
  if (std::string why = CheckAvatarSequence(s); !why.empty())
    return absl::DataLossError(absl::StrCat(std::string(context), ": avatar sequence ", why));
  return s;
}

absl::Status WriteAvatarSequenceFile(const std::string& path, const AvatarSequence& sequence) {
  absl::StatusOr<std::string> blob = EncodeAvatarSequence(sequence, path);
  if (!blob.ok()) return blob.status();
  // Written beside the target and renamed, so a reader never sees half a file.
  const std::string tmp = path + ".part";
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) return absl::PermissionDeniedError(absl::StrCat(path, ": cannot open for writing"));
    out.write(blob->data(), static_cast<std::streamsize>(blob->size()));
    out.flush();
    if (!out) return absl::ResourceExhaustedError(absl::StrCat(path, ": write failed (disk full?)"));
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    std::remove(tmp.c_str());
    return absl::InternalError(absl::StrCat(path, ": cannot rename ", tmp, " into place"));
  }
  return absl::OkStatus();
}

absl::StatusOr<AvatarSequence> ReadAvatarSequenceFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  if (!in) return absl::NotFoundError(absl::StrCat(path, ": cannot open avatar sequence file"));
  const std::streamoff size = in.tellg();
  if (size < 0 || static_cast<uint64_t>(size) > kMaxBlobBytes)
    return absl::InvalidArgumentError(absl::StrCat(path, ": ", size, " bytes is not an avatar sequence file"));
  std::string blob(static_cast<size_t>(size), '\0');
  in.seekg(0);
  in.read(blob.data(), size);
  if (!in) return absl::DataLossError(absl::StrCat(path, ": read failed"));
  return DecodeAvatarSequence(blob, path);
}

}  // namespace ave::avatar
