#pragma once
// Pre-rendered footage of a simulated camera (issue 19): its frames rendered once, at the exact
// scenario times start_s + k / fps with every effect the scenario names for it, and JPEG-encoded
// as the agent encodes a frame (OpenCV's libjpeg at the agent's quality), in one file with an
// index. A camera whose effects end in jpeg_artefacts (the campus cameras) is stored as its own
// JPEG bytes, whose decoding is exactly the live render (so the pose front end sees the same pixels
// either way); other cameras' frames are encoded at the key's quality (lossy against the render).
// The agent's sim source plays it at the scenario's times instead of rendering each frame:
// the render is the simulator standing in for a physical camera (~33 ms a frame for the moving
// backpack camera), and a physical camera delivers its frames for free. The true poses still come
// from the scenario, not from the file.
//
// File layout (integers little-endian; the file is a cache, made and read on one machine):
//   "AVEFOOT1"                          magic and format version
//   u32 n, then n bytes of key text     FootageKey::Text(): one "name=value" line per field
//   u64 frames, then per frame          u64 offset from the file's start, u32 size, u64 FNV-1a 64 of the bytes
//   the frames' JPEG bytes, in order; nothing after the last one
// A file is used only when its key is the one asked for (scenario text hash, camera, image size,
// fps, start time), it is whole (every offset in range, every hash right) and its first and last
// frames equal a fresh render of them (a changed simulator makes old footage stale).
#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "sensor_agent/sim/camera_effects.h"

namespace ave::sim {

// FNV-1a 64 of `size` bytes (a cheap checksum for cache files, not a cryptographic hash).
uint64_t Fnv1a64(const void* data, size_t size, uint64_t hash = 14695981039346656037ull);

// What a footage file holds: valid only for these.
struct FootageKey {
  std::string scenario;        // the scenario's label, e.g. "campus.yaml"
  uint64_t scenario_hash = 0;  // Fnv1a64 of the scenario's text: any edit to the scenario changes it
  std::string camera_id;
  int width = 0, height = 0;   // the camera's output image
  double fps = 0;              // frame k is at start_s + k / fps (scene seconds)
  double start_s = 0;
  int jpeg_quality = 80;       // 1..100, the quality the frames were encoded at
  // True: the frames are the camera's own JPEG (its jpeg_artefacts effect, at that effect's
  // quality): decoded, each is bit for bit the live render.
  bool camera_jpeg = false;

  std::string Text() const;
  // Empty when `file` (read from a file) holds what `want` asks for; otherwise names the first
  // field that differs, with both values. want.jpeg_quality 0 accepts any quality.
  static std::string Mismatch(const FootageKey& file, const FootageKey& want);
};

// The key of `camera_id`'s footage in a scenario (bundled name or .yaml path); errors name the
// scenario or the camera. A camera with the jpeg_artefacts effect keeps its own JPEG at that
// effect's quality; otherwise frames are encoded at `jpeg_quality` (0: any, a key to open files
// with, not to write one).
absl::StatusOr<FootageKey> MakeFootageKey(const std::string& scenario_name_or_path, const std::string& camera_id, double fps,
                                          double start_s, int jpeg_quality);

// A frame's JPEG bytes, exactly as the agent encodes its frames (AgentStreamer).
std::vector<uint8_t> EncodeFrameJpeg(const SimImage& image, int quality);
// The bytes footage stores for a frame: the camera's own JPEG (SimImage::jpeg) when it has one,
// else EncodeFrameJpeg at `quality`.
std::vector<uint8_t> FootageFrameBytes(const SimImage& image, int quality);

class Footage {
 public:
  // Reads and checks a whole file. NotFound: no file; DataLoss: corrupt (the message names the
  // file and the check that failed); FailedPrecondition: stale (names the field of the key that
  // differs). Does not render (see Verify).
  static absl::StatusOr<Footage> Open(const std::string& path, const FootageKey& want);

  // Renders frames 0 and frames() - 1 through `camera` (at the key's times) and compares their
  // JPEG bytes with the file's; FailedPrecondition naming the file and the frame when one differs
  // (the simulator or its effects changed since the footage was made). Two renders.
  absl::Status Verify(const SimulatedCamera& camera) const;

  int64_t frames() const { return static_cast<int64_t>(index_.size()); }
  // Scene time of frame k (the key's start_s + k / fps).
  double TimeOf(int64_t k) const { return key_.start_s + static_cast<double>(k) / key_.fps; }
  const FootageKey& key() const { return key_; }
  const std::string& path() const { return path_; }
  // Frame k's JPEG bytes (0 <= k < frames()).
  std::vector<uint8_t> Jpeg(int64_t k) const;

 private:
  struct Entry {
    uint64_t offset = 0;
    uint32_t size = 0;
  };
  std::string path_;
  FootageKey key_;
  std::vector<uint8_t> bytes_;  // the whole file
  std::vector<Entry> index_;
};

// Renders frames 0 .. frames - 1 through `camera` and writes them as `path` (through a temporary
// file renamed into place, so a reader never sees half a file). `camera` must be the key's camera
// in the key's scenario (the caller's contract; Verify checks it when the file is opened).
absl::Status WriteFootage(const std::string& path, const FootageKey& key, const SimulatedCamera& camera, int64_t frames);
// The same on one thread per camera in `cameras`: each must be its own instance of the key's camera
// (a SimulatedCamera renders one frame at a time); the file is the same byte for byte.
absl::Status WriteFootage(const std::string& path, const FootageKey& key, const std::vector<const SimulatedCamera*>& cameras,
                          int64_t frames);

struct EnsuredFootage {
  bool rendered = false;  // false: the file was already good
  std::string reason;     // why it was (re-)rendered: missing, corrupt, stale, too short
  int64_t frames = 0;     // frames in the file now
};
// Opens and verifies `path`; when it is missing, corrupt, stale or holds fewer than `frames`
// frames, logs why (a WARNING line naming the file, except for a missing one) and renders it anew.
absl::StatusOr<EnsuredFootage> EnsureFootage(const std::string& path, const FootageKey& key, const SimulatedCamera& camera,
                                             int64_t frames);
// The same, rendering on one thread per camera (WriteFootage); the first checks the file.
absl::StatusOr<EnsuredFootage> EnsureFootage(const std::string& path, const FootageKey& key,
                                             const std::vector<const SimulatedCamera*>& cameras, int64_t frames);

}  // namespace ave::sim
