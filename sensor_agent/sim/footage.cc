#include "sensor_agent/sim/footage.h"

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>
#include <string_view>
#include <thread>

#include <unistd.h>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "model_store/common/le_bytes.h"
#include "model_store/common/log.h"
#include "model_store/scene/scene_file.h"
#include "sensor_agent/sim/scenario.h"

namespace ave::sim {
namespace {

constexpr char kMagic[8] = {'A', 'V', 'E', 'F', 'O', 'O', 'T', '1'};
constexpr size_t kEntryBytes = 8 + 4 + 8;
// A key text longer than this is not ours (a corrupt length field must not allocate gigabytes).
constexpr uint32_t kMaxKeyBytes = 1 << 16;

// A little-endian number at p (the caller has checked that it lies inside the file).
template <typename U>
U GetAt(const uint8_t* p) {
  bytes::LeReader reader(std::string_view(reinterpret_cast<const char*>(p), sizeof(U)));
  U value = 0;
  reader.Get(value);
  return value;
}

std::string DoubleText(double v) { return absl::StrFormat("%.17g", v); }

// Parses Text()'s lines back; DataLoss naming the line when one is malformed.
absl::StatusOr<FootageKey> ParseKeyText(const std::string& text, const std::string& path) {
  FootageKey key;
  std::istringstream in(text);
  std::string line;
  int fields = 0;
  while (std::getline(in, line)) {
    const size_t eq = line.find('=');
    if (eq == std::string::npos) return absl::DataLossError(absl::StrCat(path, ": corrupt footage key line '", line, "'"));
    const std::string name = line.substr(0, eq), value = line.substr(eq + 1);
    try {
      if (name == "scenario") key.scenario = value;
      else if (name == "scenario_hash") key.scenario_hash = std::stoull(value, nullptr, 16);
      else if (name == "camera") key.camera_id = value;
      else if (name == "width") key.width = std::stoi(value);
      else if (name == "height") key.height = std::stoi(value);
      else if (name == "fps") key.fps = std::stod(value);
      else if (name == "start_s") key.start_s = std::stod(value);
      else if (name == "jpeg_quality") key.jpeg_quality = std::stoi(value);
      else if (name == "camera_jpeg") key.camera_jpeg = value == "1";
      else continue;  // a field of a later writer: ignored
    } catch (const std::exception&) {
      return absl::DataLossError(absl::StrCat(path, ": corrupt footage key field ", name, "='", value, "'"));
    }
    ++fields;
  }
  if (fields < 9) return absl::DataLossError(absl::StrCat(path, ": footage key has ", fields, " of its 9 fields"));
  if (!(key.fps > 0) || key.width <= 0 || key.height <= 0) {
    return absl::DataLossError(absl::StrCat(path, ": footage key has a non-positive fps or image size"));
  }
  return key;
}

}  // namespace

uint64_t Fnv1a64(const void* data, size_t size, uint64_t hash) {
  const auto* p = static_cast<const uint8_t*>(data);
  for (size_t i = 0; i < size; ++i) {
    hash ^= p[i];
    hash *= 1099511628211ull;
  }
  return hash;
}

std::string FootageKey::Text() const {
  return absl::StrCat("scenario=", scenario, "\nscenario_hash=", absl::StrFormat("%016x", scenario_hash), "\ncamera=", camera_id,
                      "\nwidth=", width, "\nheight=", height, "\nfps=", DoubleText(fps), "\nstart_s=", DoubleText(start_s),
                      "\njpeg_quality=", jpeg_quality, "\ncamera_jpeg=", camera_jpeg ? 1 : 0, "\n");
}

std::string FootageKey::Mismatch(const FootageKey& file, const FootageKey& want) {
  if (file.scenario != want.scenario) return absl::StrCat("scenario ", file.scenario, ", not ", want.scenario);
  if (file.scenario_hash != want.scenario_hash) {
    return absl::StrCat("scenario ", want.scenario, " was edited since (text hash ", absl::StrFormat("%016x", file.scenario_hash),
                        ", now ", absl::StrFormat("%016x", want.scenario_hash), ")");
  }
  if (file.camera_id != want.camera_id) return absl::StrCat("camera '", file.camera_id, "', not '", want.camera_id, "'");
  if (file.width != want.width || file.height != want.height) {
    return absl::StrCat("image ", file.width, "x", file.height, ", not ", want.width, "x", want.height);
  }
  if (file.fps != want.fps) return absl::StrCat("fps ", DoubleText(file.fps), ", not ", DoubleText(want.fps));
  if (file.start_s != want.start_s) return absl::StrCat("start ", DoubleText(file.start_s), " s, not ", DoubleText(want.start_s), " s");
  if (file.camera_jpeg != want.camera_jpeg) {
    return want.camera_jpeg ? "frames encoded by the agent's encoder, not the camera's own JPEG (jpeg_artefacts)"
                            : "the camera's own JPEG, but the camera has no jpeg_artefacts effect now";
  }
  if (want.jpeg_quality != 0 && file.jpeg_quality != want.jpeg_quality) {
    return absl::StrCat("JPEG quality ", file.jpeg_quality, ", not ", want.jpeg_quality);
  }
  return "";
}

absl::StatusOr<FootageKey> MakeFootageKey(const std::string& scenario_name_or_path, const std::string& camera_id, double fps,
                                          double start_s, int jpeg_quality) {
  if (!(fps > 0 && fps <= 1000)) return absl::InvalidArgumentError(absl::StrCat("footage: fps must be in (0, 1000], not ", fps));
  if (jpeg_quality < 0 || jpeg_quality > 100) {
    return absl::InvalidArgumentError(absl::StrCat("footage: JPEG quality must be in 1..100 (0: any), not ", jpeg_quality));
  }
  absl::StatusOr<scene::ScenarioSource> source = scene::ReadScenarioSource(scenario_name_or_path);
  if (!source.ok()) return source.status();
  absl::StatusOr<Scenario> scenario = LoadScenarioText(source->text, source->label);
  if (!scenario.ok()) return scenario.status();
  const scene::CameraSpec* camera = scenario->world.FindCamera(camera_id);
  if (!camera) return absl::NotFoundError(absl::StrCat(source->label, ": no camera '", camera_id, "' to make footage of"));
  FootageKey key;
  key.scenario = source->label;
  key.scenario_hash = Fnv1a64(source->text.data(), source->text.size());
  key.camera_id = camera_id;
  key.width = camera->intrinsics.width;
  key.height = camera->intrinsics.height;
  key.fps = fps;
  key.start_s = start_s;
  key.jpeg_quality = jpeg_quality;
  const auto effects = scenario->EffectsForCamera(camera_id);  // held: Find points into it
  if (const EffectParams* jpeg = effects.Find(EffectKind::kJpegArtefacts)) {
    key.camera_jpeg = true;  // the same clamp as ApplyJpegArtefacts
    key.jpeg_quality = static_cast<int>(std::clamp(jpeg->Get("quality", 70.0), 1.0, 100.0));
  }
  return key;
}

std::vector<uint8_t> EncodeFrameJpeg(const SimImage& image, int quality) {
  std::vector<uchar> jpeg;
  const cv::Mat bgr(image.height, image.width, CV_8UC3, const_cast<uint8_t*>(image.bgr.data()));
  if (!cv::imencode(".jpg", bgr, jpeg, {cv::IMWRITE_JPEG_QUALITY, quality})) return {};
  return jpeg;
}

std::vector<uint8_t> FootageFrameBytes(const SimImage& image, int quality) {
  return image.jpeg.empty() ? EncodeFrameJpeg(image, quality) : image.jpeg;
}

absl::StatusOr<Footage> Footage::Open(const std::string& path, const FootageKey& want) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::NotFoundError(absl::StrCat(path, ": no footage file"));
  Footage footage;
  footage.path_ = path;
  footage.bytes_.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  const std::vector<uint8_t>& b = footage.bytes_;
  auto corrupt = [&](const std::string& why) { return absl::DataLossError(absl::StrCat(path, ": corrupt footage: ", why)); };
  if (b.size() < sizeof(kMagic) + 4 || std::memcmp(b.data(), kMagic, sizeof(kMagic)) != 0) {
    return corrupt("not an AVEFOOT1 file (bad magic or shorter than its header)");
  }
  size_t at = sizeof(kMagic);
  const uint32_t key_bytes = GetAt<uint32_t>(b.data() + at);
  at += 4;
  if (key_bytes > kMaxKeyBytes || b.size() < at + key_bytes + 8) return corrupt("truncated in its key");
  absl::StatusOr<FootageKey> key = ParseKeyText(std::string(b.begin() + at, b.begin() + at + key_bytes), path);
  if (!key.ok()) return key.status();
  at += key_bytes;
  if (const std::string why = FootageKey::Mismatch(*key, want); !why.empty()) {
    return absl::FailedPreconditionError(absl::StrCat(path, ": stale footage: ", why));
  }
  footage.key_ = *key;
  const uint64_t frames = GetAt<uint64_t>(b.data() + at);
  at += 8;
  if (frames == 0 || frames > (b.size() - at) / kEntryBytes) return corrupt(absl::StrCat("index of ", frames, " frames does not fit the file"));
  uint64_t expected_offset = at + frames * kEntryBytes;
  for (uint64_t k = 0; k < frames; ++k, at += kEntryBytes) {
    Entry e{GetAt<uint64_t>(b.data() + at), GetAt<uint32_t>(b.data() + at + 8)};
    const uint64_t hash = GetAt<uint64_t>(b.data() + at + 12);
    if (e.offset != expected_offset || e.size == 0 || e.offset + e.size > b.size()) {
      return corrupt(absl::StrCat("frame ", k, " lies outside the file (truncated?)"));
    }
    if (Fnv1a64(b.data() + e.offset, e.size) != hash) return corrupt(absl::StrCat("frame ", k, "'s bytes do not match their checksum"));
    expected_offset = e.offset + e.size;
    footage.index_.push_back(e);
  }
  if (expected_offset != b.size()) return corrupt(absl::StrCat(b.size() - expected_offset, " bytes after the last frame"));
  return footage;
}

