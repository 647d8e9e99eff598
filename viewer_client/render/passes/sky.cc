#include "viewer_client/render/passes/sky.h"

#include <algorithm>
#include <cmath>
#include <vector>

namespace ave::viewer::internal {
namespace {

// An inward-facing dome (elevation -10 to 90 degrees): sky marker colour r < 0.
std::vector<Vertex> SkyDome(const Eigen::Vector3d& centre, double radius_m) {
  constexpr int kRings = 10, kSegments = 32;
  std::vector<Vertex> out;
  auto point = [&](int ring, int seg) {
    const double elevation = (-10.0 + 100.0 * ring / kRings) * M_PI / 180;
    const double azimuth = 2 * M_PI * seg / kSegments;
    return Eigen::Vector3d(centre + radius_m * Eigen::Vector3d(std::cos(elevation) * std::cos(azimuth),
                                                               std::cos(elevation) * std::sin(azimuth), std::sin(elevation)));
  };
  const Eigen::Vector3f sky(-1, -1, -1);
  auto make = [&](const Eigen::Vector3d& p) {
    return MakeVertex(p.cast<float>(), (centre - p).normalized().cast<float>(), sky);
  };
  for (int ring = 0; ring < kRings; ++ring) {
    for (int seg = 0; seg < kSegments; ++seg) {
      const Eigen::Vector3d a = point(ring, seg), b = point(ring, seg + 1), c = point(ring + 1, seg + 1),
                            d = point(ring + 1, seg);
      const Eigen::Vector3d inward = centre - 0.25 * (a + b + c + d);
      AppendOrientedTriangle(a, b, c, inward, out, make);
      if (ring + 1 < kRings) AppendOrientedTriangle(a, c, d, inward, out, make);
    }
  }
  return out;
}

}  // namespace

Sky::Sky(const RendererOptions& options)
    : radius_option_m_(options.sky_radius_m), mesh_(/*with_normals=*/true, /*indexed=*/false) {
  Place(Bounds());
}

void Sky::Place(const Bounds& static_bounds) {
  if (static_bounds.empty()) {
    centre_ = Eigen::Vector3d::Zero();
    radius_m_ = std::max(100.0, radius_option_m_);
  } else {
    const Eigen::Vector3d mid = 0.5 * (static_bounds.lo + static_bounds.hi);
    centre_ = Eigen::Vector3d(mid.x(), mid.y(), static_bounds.lo.z());
    radius_m_ = radius_option_m_ > 0 ? radius_option_m_
                                     : std::max(100.0, 1.2 * 0.5 * (static_bounds.hi - static_bounds.lo).norm());
  }
  mesh_.Upload(SkyDome(centre_, radius_m_), GL_STATIC_DRAW);
}

void Sky::Draw(bool on) const {
  if (on) mesh_.Draw(GL_TRIANGLES);
}

void Sky::AddTo(Bounds& scene, bool on) const {
  if (!on || mesh_.count() == 0) return;
  scene.Add(centre_ - Eigen::Vector3d::Constant(radius_m_));
  scene.Add(centre_ + Eigen::Vector3d::Constant(radius_m_));
}

}  // namespace ave::viewer::internal
