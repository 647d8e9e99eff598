#include "model_store/studio/raster.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace ave::studio {
namespace {

struct Projected {
  Eigen::Vector3d in_camera;
  Eigen::Vector2d pixel;
};

bool ProjectTriangle(const Rigid3d& camera_from_world, const PinholeIntrinsics& k, const std::vector<Eigen::Vector3f>& positions,
                     const uint32_t* tri, Projected out[3]) {
  for (int i = 0; i < 3; ++i) {
    out[i].in_camera = camera_from_world * positions[tri[i]].cast<double>();
    if (out[i].in_camera.z() < 0.05) return false;
    out[i].pixel = Eigen::Vector2d(k.fx * out[i].in_camera.x() / out[i].in_camera.z() + k.cx,
                                   k.fy * out[i].in_camera.y() / out[i].in_camera.z() + k.cy);
  }
  return true;
}

// Screen-space barycentrics of pixel centre (u, v); false when outside.
bool Barycentric(const Projected p[3], double area, double u, double v, double b[3]) {
  for (int i = 0; i < 3; ++i) {
    const Eigen::Vector2d& a = p[(i + 1) % 3].pixel;
    const Eigen::Vector2d& c = p[(i + 2) % 3].pixel;
    b[i] = ((c.x() - a.x()) * (v - a.y()) - (c.y() - a.y()) * (u - a.x())) / area;
  }
  return b[0] >= 0 && b[1] >= 0 && b[2] >= 0;
}

}  // namespace

RasterBuffers Rasterize(const StudioCameraModel& camera, const std::vector<Eigen::Vector3f>& positions_m,
                        const std::vector<uint32_t>& indices) {
  const PinholeIntrinsics& k = camera.intrinsics;
  RasterBuffers out;
  out.width = k.width;
  out.height = k.height;
  out.depth_m.assign(static_cast<size_t>(k.width) * k.height, std::numeric_limits<float>::infinity());
  out.triangle.assign(out.depth_m.size(), -1);
  const Rigid3d camera_from_world = camera.world_from_camera.Inverse();
  for (size_t t = 0; 3 * t + 2 < indices.size(); ++t) {
    Projected p[3];
    if (!ProjectTriangle(camera_from_world, k, positions_m, &indices[3 * t], p)) continue;
    const double area = (p[1].pixel - p[0].pixel).x() * (p[2].pixel - p[0].pixel).y() - (p[1].pixel - p[0].pixel).y() * (p[2].pixel - p[0].pixel).x();
    if (std::abs(area) < 1e-12) continue;
    const int u0 = std::max(0, static_cast<int>(std::ceil(std::min({p[0].pixel.x(), p[1].pixel.x(), p[2].pixel.x()}))));
    const int u1 = std::min(k.width - 1, static_cast<int>(std::floor(std::max({p[0].pixel.x(), p[1].pixel.x(), p[2].pixel.x()}))));
    const int v0 = std::max(0, static_cast<int>(std::ceil(std::min({p[0].pixel.y(), p[1].pixel.y(), p[2].pixel.y()}))));
    const int v1 = std::min(k.height - 1, static_cast<int>(std::floor(std::max({p[0].pixel.y(), p[1].pixel.y(), p[2].pixel.y()}))));
    for (int v = v0; v <= v1; ++v) {
      for (int u = u0; u <= u1; ++u) {
        double b[3];
        if (!Barycentric(p, area, u, v, b)) continue;
        const double inv_z = b[0] / p[0].in_camera.z() + b[1] / p[1].in_camera.z() + b[2] / p[2].in_camera.z();
        const float z = static_cast<float>(1.0 / inv_z);
        const size_t idx = static_cast<size_t>(v) * k.width + u;
        if (z < out.depth_m[idx]) {
          out.depth_m[idx] = z;
          out.triangle[idx] = static_cast<int32_t>(t);
        }
      }
    }
  }
  return out;
}

Image RenderTextured(const StudioCameraModel& camera, const avatar::AvatarFrame& mesh, Mask* covered) {
  const PinholeIntrinsics& k = camera.intrinsics;
  const RasterBuffers r = Rasterize(camera, mesh.positions_m, mesh.indices);
  Image image{k.width, k.height, std::vector<uint8_t>(static_cast<size_t>(k.width) * k.height * 3, 0)};
  if (covered) *covered = Mask{k.width, k.height, std::vector<uint8_t>(static_cast<size_t>(k.width) * k.height, 0)};
  const Rigid3d camera_from_world = camera.world_from_camera.Inverse();
  const int aw = mesh.atlas_width, ah = mesh.atlas_height;
  auto texel = [&](int x, int y, int c) -> double {
    x = std::clamp(x, 0, aw - 1);
    y = std::clamp(y, 0, ah - 1);
    return mesh.atlas_rgb[(static_cast<size_t>(y) * aw + x) * 3 + c];
  };
  for (int v = 0; v < k.height; ++v) {
    for (int u = 0; u < k.width; ++u) {
      const size_t idx = static_cast<size_t>(v) * k.width + u;
      const int32_t t = r.triangle[idx];
      if (t < 0) continue;
      if (covered) covered->data[idx] = 255;
      if (aw <= 0 || ah <= 0) continue;
      Projected p[3];
      ProjectTriangle(camera_from_world, k, mesh.positions_m, &mesh.indices[3 * static_cast<size_t>(t)], p);
      const double area = (p[1].pixel - p[0].pixel).x() * (p[2].pixel - p[0].pixel).y() - (p[1].pixel - p[0].pixel).y() * (p[2].pixel - p[0].pixel).x();
      double b[3];
      Barycentric(p, area, u, v, b);
      // Perspective-correct weights.
      double w[3], sum = 0;
      for (int i = 0; i < 3; ++i) sum += (w[i] = b[i] / p[i].in_camera.z());
      Eigen::Vector2d uv = Eigen::Vector2d::Zero();
      for (int i = 0; i < 3; ++i) uv += w[i] / sum * mesh.uv[mesh.indices[3 * static_cast<size_t>(t) + i]].cast<double>();
      const double x = uv.x() * aw - 0.5, y = uv.y() * ah - 0.5;
      const int x0 = static_cast<int>(std::floor(x)), y0 = static_cast<int>(std::floor(y));
      const double fx = x - x0, fy = y - y0;
      for (int c = 0; c < 3; ++c) {
        const double val = (1 - fy) * ((1 - fx) * texel(x0, y0, c) + fx * texel(x0 + 1, y0, c)) +
                           fy * ((1 - fx) * texel(x0, y0 + 1, c) + fx * texel(x0 + 1, y0 + 1, c));
        image.bgr[3 * idx + (2 - c)] = static_cast<uint8_t>(std::clamp(std::lround(val), 0L, 255L));  // RGB atlas -> BGR
      }
    }
  }
  return image;
}

}  // namespace ave::studio
