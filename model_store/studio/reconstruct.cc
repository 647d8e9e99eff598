#include "model_store/studio/reconstruct.h"

#include "model_store/common/cpu_clock.h"

namespace ave::studio {
namespace {

double MsSince(ThreadCpuClock::time_point t0) {
  return std::chrono::duration<double, std::milli>(ThreadCpuClock::now() - t0).count();
}

}  // namespace

std::string ReconstructOptions::Check() const {
  if (std::string why = segmentation.Check(); !why.empty()) return "segmentation: " + why;
  if (std::string why = hull.Check(); !why.empty()) return "hull: " + why;
  if (std::string why = surface.Check(); !why.empty()) return "surface: " + why;
  if (std::string why = texture.Check(); !why.empty()) return "texture: " + why;
  return {};
}

absl::StatusOr<FrameSetResult> ReconstructFromSilhouettes(const std::vector<StudioCameraModel>& cameras, const std::vector<Image>& images,
                                                          std::vector<Mask> silhouettes, const ReconstructOptions& options) {
  if (const std::string why = options.Check(); !why.empty()) return absl::InvalidArgumentError("studio options: " + why);
  FrameSetResult result;
  result.silhouettes = std::move(silhouettes);
  auto t0 = ThreadCpuClock::now();
  absl::StatusOr<VoxelGrid> hull = CarveVisualHull(cameras, result.silhouettes, options.hull, &result.hull_stats);
  if (!hull.ok()) return hull.status();
  result.hull = *std::move(hull);
  result.cost.hull_ms = MsSince(t0);
  t0 = ThreadCpuClock::now();
  absl::StatusOr<SurfaceMesh> surface = ExtractSurface(result.hull, options.surface);
  if (!surface.ok()) return surface.status();
  result.surface = *std::move(surface);
  result.cost.surface_ms = MsSince(t0);
  t0 = ThreadCpuClock::now();
  absl::StatusOr<avatar::AvatarFrame> textured = TextureMesh(result.surface, cameras, images, options.texture, &result.texture_stats);
  if (!textured.ok()) return textured.status();
  result.textured = *std::move(textured);
  result.cost.texture_ms = MsSince(t0);
  return result;
}

absl::StatusOr<FrameSetResult> ReconstructFrameSet(const std::vector<StudioCameraModel>& cameras, const std::vector<Image>& images,
                                                   const std::vector<Image>& backgrounds, const ReconstructOptions& options) {
  if (const std::string why = options.Check(); !why.empty()) return absl::InvalidArgumentError("studio options: " + why);
  if (images.size() != cameras.size() || backgrounds.size() != cameras.size()) {
    return absl::InvalidArgumentError("studio: " + std::to_string(cameras.size()) + " cameras, " + std::to_string(images.size()) +
                                      " images, " + std::to_string(backgrounds.size()) + " backgrounds");
  }
  const auto t0 = ThreadCpuClock::now();
  std::vector<Mask> silhouettes;
  for (size_t c = 0; c < cameras.size(); ++c) {
    const PinholeIntrinsics& k = cameras[c].intrinsics;
    if (images[c].width != k.width || images[c].height != k.height) {
      return absl::InvalidArgumentError("camera " + cameras[c].id + ": image is " + std::to_string(images[c].width) + "x" +
                                        std::to_string(images[c].height) + ", the calibration says " + std::to_string(k.width) + "x" +
                                        std::to_string(k.height));
    }
    absl::StatusOr<Mask> m = SegmentForeground(images[c], backgrounds[c], options.segmentation, cameras[c].id);
    if (!m.ok()) return m.status();
    silhouettes.push_back(*std::move(m));
  }
  const double segment_ms = MsSince(t0);
  absl::StatusOr<FrameSetResult> result = ReconstructFromSilhouettes(cameras, images, std::move(silhouettes), options);
  if (result.ok()) result->cost.segment_ms = segment_ms;
  return result;
}

}  // namespace ave::studio
