#include "model_store/studio/photo_carve.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace ave::studio {

std::string PhotoCarveOptions::Check() const {
  if (passes < 0 || passes > 64) return "passes must be in [0, 64]";
  if (!(max_std_levels > 0)) return "max_std_levels must be > 0";
  if (min_cameras < 2) return "min_cameras must be >= 2";
  return {};
}

absl::StatusOr<int64_t> PhotoCarve(VoxelGrid& grid, const std::vector<StudioCameraModel>& cameras, const std::vector<Image>& images,
                                   const PhotoCarveOptions& options) {
  if (const std::string why = options.Check(); !why.empty()) return absl::InvalidArgumentError("photo carve options: " + why);
  if (images.size() != cameras.size()) {
    return absl::InvalidArgumentError("photo carve: " + std::to_string(cameras.size()) + " cameras but " + std::to_string(images.size()) + " images");
  }
  for (size_t c = 0; c < cameras.size(); ++c) {
    const PinholeIntrinsics& k = cameras[c].intrinsics;
    if (images[c].width != k.width || images[c].height != k.height || images[c].bgr.size() != 3 * static_cast<size_t>(k.width) * k.height) {
      return absl::InvalidArgumentError("photo carve: camera " + cameras[c].id + ": image is " + std::to_string(images[c].width) + "x" +
                                        std::to_string(images[c].height) + ", the calibration says " + std::to_string(k.width) + "x" +
                                        std::to_string(k.height));
    }
  }
  struct Cam {
    Eigen::Matrix3f r;
    Eigen::Vector3f t;
    float fx, fy, cx, cy;
    int w, h;
    std::vector<float> depth;
  };
  std::vector<Cam> cams;
  for (const StudioCameraModel& c : cameras) {
    const Rigid3d cw = c.world_from_camera.Inverse();
    const PinholeIntrinsics& k = c.intrinsics;
    cams.push_back({cw.rotation.toRotationMatrix().cast<float>(), cw.translation.cast<float>(), static_cast<float>(k.fx),
                    static_cast<float>(k.fy), static_cast<float>(k.cx), static_cast<float>(k.cy), k.width, k.height, {}});
  }
  const int nx = grid.size.x(), ny = grid.size.y(), nz = grid.size.z();
  auto occ = [&](int x, int y, int z) {
    return x >= 0 && y >= 0 && z >= 0 && x < nx && y < ny && z < nz && grid.occupied[grid.Index(x, y, z)];
  };
  int64_t removed = 0;
  std::vector<Eigen::Vector3i> surface;
  std::vector<uint8_t> carve;
  for (int pass = 0; pass < options.passes; ++pass) {
    surface.clear();
    for (int z = 0; z < nz; ++z)
      for (int y = 0; y < ny; ++y)
        for (int x = 0; x < nx; ++x)
          if (occ(x, y, z) && (!occ(x - 1, y, z) || !occ(x + 1, y, z) || !occ(x, y - 1, z) || !occ(x, y + 1, z) || !occ(x, y, z - 1) ||
                               !occ(x, y, z + 1)))
            surface.push_back({x, y, z});
    // Depth buffers of the surface voxels (a square splat of the voxel's projected size).
    for (Cam& c : cams) {
      c.depth.assign(static_cast<size_t>(c.w) * c.h, std::numeric_limits<float>::infinity());
      for (const Eigen::Vector3i& v : surface) {
        const Eigen::Vector3f q = c.r * grid.Center(v.x(), v.y(), v.z()).cast<float>() + c.t;
        if (q.z() <= 0.05f) continue;
        const float u = c.fx * q.x() / q.z() + c.cx, vv = c.fy * q.y() / q.z() + c.cy;
        const float half = 0.5f * static_cast<float>(grid.voxel_m) * c.fx / q.z();
        const int u0 = std::max(0, static_cast<int>(std::floor(u - half + 0.5f))), u1 = std::min(c.w - 1, static_cast<int>(std::floor(u + half + 0.5f)));
        const int v0 = std::max(0, static_cast<int>(std::floor(vv - half + 0.5f))), v1 = std::min(c.h - 1, static_cast<int>(std::floor(vv + half + 0.5f)));
        for (int py = v0; py <= v1; ++py)
          for (int px = u0; px <= u1; ++px) {
            float& d = c.depth[static_cast<size_t>(py) * c.w + px];
            d = std::min(d, q.z());
          }
      }
    }
    carve.assign(surface.size(), 0);
    int64_t carved = 0;
    for (size_t i = 0; i < surface.size(); ++i) {
      const Eigen::Vector3f p = grid.Center(surface[i].x(), surface[i].y(), surface[i].z()).cast<float>();
      double sum[3] = {0, 0, 0}, sum2[3] = {0, 0, 0};
      int n = 0;
      for (size_t ci = 0; ci < cams.size(); ++ci) {
        const Cam& c = cams[ci];
        const Eigen::Vector3f q = c.r * p + c.t;
        if (q.z() <= 0.05f) continue;
        const int u = static_cast<int>(std::floor(c.fx * q.x() / q.z() + c.cx + 0.5f)), v = static_cast<int>(std::floor(c.fy * q.y() / q.z() + c.cy + 0.5f));
        if (u < 0 || v < 0 || u >= c.w || v >= c.h) continue;
        const size_t idx = static_cast<size_t>(v) * c.w + u;
        if (q.z() > c.depth[idx] + 0.75f * static_cast<float>(grid.voxel_m)) continue;  // hidden by nearer surface
        for (int k = 0; k < 3; ++k) {
          const double b = images[ci].bgr[3 * idx + k];
          sum[k] += b;
          sum2[k] += b * b;
        }
        ++n;
      }
      if (n < options.min_cameras) continue;
      double var = 0;
      for (int k = 0; k < 3; ++k) var += std::max(0.0, sum2[k] / n - (sum[k] / n) * (sum[k] / n)) / 3;
      if (std::sqrt(var) > options.max_std_levels) carve[i] = 1, ++carved;
    }
    for (size_t i = 0; i < surface.size(); ++i)
      if (carve[i]) grid.occupied[grid.Index(surface[i].x(), surface[i].y(), surface[i].z())] = 0;
    removed += carved;
    if (carved == 0) break;
  }
  return removed;
}

}  // namespace ave::studio