std::vector<uint8_t> Footage::Jpeg(int64_t k) const {
  const Entry& e = index_.at(static_cast<size_t>(k));
  return std::vector<uint8_t>(bytes_.begin() + e.offset, bytes_.begin() + e.offset + e.size);
}

absl::Status Footage::Verify(const SimulatedCamera& camera) const {
  for (const int64_t k : {int64_t{0}, frames() - 1}) {
    const SimImage image = camera.Frame(k, TimeOf(k));
    const Entry& e = index_[k];
    const std::vector<uint8_t> fresh = FootageFrameBytes(image, key_.jpeg_quality);
    if (fresh.size() != e.size || std::memcmp(fresh.data(), bytes_.data() + e.offset, e.size) != 0) {
      return absl::FailedPreconditionError(absl::StrCat(path_, ": stale footage: frame ", k, " (t = ", DoubleText(TimeOf(k)),
                                                        " s) differs from a fresh render (the simulator changed since it was made)"));
    }
    if (frames() == 1) break;
  }
  return absl::OkStatus();
}

absl::Status WriteFootage(const std::string& path, const FootageKey& key, const SimulatedCamera& camera, int64_t frames) {
  return WriteFootage(path, key, std::vector<const SimulatedCamera*>{&camera}, frames);
}

absl::Status WriteFootage(const std::string& path, const FootageKey& key, const std::vector<const SimulatedCamera*>& cameras,
                          int64_t frames) {
  if (frames <= 0) return absl::InvalidArgumentError(absl::StrCat(path, ": footage needs at least one frame"));
  if (!(key.fps > 0)) return absl::InvalidArgumentError(absl::StrCat(path, ": footage key fps must be > 0"));
  if (key.jpeg_quality < 1 || key.jpeg_quality > 100) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": footage JPEG quality must be in 1..100, not ", key.jpeg_quality));
  }
  if (cameras.empty()) return absl::InvalidArgumentError(absl::StrCat(path, ": no camera to render footage with"));
  // Frame k is rendered by camera k % n on thread k % n (a SimulatedCamera renders one frame at a
  // time; every frame depends on (seed, k) only, so which instance renders it does not matter).
  std::vector<std::vector<uint8_t>> jpegs(static_cast<size_t>(frames));
  std::vector<absl::Status> failed(cameras.size());
  auto render = [&](size_t worker) {
    for (int64_t k = static_cast<int64_t>(worker); k < frames; k += static_cast<int64_t>(cameras.size())) {
      const SimImage image = cameras[worker]->Frame(k, key.start_s + static_cast<double>(k) / key.fps);
      if (image.width != key.width || image.height != key.height) {
        failed[worker] = absl::InvalidArgumentError(absl::StrCat(path, ": camera '", key.camera_id, "' renders ", image.width, "x",
                                                                 image.height, ", the footage key says ", key.width, "x", key.height));
        return;
      }
      if (image.jpeg.empty() == key.camera_jpeg) {
        failed[worker] = absl::InvalidArgumentError(absl::StrCat(path, ": camera '", key.camera_id, "' ",
                                                                 key.camera_jpeg ? "delivers no JPEG of its own" : "delivers its own JPEG",
                                                                 ", the footage key says otherwise"));
        return;
      }
      jpegs[static_cast<size_t>(k)] = FootageFrameBytes(image, key.jpeg_quality);
      if (jpegs[static_cast<size_t>(k)].empty()) {
        failed[worker] = absl::InternalError(absl::StrCat(path, ": JPEG encoding failed at frame ", k));
        return;
      }
    }
  };
  std::vector<std::thread> threads;
  for (size_t w = 1; w < cameras.size(); ++w) threads.emplace_back(render, w);
  render(0);
  for (std::thread& t : threads) t.join();
  for (const absl::Status& f : failed)
    if (!f.ok()) return f;
  std::string head(kMagic, sizeof(kMagic));
  const std::string key_text = key.Text();
  bytes::PutLe<uint32_t>(head, static_cast<uint32_t>(key_text.size()));
  head += key_text;
  bytes::PutLe<uint64_t>(head, static_cast<uint64_t>(frames));
  uint64_t offset = head.size() + static_cast<uint64_t>(frames) * kEntryBytes;
  for (const std::vector<uint8_t>& j : jpegs) {
    bytes::PutLe<uint64_t>(head, offset);
    bytes::PutLe<uint32_t>(head, static_cast<uint32_t>(j.size()));
    bytes::PutLe<uint64_t>(head, Fnv1a64(j.data(), j.size()));
    offset += j.size();
  }
  const std::filesystem::path target(path);
  std::error_code ec;
  if (target.has_parent_path()) std::filesystem::create_directories(target.parent_path(), ec);
  const std::string tmp = absl::StrCat(path, ".tmp.", ::getpid());
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    out.write(head.data(), static_cast<std::streamsize>(head.size()));
    for (const std::vector<uint8_t>& j : jpegs) out.write(reinterpret_cast<const char*>(j.data()), static_cast<std::streamsize>(j.size()));
    out.flush();
    if (!out) {
      std::filesystem::remove(tmp, ec);
      return absl::InternalError(absl::StrCat("cannot write footage ", tmp));
    }
  }
  std::filesystem::rename(tmp, target, ec);
  if (ec) {
    std::filesystem::remove(tmp, ec);
    return absl::InternalError(absl::StrCat("cannot move footage into place as ", path, ": ", ec.message()));
  }
  return absl::OkStatus();
}

absl::StatusOr<EnsuredFootage> EnsureFootage(const std::string& path, const FootageKey& key, const SimulatedCamera& camera,
                                             int64_t frames) {
  return EnsureFootage(path, key, std::vector<const SimulatedCamera*>{&camera}, frames);
}

absl::StatusOr<EnsuredFootage> EnsureFootage(const std::string& path, const FootageKey& key,
                                             const std::vector<const SimulatedCamera*>& cameras, int64_t frames) {
  if (cameras.empty()) return absl::InvalidArgumentError(absl::StrCat(path, ": no camera to check footage with"));
  const SimulatedCamera& camera = *cameras.front();
  EnsuredFootage result;
  absl::StatusOr<Footage> footage = Footage::Open(path, key);
  absl::Status why = footage.status();
  if (footage.ok()) {
    why = footage->Verify(camera);
    if (why.ok() && footage->frames() < frames) {
      why = absl::FailedPreconditionError(absl::StrCat(path, ": footage too short: ", footage->frames(), " frames, ", frames, " asked"));
    }
    if (why.ok()) {
      result.frames = footage->frames();
      return result;
    }
  }
  result.rendered = true;
  result.reason = std::string(why.message());
  if (!absl::IsNotFound(why)) {
    AVE_LOG(WARNING) << why.message() << "; re-rendering its " << frames << " frames";
  }
  if (absl::Status written = WriteFootage(path, key, cameras, frames); !written.ok()) return written;
  result.frames = frames;
  return result;
}

}  // namespace ave::sim
